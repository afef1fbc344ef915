//! MaxWalkSAT over weighted conjunctive factors (Kautz, Selman & Jiang 1997; the MAP
//! algorithm of Alchemy and Tuffy), generalised to factors that are conjunctions of clauses.
//!
//! A factor (w, C₁ ∧ … ∧ Cₘ) costs −w when true. It is *bad* when it holds the cost up:
//! w > 0 and false, or w < 0 and true. Each flip picks a random bad factor and, with
//! probability `noise`, flips a random variable of it, else the variable whose flip lowers
//! the total cost most. Ground formulas are factors (the `maxwalksat` method); so are the
//! monomials of the cost polynomial, a·Π lᵢ being the factor (−a, \[l₁\] ∧ … ∧ \[lₖ\])
//! (`maxwalksat-monomials`, thesis §3.2.4). Chains run in parallel (rayon), each seeded
//! from the base seed and its index; the best assignment wins (ties: lowest chain index).

use pbo::polynomial::{Literal, Polynomial};
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// A weighted conjunction of clauses over variables `0..n`.
#[derive(Debug, Clone)]
pub struct Factor {
    /// Cost −w when the conjunction is true.
    pub weight: f64,
    /// Clauses (disjunctions of literals).
    pub clauses: Vec<Vec<Literal>>,
}

/// Options of [`max_walk_sat`].
#[derive(Debug, Clone)]
pub struct WalkSatOptions {
    /// Flips per chain.
    pub max_flips: usize,
    /// Independent chains (restarts), run in parallel.
    pub chains: usize,
    /// Probability of a random-walk move.
    pub noise: f64,
    /// Base seed.
    pub seed: u64,
}

impl Default for WalkSatOptions {
    fn default() -> Self {
        WalkSatOptions {
            max_flips: 1_000_000,
            chains: 2,
            noise: 0.5,
            seed: 0,
        }
    }
}

/// Factors from the monomials of a polynomial: a·Π lᵢ → (−a, unit clauses lᵢ).
pub fn monomial_factors(f: &Polynomial) -> Vec<Factor> {
    f.terms()
        .map(|(lits, a)| Factor {
            weight: -a,
            clauses: lits.iter().map(|&l| vec![l]).collect(),
        })
        .collect()
}

/// The total cost −Σ w·[factor true] of an assignment.
pub fn cost(factors: &[Factor], x: &[bool]) -> f64 {
    factors
        .iter()
        .filter(|f| {
            f.clauses
                .iter()
                .all(|c| c.iter().any(|l| l.eval(x[l.var() as usize])))
        })
        .map(|f| -f.weight)
        .sum()
}

/// Runs MaxWalkSAT from `start` (or a random assignment) and returns the best assignment
/// and its cost.
pub fn max_walk_sat(
    factors: &[Factor],
    num_vars: usize,
    start: Option<&[bool]>,
    options: &WalkSatOptions,
) -> (Vec<bool>, f64) {
    max_walk_sat_frozen(factors, num_vars, start, None, options)
}

/// [`max_walk_sat`] where variables with `frozen[v]` never flip (e.g. persistencies).
pub fn max_walk_sat_frozen(
    factors: &[Factor],
    num_vars: usize,
    start: Option<&[bool]>,
    frozen: Option<&[bool]>,
    options: &WalkSatOptions,
) -> (Vec<bool>, f64) {
    let chains = options.chains.max(1);
    let results: Vec<(Vec<bool>, f64)> = (0..chains)
        .into_par_iter()
        .map(|c| {
            let seed = options
                .seed
                .wrapping_mul(0x9E37_79B9_7F4A_7C15)
                .wrapping_add(c as u64);
            Chain::new(factors, num_vars, start, seed).run(options, frozen)
        })
        .collect();
    let mut best: Option<(Vec<bool>, f64)> = None;
    for r in results {
        if best.as_ref().is_none_or(|b| r.1 < b.1) {
            best = Some(r);
        }
    }
    best.unwrap_or_else(|| (vec![false; num_vars], cost(factors, &vec![false; num_vars])))
}

/// One chain's incremental state.
struct Chain<'a> {
    factors: &'a [Factor],
    x: Vec<bool>,
    /// Per factor, per clause: number of true literals.
    true_lits: Vec<Vec<u32>>,
    /// Per factor: number of satisfied clauses.
    sat_clauses: Vec<u32>,
    /// Occurrences per variable: (factor, clause, literal).
    occurs: Vec<Vec<(u32, u32, Literal)>>,
    bad: Vec<u32>,
    bad_pos: Vec<u32>,
    cost: f64,
    rng: ChaCha8Rng,
}

const NOT_BAD: u32 = u32::MAX;

/// The satisfied-clause count of one factor after flipping a variable of value `value`
/// (MaxWalkSAT's delta; MC-SAT's sampler has its own occurrence layout, `marginal::Occ`):
/// `occ[*k..]` starts with the factor's run of the variable's occurrences (factor, clause,
/// literal; a factor's and a clause's occurrences adjacent, a clause may hold the variable
/// more than once, as x ∨ x̄ from groundings with equal arguments), `sat` is the factor's
/// count now and `true_lits(clause)` a clause's true literals now; `*k` moves past the run.
fn satisfied_after_flip(
    occ: &[(u32, u32, Literal)],
    k: &mut usize,
    value: bool,
    mut sat: i64,
    true_lits: impl Fn(u32) -> u32,
) -> i64 {
    let f = occ[*k].0;
    while *k < occ.len() && occ[*k].0 == f {
        let c = occ[*k].1;
        let t = i64::from(true_lits(c));
        let mut after = t;
        while *k < occ.len() && occ[*k].0 == f && occ[*k].1 == c {
            after += if occ[*k].2.eval(value) { -1 } else { 1 };
            *k += 1;
        }
        sat += i64::from(after > 0) - i64::from(t > 0);
    }
    sat
}

impl<'a> Chain<'a> {
    fn new(factors: &'a [Factor], n: usize, start: Option<&[bool]>, seed: u64) -> Chain<'a> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let x: Vec<bool> = match start {
            Some(s) => s.to_vec(),
            None => (0..n).map(|_| rng.gen_bool(0.5)).collect(),
        };
        let mut occurs: Vec<Vec<(u32, u32, Literal)>> = vec![Vec::new(); n];
        let mut true_lits = Vec::with_capacity(factors.len());
        let mut sat_clauses = Vec::with_capacity(factors.len());
        for (fi, f) in factors.iter().enumerate() {
            let mut counts = Vec::with_capacity(f.clauses.len());
            let mut sat = 0;
            for (ci, c) in f.clauses.iter().enumerate() {
                let t = c.iter().filter(|l| l.eval(x[l.var() as usize])).count() as u32;
                counts.push(t);
                sat += u32::from(t > 0);
                for &l in c {
                    occurs[l.var() as usize].push((fi as u32, ci as u32, l));
                }
            }
            true_lits.push(counts);
            sat_clauses.push(sat);
        }
        let mut chain = Chain {
            factors,
            x,
            true_lits,
            sat_clauses,
            occurs,
            bad: Vec::new(),
            bad_pos: vec![NOT_BAD; factors.len()],
            cost: 0.0,
            rng,
        };
        for (fi, f) in factors.iter().enumerate() {
            if chain.is_true(fi) {
                chain.cost -= f.weight;
            }
            if chain.is_bad(fi) {
                chain.mark_bad(fi);
            }
        }
        chain
    }

    fn is_true(&self, fi: usize) -> bool {
        self.sat_clauses[fi] as usize == self.factors[fi].clauses.len()
    }

    fn is_bad(&self, fi: usize) -> bool {
        let w = self.factors[fi].weight;
        (w > 0.0 && !self.is_true(fi)) || (w < 0.0 && self.is_true(fi))
    }

    fn mark_bad(&mut self, fi: usize) {
        if self.bad_pos[fi] == NOT_BAD {
            self.bad_pos[fi] = self.bad.len() as u32;
            self.bad.push(fi as u32);
        }
    }

    fn unmark_bad(&mut self, fi: usize) {
        let pos = self.bad_pos[fi];
        if pos != NOT_BAD {
            let last = self.bad.len() - 1;
            self.bad.swap(pos as usize, last);
            let moved = self.bad[pos as usize];
            self.bad_pos[moved as usize] = pos;
            self.bad.pop();
            self.bad_pos[fi] = NOT_BAD;
        }
    }

    /// Cost change if variable v were flipped.
    fn delta(&self, v: usize) -> f64 {
        let mut d = 0.0;
        let occ = &self.occurs[v];
        let mut k = 0;
        while k < occ.len() {
            let fi = occ[k].0 as usize;
            let sat =
                satisfied_after_flip(occ, &mut k, self.x[v], self.sat_clauses[fi] as i64, |ci| {
                    self.true_lits[fi][ci as usize]
                });
            let before = self.is_true(fi);
            let after = sat as usize == self.factors[fi].clauses.len();
            if before != after {
                let w = self.factors[fi].weight;
                d += if after { -w } else { w };
            }
        }
        d
    }

    fn flip(&mut self, v: usize) {
        let occ = std::mem::take(&mut self.occurs[v]);
        let mut k = 0;
        while k < occ.len() {
            let fi = occ[k].0 as usize;
            let before = self.is_true(fi);
            while k < occ.len() && occ[k].0 as usize == fi {
                let (_, ci, l) = occ[k];
                let t = &mut self.true_lits[fi][ci as usize];
                if l.eval(self.x[v]) {
                    *t -= 1;
                    if *t == 0 {
                        self.sat_clauses[fi] -= 1;
                    }
                } else {
                    *t += 1;
                    if *t == 1 {
                        self.sat_clauses[fi] += 1;
                    }
                }
                k += 1;
            }
            let after = self.is_true(fi);
            if before != after {
                let w = self.factors[fi].weight;
                self.cost += if after { -w } else { w };
            }
            if self.is_bad(fi) {
                self.mark_bad(fi);
            } else {
                self.unmark_bad(fi);
            }
        }
        self.occurs[v] = occ;
        self.x[v] = !self.x[v];
    }

    fn run(mut self, options: &WalkSatOptions, frozen: Option<&[bool]>) -> (Vec<bool>, f64) {
        let is_frozen = |v: usize| frozen.is_some_and(|f| f.get(v).copied().unwrap_or(false));
        // The best world is kept as the flips made since it (undone at the end), so an
        // improvement costs nothing instead of a copy of the world; once that log is as long
        // as the world, the best world is copied out and the log restarts.
        let mut best_cost = self.cost;
        let mut since_best: Vec<u32> = Vec::new();
        let mut snapshot: Option<Vec<bool>> = None;
        for _ in 0..options.max_flips {
            if self.bad.is_empty() {
                break;
            }
            let fi = self.bad[self.rng.gen_range(0..self.bad.len())] as usize;
            let vars: Vec<usize> = {
                let mut v: Vec<usize> = self.factors[fi]
                    .clauses
                    .iter()
                    .flatten()
                    .map(|l| l.var() as usize)
                    .collect();
                v.sort_unstable();
                v.dedup();
                v.retain(|&v| !is_frozen(v));
                v
            };
            if vars.is_empty() {
                continue; // a bad factor over frozen variables only
            }
            let v = if self.rng.gen_bool(options.noise) {
                vars[self.rng.gen_range(0..vars.len())]
            } else {
                let mut best_v = vars[0];
                let mut best_d = f64::INFINITY;
                for &v in &vars {
                    let d = self.delta(v);
                    if d < best_d {
                        best_d = d;
                        best_v = v;
                    }
                }
                best_v
            };
            self.flip(v);
            if self.cost < best_cost - 1e-12 {
                best_cost = self.cost;
                since_best.clear();
                snapshot = None;
            } else {
                since_best.push(v as u32);
                if since_best.len() >= self.x.len().max(64) {
                    if snapshot.is_none() {
                        let mut b = self.x.clone();
                        for &u in &since_best {
                            b[u as usize] = !b[u as usize];
                        }
                        snapshot = Some(b);
                    }
                    since_best.clear();
                }
            }
        }
        let best = match snapshot {
            Some(b) => b,
            None => {
                let mut b = self.x;
                for &u in since_best.iter().rev() {
                    b[u as usize] = !b[u as usize];
                }
                b
            }
        };
        // Recompute exactly to avoid accumulated round-off in the reported cost.
        let c = cost(self.factors, &best);
        (best, c)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn arb_factors() -> impl Strategy<Value = (usize, Vec<Factor>)> {
        (2usize..9).prop_flat_map(|n| {
            let clause = proptest::collection::vec((0..n as u32, any::<bool>()), 1..4);
            let factor = (proptest::collection::vec(clause, 1..3), -3i32..=3);
            (Just(n), proptest::collection::vec(factor, 1..14)).prop_map(|(n, fs)| {
                let factors = fs
                    .into_iter()
                    .map(|(cs, w)| Factor {
                        weight: f64::from(w),
                        clauses: cs
                            .into_iter()
                            .map(|c| c.into_iter().map(|(v, s)| Literal::new(v, s)).collect())
                            .collect(),
                    })
                    .collect();
                (n, factors)
            })
        })
    }

    proptest! {
        /// On small problems WalkSAT reaches the brute-force optimum, and the incremental
        /// cost it reports equals a direct evaluation.
        #[test]
        fn reaches_the_optimum_on_small_problems((n, factors) in arb_factors(), seed in any::<u64>()) {
            let mut best = f64::INFINITY;
            for m in 0u32..(1 << n) {
                let x: Vec<bool> = (0..n).map(|i| m >> i & 1 == 1).collect();
                best = best.min(cost(&factors, &x));
            }
            let opts = WalkSatOptions { max_flips: 5_000, chains: 2, noise: 0.3, seed };
            let (x, c) = max_walk_sat(&factors, n, None, &opts);
            prop_assert!((cost(&factors, &x) - c).abs() < 1e-9);
            prop_assert!((c - best).abs() < 1e-9, "walksat {c} vs optimum {best}");
        }
    }

    #[test]
    fn monomials_as_factors_give_the_polynomial() {
        let mut f = Polynomial::new(3);
        f.add_term(2.0, &[Literal::pos(0), Literal::neg(1)]);
        f.add_term(-1.5, &[Literal::pos(2)]);
        let fs = monomial_factors(&f);
        for m in 0u32..8 {
            let x: Vec<bool> = (0..3).map(|i| m >> i & 1 == 1).collect();
            assert_eq!(cost(&fs, &x) + f.constant(), f.evaluate(&x));
        }
    }

    #[test]
    fn frozen_variables_never_flip_and_start_is_never_worsened() {
        let mut f = Polynomial::new(30);
        for i in 0..29u32 {
            f.add_term(
                if i % 4 == 0 { -2.0 } else { 1.0 },
                &[Literal::pos(i), Literal::pos(i + 1)],
            );
            f.add_term(-0.5, &[Literal::pos(i)]);
        }
        let fs = monomial_factors(&f);
        let start: Vec<bool> = (0..30).map(|i| i % 3 == 0).collect();
        let frozen: Vec<bool> = (0..30).map(|i| i % 5 == 0).collect();
        let o = WalkSatOptions {
            max_flips: 3_000,
            chains: 2,
            noise: 0.5,
            seed: 3,
        };
        let (x, c) = max_walk_sat_frozen(&fs, 30, Some(&start), Some(&frozen), &o);
        for i in (0..30).step_by(5) {
            assert_eq!(x[i], start[i], "frozen variable {i} flipped");
        }
        assert!(c <= cost(&fs, &start) + 1e-12);
    }

    #[test]
    fn same_seed_same_answer() {
        let mut f = Polynomial::new(40);
        for i in 0..39u32 {
            f.add_term(
                if i % 3 == 0 { -1.0 } else { 1.0 },
                &[Literal::pos(i), Literal::neg(i + 1)],
            );
        }
        let fs = monomial_factors(&f);
        let o = WalkSatOptions {
            max_flips: 2_000,
            chains: 3,
            noise: 0.5,
            seed: 11,
        };
        assert_eq!(
            max_walk_sat(&fs, 40, None, &o),
            max_walk_sat(&fs, 40, None, &o)
        );
    }
}
