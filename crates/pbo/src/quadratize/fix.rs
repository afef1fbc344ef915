//! FIX: reduction of positive terms that share a literal (Fix, Gruber, Boros & Zabih,
//! "A graph cut algorithm for higher-order Markov random fields", ICCV 2011,
//! doi:10.1109/ICCV.2011.6126347, Theorem 3.1 with C = {l}).
//!
//! For the set 𝓗 of positive terms containing literal l, with α = Σ_H α_H:
//! Σ_H α_H·l·Π_{H∖l} = min_y [ α·y·l + Σ_H α_H·Π_{H∖l} − Σ_H α_H·y·Π_{H∖l} ].
//! The first part is one pairwise term, the second has lower degree (and goes back into
//! the pool), the third is negative and takes the single-slack reduction. Literals are
//! processed in rounds, most shared first, until no positive term of degree ≥ 3 remains.

use super::{reduce_negative, Quadratization};
use crate::polynomial::{Literal, Polynomial};
use rustc_hash::FxHashMap;

/// Quadratizes `f` by reducing positive terms in groups sharing a literal.
pub fn quadratize(f: &Polynomial) -> Quadratization {
    let mut work = f.clone();
    loop {
        let positives: Vec<(Vec<Literal>, f64)> = work
            .terms()
            .filter(|(l, a)| l.len() >= 3 && *a > 0.0)
            .map(|(l, a)| (l.to_vec(), a))
            .collect();
        if positives.is_empty() {
            break;
        }
        // Inverted index literal → positive terms, literals ordered by count (desc).
        let mut by_literal: FxHashMap<Literal, Vec<usize>> = FxHashMap::default();
        for (t, (lits, _)) in positives.iter().enumerate() {
            for &l in lits {
                by_literal.entry(l).or_default().push(t);
            }
        }
        let mut order: Vec<(Literal, Vec<usize>)> = by_literal.into_iter().collect();
        order.sort_by(|a, b| b.1.len().cmp(&a.1.len()).then(a.0.cmp(&b.0)));
        let mut done = vec![false; positives.len()];
        for (l, group) in order {
            let members: Vec<usize> = group.into_iter().filter(|&t| !done[t]).collect();
            if members.is_empty() {
                continue;
            }
            let y = Literal::pos(work.add_vars(1));
            let mut alpha = 0.0;
            for &t in &members {
                done[t] = true;
                let (lits, a) = &positives[t];
                alpha += a;
                work.add_term(-a, lits);
                let rest: Vec<Literal> = lits.iter().copied().filter(|&m| m != l).collect();
                work.add_term(*a, &rest);
                let mut with_y = rest;
                with_y.push(y);
                work.add_term(-a, &with_y);
            }
            work.add_term(alpha, &[y, l]);
        }
        work.simplify(0.0);
    }
    // Only negative higher-order terms remain.
    let mut out = Polynomial::new(work.num_vars());
    out.add_constant(work.constant());
    for (lits, a) in work.terms() {
        if lits.len() <= 2 {
            out.add_term(a, lits);
        } else {
            reduce_negative(&mut out, a, lits);
        }
    }
    Quadratization {
        poly: out,
        num_original_vars: f.num_vars(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn terms_sharing_a_literal_share_one_slack_for_the_group() {
        // Two positive cubics sharing x0: one shared slack y + two Freedman slacks.
        let mut f = Polynomial::new(5);
        f.add_term(1.0, &[Literal::pos(0), Literal::pos(1), Literal::pos(2)]);
        f.add_term(2.0, &[Literal::pos(0), Literal::pos(3), Literal::pos(4)]);
        let q = quadratize(&f);
        assert_eq!(q.num_slacks(), 3);
        for mask in 0u32..32 {
            let x: Vec<bool> = (0..5).map(|b| mask >> b & 1 == 1).collect();
            assert_eq!(q.min_over_slacks(&x), f.evaluate(&x), "x={x:?}");
        }
    }
}
