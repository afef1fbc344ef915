//! The ground MAP problem as weighted partial MaxSAT (DIMACS `p wcnf`), so that exact MaxSAT
//! solvers (RC2, MaxHS, …) can give the true optimum of the same ground problem.
//!
//! Atom i is variable i + 1. A ground formula F = C₁ ∧ … ∧ Cₘ of weight w costs |w| when it
//! is *bad* (w > 0 and F false, or w < 0 and F true); each becomes soft clauses of weight
//! round(|w|·scale) plus hard clauses (weight `top`) over auxiliary variables, exactly:
//!
//! - w > 0, m = 1: the soft clause C₁.
//! - w > 0, m > 1: y with hard ¬y ∨ Cⱼ for every j, soft y (y can be true only if F is).
//! - w < 0, m = 1: y with hard y ∨ ¬l for every literal l of C₁, soft ¬y.
//! - w < 0, m > 1: uⱼ with hard ¬uⱼ ∨ ¬l for l ∈ Cⱼ (uⱼ only if Cⱼ is false), hard
//!   y ∨ u₁ ∨ … ∨ uₘ, soft ¬y (y must be true unless some clause is false).
//! - hard formulas: their clauses as hard clauses.
//!
//! The minimum total soft weight of the WCNF over the auxiliaries, for fixed atoms, is the
//! scaled violated weight of the ground formulas with unknown atoms; so the MaxSAT optimum
//! `o` gives our cost as `o / scale + offset`, with `offset` = −Σ_{w>0} w written in a
//! comment line (up to the rounding of the weights).

use crate::ground::GroundProblem;
use pbo::polynomial::Literal;
use std::io::Write;

/// What [`write_wcnf`] wrote.
#[derive(Debug, Clone, PartialEq)]
pub struct WcnfSummary {
    /// Variables (atoms and auxiliaries).
    pub variables: usize,
    /// Auxiliary variables.
    pub auxiliaries: usize,
    /// Hard clauses.
    pub hard_clauses: usize,
    /// Soft clauses.
    pub soft_clauses: usize,
    /// Weight of the hard clauses (1 + the sum of the soft weights).
    pub top: u64,
    /// cost = optimum / scale + offset.
    pub offset: f64,
}

fn dimacs(l: Literal) -> i64 {
    let v = i64::from(l.var()) + 1;
    if l.is_negated() {
        -v
    } else {
        v
    }
}

/// Writes the ground problem as `p wcnf` with soft weights round(|w|·scale).
pub fn write_wcnf(
    problem: &GroundProblem,
    scale: f64,
    out: &mut impl Write,
) -> std::io::Result<WcnfSummary> {
    let n = problem.atoms.len() as i64;
    let mut aux = 0i64;
    let mut hard: Vec<Vec<i64>> = Vec::new();
    let mut soft: Vec<(u64, Vec<i64>)> = Vec::new();
    let mut offset = 0.0;
    for f in &problem.factors {
        let clauses: Vec<Vec<i64>> = f
            .clauses
            .iter()
            .map(|c| c.iter().map(|&l| dimacs(l)).collect())
            .collect();
        if f.hard {
            hard.extend(clauses);
            continue;
        }
        let weight = (f.weight.abs() * scale).round() as u64;
        if weight == 0 {
            continue;
        }
        if f.weight > 0.0 {
            offset -= f.weight;
            if let [c] = clauses.as_slice() {
                soft.push((weight, c.clone()));
            } else {
                aux += 1;
                let y = n + aux;
                for c in clauses {
                    let mut h = vec![-y];
                    h.extend(c);
                    hard.push(h);
                }
                soft.push((weight, vec![y]));
            }
        } else {
            aux += 1;
            let y = n + aux;
            if let [c] = clauses.as_slice() {
                for &l in c {
                    hard.push(vec![y, -l]);
                }
            } else {
                let mut some_false = vec![y];
                for c in clauses {
                    aux += 1;
                    let u = n + aux;
                    some_false.push(u);
                    for l in c {
                        hard.push(vec![-u, -l]);
                    }
                }
                hard.push(some_false);
            }
            soft.push((weight, vec![-y]));
        }
    }
    // Saturating: weights near u64::MAX (a huge |w|·scale) must not wrap the hard weight.
    let top = soft
        .iter()
        .fold(0u64, |acc, (w, _)| acc.saturating_add(*w))
        .saturating_add(1);
    let variables = (n + aux) as usize;
    writeln!(
        out,
        "c ground MLN as weighted partial MaxSAT (urbansem mln)"
    )?;
    writeln!(
        out,
        "c atoms 1..{n}, {aux} auxiliaries after them; soft weights = round(|w| * {scale})"
    )?;
    writeln!(out, "c cost = optimum / {scale} {offset:+}")?;
    writeln!(out, "p wcnf {variables} {} {top}", hard.len() + soft.len())?;
    let mut line = String::new();
    let mut emit = |w: u64, lits: &[i64], out: &mut dyn Write| -> std::io::Result<()> {
        use std::fmt::Write as _;
        line.clear();
        let _ = write!(line, "{w}");
        for l in lits {
            let _ = write!(line, " {l}");
        }
        writeln!(out, "{line} 0")
    };
    for h in &hard {
        emit(top, h, out)?;
    }
    for (w, s) in &soft {
        emit(*w, s, out)?;
    }
    Ok(WcnfSummary {
        variables,
        auxiliaries: aux as usize,
        hard_clauses: hard.len(),
        soft_clauses: soft.len(),
        top,
        offset,
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ground::{GroundAtom, GroundFactor};
    use pbo::polynomial::Polynomial;
    use proptest::prelude::*;

    fn problem(n: usize, factors: Vec<GroundFactor>) -> GroundProblem {
        GroundProblem {
            constants: Vec::new(),
            atoms: (0..n)
                .map(|i| GroundAtom {
                    predicate: 0,
                    args: vec![i as u32].into_boxed_slice(),
                })
                .collect(),
            factors,
            cost: Polynomial::new(n),
            hard_weight: 1e3,
            constant_violated_weight: 0.0,
            constant_hard_violations: 0,
            inactive_predicates: Vec::new(),
        }
    }

    /// Parses our own output: (num vars, top, clauses as (weight, lits)).
    fn parse(text: &str) -> (usize, u64, Vec<(u64, Vec<i64>)>) {
        let mut vars = 0;
        let mut top = 0;
        let mut clauses = Vec::new();
        for line in text.lines() {
            if line.starts_with('c') {
                continue;
            }
            let words: Vec<&str> = line.split_whitespace().collect();
            if words[0] == "p" {
                vars = words[2].parse().unwrap();
                top = words[4].parse().unwrap();
                continue;
            }
            let w: u64 = words[0].parse().unwrap();
            let lits: Vec<i64> = words[1..words.len() - 1]
                .iter()
                .map(|s| s.parse().unwrap())
                .collect();
            clauses.push((w, lits));
        }
        (vars, top, clauses)
    }

    fn arb_factors() -> impl Strategy<Value = Vec<GroundFactor>> {
        let clause = proptest::collection::vec((0u32..4, any::<bool>()), 1..3);
        let factor = (
            proptest::collection::vec(clause, 1..3),
            -3i32..=3,
            proptest::bool::weighted(0.15),
        );
        proptest::collection::vec(factor, 1..5).prop_map(|fs| {
            fs.into_iter()
                .map(|(cs, w, hard)| GroundFactor {
                    weight: if hard { 1e3 } else { f64::from(w) / 2.0 },
                    hard,
                    formula: 0,
                    clauses: cs
                        .into_iter()
                        .map(|c| c.into_iter().map(|(v, s)| Literal::new(v, s)).collect())
                        .collect(),
                })
                .collect()
        })
    }

    proptest! {
        /// For every atom assignment satisfying the hard formulas, the cheapest extension to
        /// the auxiliaries costs exactly the scaled violated weight.
        #[test]
        fn wcnf_minimum_is_the_violated_weight(factors in arb_factors()) {
            let p = problem(4, factors);
            let mut buf = Vec::new();
            let summary = write_wcnf(&p, 2.0, &mut buf).unwrap();
            let (vars, top, clauses) = parse(std::str::from_utf8(&buf).unwrap());
            prop_assert_eq!(vars, summary.variables);
            let aux = vars - 4;
            for m in 0u32..16 {
                let x: Vec<bool> = (0..4).map(|i| m >> i & 1 == 1).collect();
                let s = p.score(&x);
                let mut best = u64::MAX;
                for a in 0u32..(1 << aux) {
                    let val = |l: i64| {
                        let v = l.unsigned_abs() as usize - 1;
                        let b = if v < 4 { x[v] } else { a >> (v - 4) & 1 == 1 };
                        b == (l > 0)
                    };
                    let mut cost = 0u64;
                    for (w, c) in &clauses {
                        if !c.iter().any(|&l| val(l)) {
                            cost = cost.saturating_add(*w);
                        }
                    }
                    best = best.min(cost);
                }
                if s.hard_violations > 0 {
                    prop_assert!(best >= top);
                } else {
                    prop_assert!(best < top);
                    prop_assert_eq!(best as f64, 2.0 * s.violated_weight);
                    prop_assert!((best as f64 / 2.0 + summary.offset - s.cost).abs() < 1e-9);
                }
            }
        }
    }
}
