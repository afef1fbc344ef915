//! Order reduction: a quadratic ρ(x, w) with slack variables w such that
//! φ(x) = min_w ρ(x, w) for every x (thesis §3.2, "Order Reduction of Pseudo-Boolean
//! functions").
//!
//! All methods work directly on literal monomials (a literal x̄ is itself a Boolean
//! variable), so MLN clauses never need the exponential expansion into positive literals.
//! Terms with a negative coefficient use Freedman–Drineas / Kolmogorov–Zabih's single-slack
//! reduction a·Π lᵢ = min_w a·w·(Σ lᵢ − (d − 1)) (thesis Example 3.2.3), which is
//! submodular in w. Positive terms are where the methods differ:
//!
//! - [`ish`]: Ishikawa (PAMI 2011, doi:10.1109/TPAMI.2010.91), ⌊(d−1)/2⌋ slacks per term.
//! - [`asm`]: Gallagher, Batra & Parikh (CVPR 2011, doi:10.1109/CVPR.2011.5995452),
//!   asymmetric cubic reduction, variant chosen per term to avoid non-submodular pairs.
//! - [`fix`]: Fix, Gruber, Boros & Zabih (ICCV 2011, doi:10.1109/ICCV.2011.6126347),
//!   positive terms sharing a literal reduced together with one shared slack.
//!
//! - [`grd`]: Kahl & Strandmark (ICCV 2011; DAM 160(16–17), 2012), generalized
//!   roof duality on the diagonal: each cubic/quartic term split over sign-restricted types
//!   chosen by the paper's LP (ISH for degree ≥ 5).
//!
//! ```
//! use pbo::polynomial::{Literal, Polynomial};
//! use pbo::quadratize::{quadratize, Quadratizer};
//! let mut f = Polynomial::new(3);
//! f.add_term(2.0, &[Literal::pos(0), Literal::pos(1), Literal::neg(2)]);
//! let q = quadratize(&f, Quadratizer::Ish);
//! assert!(q.poly.degree() <= 2);
//! assert_eq!(q.min_over_slacks(&[true, true, false]), 2.0);
//! ```

pub mod asm;
pub mod fix;
pub mod grd;
pub mod ish;

use crate::polynomial::{Literal, Polynomial};

/// Which order reduction to use for positive higher-order terms.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
#[non_exhaustive]
pub enum Quadratizer {
    /// Ishikawa's reduction, term by term.
    #[default]
    Ish,
    /// Gallagher–Batra–Parikh asymmetric reduction of cubic terms (ISH for degree ≥ 4).
    Asm,
    /// Fix–Gruber–Boros–Zabih reduction of terms sharing a literal.
    Fix,
    /// Kahl–Strandmark generalized roof duality (LP-chosen types; ISH for degree ≥ 5).
    Grd,
}

impl Quadratizer {
    /// All available methods.
    pub const ALL: [Quadratizer; 4] = [
        Quadratizer::Ish,
        Quadratizer::Asm,
        Quadratizer::Fix,
        Quadratizer::Grd,
    ];

    /// Lower-case name as used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Quadratizer::Ish => "ish",
            Quadratizer::Asm => "asm",
            Quadratizer::Fix => "fix",
            Quadratizer::Grd => "grd",
        }
    }
}

impl std::str::FromStr for Quadratizer {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        Quadratizer::ALL
            .into_iter()
            .find(|q| q.name().eq_ignore_ascii_case(s))
            .ok_or_else(|| format!("unknown quadratization {s:?}: expected ish, asm, fix or grd"))
    }
}

impl std::fmt::Display for Quadratizer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

/// A quadratic function over the original variables `0..num_original_vars` followed by
/// slack variables, whose minimum over the slacks equals the original function.
#[derive(Debug, Clone)]
pub struct Quadratization {
    /// The quadratic function ρ(x, w) (degree ≤ 2).
    pub poly: Polynomial,
    /// Number of original variables; slacks are `num_original_vars..poly.num_vars()`.
    pub num_original_vars: usize,
}

impl Quadratization {
    /// Number of slack variables introduced.
    pub fn num_slacks(&self) -> usize {
        self.poly.num_vars() - self.num_original_vars
    }

    /// Completes an assignment of the original variables with slack values by coordinate
    /// descent on ρ (each slack set to its better value until nothing changes).
    ///
    /// Exact for ISH and the negative-term reduction (their slacks do not interact); a good
    /// start for FIX, whose shared slacks interact with their Freedman slacks.
    pub fn complete_slacks(&self, x: &[bool]) -> Vec<bool> {
        let n = self.poly.num_vars();
        let mut full: Vec<bool> = x
            .iter()
            .copied()
            .chain(std::iter::repeat(false))
            .take(n)
            .collect();
        // Linear coefficient of each slack given everything else: Δ(w=1) − Δ(w=0).
        // Per slack: (coefficient, the slack's literal, the other literal of a pair term).
        type Touch = (f64, Literal, Option<Literal>);
        let mut touching: Vec<Vec<Touch>> = vec![Vec::new(); n];
        for (lits, a) in self.poly.terms() {
            for (k, l) in lits.iter().enumerate() {
                if (l.var() as usize) >= self.num_original_vars {
                    let other = lits.get(1 - k).copied().filter(|_| lits.len() == 2);
                    touching[l.var() as usize].push((a, *l, other));
                }
            }
        }
        for _sweep in 0..50 {
            let mut changed = false;
            for w in self.num_original_vars..n {
                let mut gain_one = 0.0; // ρ(w=1) − ρ(w=0)
                for &(a, l, other) in &touching[w] {
                    let other_true = other.is_none_or(|o| o.eval(full[o.var() as usize]));
                    if other_true {
                        gain_one += if l.is_negated() { -a } else { a };
                    }
                }
                let want = gain_one < 0.0;
                if full[w] != want {
                    full[w] = want;
                    changed = true;
                }
            }
            if !changed {
                break;
            }
        }
        full
    }

    /// min over all slack assignments of ρ(x, w), by enumeration (tests; ≤ 20 slacks).
    pub fn min_over_slacks(&self, x: &[bool]) -> f64 {
        let k = self.num_slacks();
        assert!(k <= 20, "enumerating {k} slacks");
        let mut full: Vec<bool> = x.to_vec();
        full.resize(self.poly.num_vars(), false);
        let mut best = f64::INFINITY;
        for mask in 0u64..(1u64 << k) {
            for j in 0..k {
                full[self.num_original_vars + j] = mask >> j & 1 == 1;
            }
            best = best.min(self.poly.evaluate(&full));
        }
        best
    }
}

/// Quadratizes `f` with the chosen method: φ(x) = min_w ρ(x, w).
pub fn quadratize(f: &Polynomial, method: Quadratizer) -> Quadratization {
    match method {
        Quadratizer::Ish => ish::quadratize(f),
        Quadratizer::Asm => asm::quadratize(f),
        Quadratizer::Fix => fix::quadratize(f),
        Quadratizer::Grd => grd::quadratize(f),
    }
}

/// Adds the single-slack reduction of a negative term a·Π lᵢ (a < 0, degree ≥ 3):
/// a·Π lᵢ = min_w a·w·(Σ lᵢ − (d − 1)).
pub(crate) fn reduce_negative(out: &mut Polynomial, a: f64, lits: &[Literal]) {
    debug_assert!(a < 0.0 && lits.len() >= 3);
    let w = out.add_vars(1);
    let wl = Literal::pos(w);
    for &l in lits {
        out.add_term(a, &[wl, l]);
    }
    out.add_term(-a * (lits.len() as f64 - 1.0), &[wl]);
}

/// Copies every term of degree ≤ 2 and the constant of `f` into a new polynomial with the
/// same variables; returns it with the higher-order terms left to reduce.
pub(crate) fn split_low_order(f: &Polynomial) -> (Polynomial, Vec<(Vec<Literal>, f64)>) {
    let mut out = Polynomial::new(f.num_vars());
    out.add_constant(f.constant());
    let mut high = Vec::new();
    for (lits, a) in f.terms() {
        if lits.len() <= 2 {
            out.add_term(a, lits);
        } else {
            high.push((lits.to_vec(), a));
        }
    }
    (out, high)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use proptest::prelude::*;

    /// Random polynomials of degree ≤ 4 over ≤ 8 variables with mixed-sign integer
    /// coefficients and literals of both polarities, many sharing literals.
    pub(crate) fn arb_higher_order(max_vars: usize) -> impl Strategy<Value = Polynomial> {
        (3..=max_vars).prop_flat_map(|n| {
            let term = (
                proptest::collection::vec((0..n as u32, any::<bool>()), 1..=4),
                -6i32..=6,
            );
            proptest::collection::vec(term, 1..10).prop_map(move |terms| {
                let mut f = Polynomial::new(n);
                for (lits, a) in terms {
                    let lits: Vec<Literal> =
                        lits.into_iter().map(|(v, s)| Literal::new(v, s)).collect();
                    f.add_term(f64::from(a), &lits);
                }
                f
            })
        })
    }

    pub(crate) fn assert_exact(f: &Polynomial, q: &Quadratization) -> Result<(), TestCaseError> {
        prop_assert!(q.poly.degree() <= 2, "degree {}", q.poly.degree());
        prop_assert_eq!(q.num_original_vars, f.num_vars());
        let n = f.num_vars();
        for mask in 0u64..(1u64 << n) {
            let x: Vec<bool> = (0..n).map(|i| mask >> i & 1 == 1).collect();
            let want = f.evaluate(&x);
            let got = q.min_over_slacks(&x);
            prop_assert!(
                (want - got).abs() < 1e-9,
                "x={:?}: φ={} min ρ={}",
                x,
                want,
                got
            );
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig::with_cases(300))]
        #[test]
        fn every_quadratizer_is_exact(f in arb_higher_order(8)) {
            for method in Quadratizer::ALL {
                let q = quadratize(&f, method);
                if q.num_slacks() <= 16 {
                    assert_exact(&f, &q)?;
                }
            }
        }

        #[test]
        fn slack_completion_never_exceeds_brute_force_much_and_is_exact_for_ish(f in arb_higher_order(7)) {
            let q = quadratize(&f, Quadratizer::Ish);
            let n = f.num_vars();
            for mask in 0u64..(1u64 << n) {
                let x: Vec<bool> = (0..n).map(|i| mask >> i & 1 == 1).collect();
                let full = q.complete_slacks(&x);
                prop_assert!((q.poly.evaluate(&full) - f.evaluate(&x)).abs() < 1e-9);
            }
        }
    }

    #[test]
    fn parses_method_names() {
        assert_eq!("ASM".parse::<Quadratizer>(), Ok(Quadratizer::Asm));
        assert_eq!("grd".parse::<Quadratizer>(), Ok(Quadratizer::Grd));
        assert!("grdx".parse::<Quadratizer>().is_err());
    }
}
