//! ASM: asymmetric reduction of positive cubic terms (Gallagher, Batra & Parikh,
//! "Inference for order reduction in Markov random fields", CVPR 2011,
//! doi:10.1109/CVPR.2011.5995452).
//!
//! For a > 0 and any ordering (i, j, k) of the three literals:
//! a·lᵢlⱼlₖ = a·min_w [ lᵢlⱼ + w·(1 − lᵢ − lⱼ + lₖ) ].
//! (The thesis prints the bracket with a typo; this identity is checked exhaustively in the
//! tests.) Each variant leaves one positive pairwise term lᵢlⱼ on original variables. We pick,
//! term by term in decreasing |a|, the pair whose multinomial coefficient after adding it
//! stays most submodular given the rest of the function (a greedy stand-in for the paper's
//! per-term selection problem). Negative terms use the single-slack reduction; positive terms
//! of degree ≥ 4 use ISH.

use super::{ish, reduce_negative, split_low_order, Quadratization};
use crate::polynomial::{Literal, Polynomial};
use rustc_hash::FxHashMap;

/// Quadratizes `f`, choosing the asymmetric variant of each positive cubic term greedily.
pub fn quadratize(f: &Polynomial) -> Quadratization {
    let (mut out, high) = split_low_order(f);
    let mut cubic = Vec::new();
    for (lits, a) in high {
        if a < 0.0 {
            reduce_negative(&mut out, a, &lits);
        } else if lits.len() == 3 {
            cubic.push((lits, a));
        } else {
            ish::reduce_positive(&mut out, a, &lits);
        }
    }
    // Multinomial pairwise coefficients c_uv (coefficient of x_u·x_v once every literal is
    // expanded): c·lᵤ·lᵥ contributes c·sᵤ·sᵥ. A pair is submodular iff c_uv ≤ 0.
    let mut pair_coeff: FxHashMap<(u32, u32), f64> = FxHashMap::default();
    for (lits, a) in out.terms() {
        if let [l1, l2] = lits {
            if (l1.var() as usize) < f.num_vars() && (l2.var() as usize) < f.num_vars() {
                *pair_coeff.entry(pair_key(*l1, *l2)).or_default() += a * l1.sign() * l2.sign();
            }
        }
    }
    cubic.sort_by(|x, y| y.1.total_cmp(&x.1).then_with(|| x.0.cmp(&y.0)));
    for (lits, a) in cubic {
        let (i, j, k) = choose_variant(&pair_coeff, &lits, a);
        let (li, lj, lk) = (lits[i], lits[j], lits[k]);
        *pair_coeff.entry(pair_key(li, lj)).or_default() += a * li.sign() * lj.sign();
        out.add_term(a, &[li, lj]);
        let w = Literal::pos(out.add_vars(1));
        out.add_term(a, &[w]);
        out.add_term(-a, &[w, li]);
        out.add_term(-a, &[w, lj]);
        out.add_term(a, &[w, lk]);
    }
    Quadratization {
        poly: out,
        num_original_vars: f.num_vars(),
    }
}

fn pair_key(a: Literal, b: Literal) -> (u32, u32) {
    let (u, v) = (a.var(), b.var());
    if u < v {
        (u, v)
    } else {
        (v, u)
    }
}

/// The ordering (i, j, k) whose positive pair lᵢlⱼ adds the least non-submodularity.
fn choose_variant(
    pair_coeff: &FxHashMap<(u32, u32), f64>,
    lits: &[Literal],
    a: f64,
) -> (usize, usize, usize) {
    let variants = [(0, 1, 2), (0, 2, 1), (1, 2, 0)];
    let score = |&(i, j, _): &(usize, usize, usize)| {
        let old = pair_coeff
            .get(&pair_key(lits[i], lits[j]))
            .copied()
            .unwrap_or(0.0);
        let new = old + a * lits[i].sign() * lits[j].sign();
        // Primary: increase of the non-submodular part; secondary: resulting coefficient.
        (new.max(0.0) - old.max(0.0), new)
    };
    let mut best = variants[0];
    let mut best_score = score(&best);
    for v in &variants[1..] {
        let s = score(v);
        if s.0 < best_score.0 || (s.0 == best_score.0 && s.1 < best_score.1) {
            best = *v;
            best_score = s;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn asymmetric_identity_holds_for_every_ordering() {
        for (i, j, k) in [(0, 1, 2), (0, 2, 1), (1, 2, 0)] {
            for mask in 0u32..16 {
                let x: Vec<bool> = (0..4).map(|b| mask >> b & 1 == 1).collect();
                let (xi, xj, xk, w) = (x[i] as i32, x[j] as i32, x[k] as i32, x[3] as i32);
                let rho = |w: i32| xi * xj + w * (1 - xi - xj + xk);
                let min = rho(0).min(rho(1));
                let _ = w;
                assert_eq!(min, xi * xj * xk, "ordering {:?} x={:?}", (i, j, k), x);
            }
        }
    }

    #[test]
    fn picks_the_pair_a_negative_pairwise_term_cancels() {
        // f = x0x1x2 − 2·x1x2: the variant with pair (1,2) keeps every pair submodular.
        let mut f = Polynomial::new(3);
        f.add_term(1.0, &[Literal::pos(0), Literal::pos(1), Literal::pos(2)]);
        f.add_term(-2.0, &[Literal::pos(1), Literal::pos(2)]);
        let q = quadratize(&f);
        assert_eq!(
            q.poly.coefficient(&[Literal::pos(1), Literal::pos(2)]),
            -1.0
        );
        assert_eq!(q.poly.coefficient(&[Literal::pos(0), Literal::pos(1)]), 0.0);
        assert_eq!(q.poly.coefficient(&[Literal::pos(0), Literal::pos(2)]), 0.0);
    }
}
