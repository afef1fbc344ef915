//! ISH: Ishikawa's order reduction, term by term (Ishikawa, "Transformation of general
//! binary MRF minimization to the first-order case", PAMI 33(6), 2011,
//! doi:10.1109/TPAMI.2010.91).
//!
//! For a > 0 and degree d with S₁ = Σ lᵢ, S₂ = Σ_{i<j} lᵢlⱼ, m = ⌊(d−1)/2⌋:
//! a·Π lᵢ = a·min_w [ Σ_{i=1..m} wᵢ (c_{i,d}(−S₁ + 2i) − 1) + S₂ ],
//! with c_{i,d} = 1 if d is odd and i = m, else 2. Negative terms use the single-slack
//! reduction. O(d²) terms per monomial.

use super::{reduce_negative, split_low_order, Quadratization};
use crate::polynomial::{Literal, Polynomial};

/// Quadratizes every higher-order term of `f` independently.
pub fn quadratize(f: &Polynomial) -> Quadratization {
    let (mut out, high) = split_low_order(f);
    for (lits, a) in high {
        if a < 0.0 {
            reduce_negative(&mut out, a, &lits);
        } else {
            reduce_positive(&mut out, a, &lits);
        }
    }
    Quadratization {
        poly: out,
        num_original_vars: f.num_vars(),
    }
}

/// Adds Ishikawa's reduction of the positive term a·Π lᵢ (a > 0, degree ≥ 3).
pub(crate) fn reduce_positive(out: &mut Polynomial, a: f64, lits: &[Literal]) {
    let d = lits.len();
    debug_assert!(a > 0.0 && d >= 3);
    // a·S₂
    for i in 0..d {
        for j in i + 1..d {
            out.add_term(a, &[lits[i], lits[j]]);
        }
    }
    let m = (d - 1) / 2;
    for i in 1..=m {
        let c = if d % 2 == 1 && i == m { 1.0 } else { 2.0 };
        let w = Literal::pos(out.add_vars(1));
        // a·w·(c·(2i − S₁) − 1) = a(2ic − 1)·w − a·c·Σ w·lⱼ
        out.add_term(a * (2.0 * i as f64 * c - 1.0), &[w]);
        for &l in lits {
            out.add_term(-a * c, &[w, l]);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn cubic_and_quartic_by_hand() {
        for d in 3..=6u32 {
            let mut f = Polynomial::new(d as usize);
            let lits: Vec<Literal> = (0..d).map(Literal::pos).collect();
            f.add_term(1.0, &lits);
            let q = quadratize(&f);
            assert_eq!(q.num_slacks(), ((d - 1) / 2) as usize);
            for mask in 0u32..(1 << d) {
                let x: Vec<bool> = (0..d).map(|i| mask >> i & 1 == 1).collect();
                let want = if mask == (1 << d) - 1 { 1.0 } else { 0.0 };
                assert_eq!(q.min_over_slacks(&x), want, "d={d} x={x:?}");
            }
        }
    }
}
