//! Lazy grounding: open predicates whose atoms can stay false without losing optimality.
//!
//! Tuffy's active closure and LazySAT (Singla & Domingos 2006) ground only what a search step
//! could violate. Here the closure is taken per predicate: an open predicate is *active* when
//! some formula could lower its cost by making one of its atoms true —
//! - a positive-weight or hard formula in which it occurs positively, and which can be false
//!   while every inactive predicate (without true evidence) is false;
//! - a negative-weight formula in which it occurs negatively, and which can be true then.
//!
//! "Can be false/true" is the formula's three-valued value with inactive predicates false and
//! everything else unknown. The closure starts with no active predicate and grows to a fixed
//! point. Every inactive predicate is then grounded closed-world (its atoms false, its true
//! evidence kept), and no MAP state loses by it: from any state, making inactive atoms false
//! never raises the cost — a positive-weight formula that holds one of them positively is true
//! whatever the active atoms are, a negative-weight formula that holds one negatively is
//! false whatever they are, and every other occurrence only gains from the atom being false.
//! MAP inference grounds this way by default; marginal inference and learning ground eagerly,
//! since there the inactive atoms' probabilities are not 0.

use crate::parse::{Formula, Program, Weight};

/// Three-valued truth.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Tri {
    False,
    True,
    Unknown,
}

impl Tri {
    fn not(self) -> Tri {
        match self {
            Tri::False => Tri::True,
            Tri::True => Tri::False,
            Tri::Unknown => Tri::Unknown,
        }
    }
    fn and(self, o: Tri) -> Tri {
        match (self, o) {
            (Tri::False, _) | (_, Tri::False) => Tri::False,
            (Tri::True, Tri::True) => Tri::True,
            _ => Tri::Unknown,
        }
    }
    fn or(self, o: Tri) -> Tri {
        self.not().and(o.not()).not()
    }
}

/// The formula's value when the predicates in `fixed_false` are false and all else unknown.
fn value(f: &Formula, fixed_false: &[bool]) -> Tri {
    match f {
        Formula::Atom(a) if fixed_false[a.predicate] => Tri::False,
        Formula::Atom(_) | Formula::Equal(..) => Tri::Unknown,
        Formula::Not(g) => value(g, fixed_false).not(),
        Formula::And(v) => v
            .iter()
            .fold(Tri::True, |acc, g| acc.and(value(g, fixed_false))),
        Formula::Or(v) => v
            .iter()
            .fold(Tri::False, |acc, g| acc.or(value(g, fixed_false))),
        Formula::Implies(a, b) => value(a, fixed_false).not().or(value(b, fixed_false)),
        Formula::Iff(a, b) => {
            let (a, b) = (value(a, fixed_false), value(b, fixed_false));
            a.and(b).or(a.not().and(b.not()))
        }
        // Over a non-empty domain (grounding refuses empty ones), the body's value.
        Formula::Exists(_, g) | Formula::Forall(_, g) => value(g, fixed_false),
    }
}

/// Calls `visit(predicate, positive)` for every atom occurrence with its polarity (both for
/// an equivalence's sides).
fn polarities(f: &Formula, positive: bool, visit: &mut impl FnMut(usize, bool)) {
    match f {
        Formula::Atom(a) => visit(a.predicate, positive),
        Formula::Equal(..) => {}
        Formula::Not(g) => polarities(g, !positive, visit),
        Formula::And(v) | Formula::Or(v) => v.iter().for_each(|g| polarities(g, positive, visit)),
        Formula::Implies(a, b) => {
            polarities(a, !positive, visit);
            polarities(b, positive, visit);
        }
        Formula::Iff(a, b) => {
            for g in [a, b] {
                polarities(g, positive, visit);
                polarities(g, !positive, visit);
            }
        }
        Formula::Exists(_, g) | Formula::Forall(_, g) => polarities(g, positive, visit),
    }
}

/// Which open predicates are active (see the module doc); `has_true_evidence[p]` when some
/// atom of `p` is true in the evidence. Closed predicates are never active.
pub(super) fn active_predicates(
    program: &Program,
    open: &[bool],
    has_true_evidence: &[bool],
) -> Vec<bool> {
    let np = program.predicates.len();
    let mut active = vec![false; np];
    loop {
        let fixed_false: Vec<bool> = (0..np)
            .map(|p| open[p] && !active[p] && !has_true_evidence[p])
            .collect();
        let mut changed = false;
        for f in &program.formulas {
            let (wants_true, when) = match f.weight {
                Weight::Soft(0.0) => continue,
                Weight::Soft(w) if w < 0.0 => (false, Tri::False),
                _ => (true, Tri::True),
            };
            // Nothing to gain when the formula's value is already the costless one.
            if value(&f.formula, &fixed_false) == when {
                continue;
            }
            polarities(&f.formula, true, &mut |p, positive| {
                if open[p] && !active[p] && positive == wants_true {
                    active[p] = true;
                    changed = true;
                }
            });
        }
        if !changed {
            return active;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse::parse_program;

    #[test]
    fn protein_interaction_keeps_interaction_inactive() {
        let p = parse_program(
            "interaction(p, p)\nfp(p, f)\n-4.07 interaction(a1, a2)\n0.01 fp(a1, a2)\n\
             0.04 !interaction(a1, a2) v fp(a2, a3) v !fp(a1, a3)\n\
             0.07 interaction(a1, a2) v !interaction(a2, a1) v fp(a2, a3)\n\
             -0.01 fp(a1, F1) v !fp(a1, F2)\n",
            "pr.mln",
        )
        .unwrap();
        let active = active_predicates(&p, &[true, true], &[false, false]);
        assert_eq!(active, [false, true]);
        // With an interaction in the evidence, interaction's negative literals are no longer
        // false by default, and the last-but-one formula activates it.
        let active = active_predicates(&p, &[true, true], &[true, false]);
        assert_eq!(active, [true, true]);
    }

    #[test]
    fn closure_grows_through_chains_and_weights_of_both_signs() {
        // A is wanted true; then B => C can be violated, so C is active; D only occurs where
        // it would have to become false; E is wanted false by a negative weight on !E.
        let p = parse_program(
            "A(t)\nB(t)\nC(t)\nD(t)\nE(t)\n1 A(x)\n1 A(x) => C(x)\n1 B(x) => C(x)\n\
             2 !D(x) v A(x)\n-1 !E(x) v A(x)\n",
            "chain.mln",
        )
        .unwrap();
        let active = active_predicates(&p, &[true; 5], &[false; 5]);
        assert_eq!(active, [true, false, true, false, true]);
    }
}
