//! Marginal inference: the probability of every unknown atom, by MC-SAT (Poon & Domingos
//! 2006), and by exact enumeration for small problems.
//!
//! A world x has probability ∝ exp(Σ w·\[F(x)\]) over the soft ground formulas, and zero
//! unless every hard formula holds. MC-SAT is slice sampling on that distribution: each step
//! keeps every hard formula and, for every soft formula the current world *satisfies* (w > 0:
//! F true; w < 0: F false), keeps it as a constraint with probability 1 − e^{−|w|}; the next
//! world is drawn from the worlds that satisfy all kept constraints (the *slice*).
//!
//! **How the slice is sampled, and a Gibbs sweep per step.** Alchemy draws the next world
//! with SampleSAT (WalkSAT mixed with simulated annealing), which is only approximately
//! uniform on the slice. Here each step is made of moves that are each a valid Markov chain
//! update, so the chain's stationary distribution is exactly the MLN's (no SampleSAT bias):
//! - **Paired flips inside the slice.** A pair is drawn independently of the world (the next
//!   formula of a scan over the formulas that goes on from step to step, two of its atoms at
//!   random), both atoms flip, and the flip is kept iff every kept formula still holds
//!   (Metropolis on the slice). They move what one
//!   flip cannot: "exactly one" hard constraints, formulas kept as equivalences.
//! - **A Gibbs sweep.** Every free atom is redrawn from its conditional P(xᵢ = 1 | x₋ᵢ) =
//!   σ(Σ w·(\[F\]ₓᵢ₌₁ − \[F\]ₓᵢ₌₀)) (0 or 1 where a hard formula allows one value only). This
//!   leaves the same distribution invariant and replaces MC-SAT's single flips inside the
//!   slice, which it subsumes. MC-SAT alone keeps a formula of weight w for about e^w steps,
//!   so with weights near 3 its samples are strongly correlated: on the random 6–16-atom
//!   problems of `tests/marginals.rs`, 1 000 steps without the sweep left errors up to 0.11.
//!
//! **One-atom formulas** (most ground formulas once evidence is applied: 80 % on KB) are not
//! formulas of the slice: each adds its weight to its atom's log-odds, which the Gibbs sweep
//! uses and a paired flip accepts by Metropolis (the slice's target is ∝ e^{bias·x} on the
//! kept worlds instead of uniform). No occurrence of theirs is visited in a step.
//!
//! **Fewer, merged formulas.** Before sampling, the forced atoms are substituted, clauses
//! they satisfy and tautologies dropped, and formulas equal up to the order of their clauses
//! and literals merged into one whose weight is the sum (hard if one is): the same
//! distribution with fewer formulas (LP: 357 229 ground formulas, 157 251 sampled). Atoms
//! left in no formula with another atom are independent: their probability is σ(bias),
//! exactly, and they are not sampled (IE: 264 196 of 336 670 atoms).
//!
//! **Cost per step.** The slice is drawn lazily: a formula's requirement is drawn when a move
//! first touches it in a step, before any of its atoms flips, so it is judged on the step's
//! starting world as MC-SAT prescribes, and a step costs the moves it makes, not a pass over
//! every formula. Paired flips stop once their atoms' occurrences reach an eighth of a sweep's.
//! Formulas are renumbered in the order the atoms reach them, so a sweep reads their counts
//! nearly in order; each occurrence carries its formula's weight and kind, so a one-clause
//! formula costs one look-up of its clause's count; an atom whose log-odds are those of
//! the step before reuses their probability (no e^x). Against the first version (one
//! occurrence list of (formula, clause, literal) over every ground formula) 1 000 samples
//! take 2–4× less CPU on the benchmark sets (`urbansem bench mln --marginal`).
//!
//! **Limits.** Worlds that neither paired flips nor single-atom conditionals connect mix
//! slowly (frustrated dense couplings: LP's `advisedBy` network). The spread between the
//! chains' estimates is reported so a user sees it.
//!
//! **Estimator.** Each atom contributes that conditional probability, computed at its Gibbs
//! update, instead of its 0/1 value: the same expectation (Rao–Blackwell), less variance.
//! On the random problems of `tests/marginals.rs` the worst error over 24 is 0.010 after
//! 5 000 steps, the default (issue 20's bound: 0.03).
//!
//! **Exact shortcuts.** Atoms the hard formulas force by unit propagation get exactly 0 or 1
//! and never move; an atom in no formula with another unforced atom gets exactly σ(bias)
//! (½ in no formula at all).
//!
//! Chains run in parallel (rayon), each from its own world satisfying the hard formulas
//! (WalkSAT), seeded from the base seed and its index; the estimate is their mean, in chain
//! order, so a seed gives the same bytes on every run.

use crate::ground::GroundProblem;
use crate::walksat::{max_walk_sat_frozen, Factor, WalkSatOptions};
use pbo::polynomial::Literal;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use std::collections::HashMap;
use std::time::Instant;
use thiserror::Error;

/// Why marginals could not be computed.
#[derive(Debug, Error, PartialEq)]
pub enum MarginalError {
    /// Unit propagation over the hard formulas derived a contradiction.
    #[error("the hard formulas contradict each other: unit propagation forces atom {atom} both true and false (ground formula {factor})")]
    HardConflict {
        /// Index of the unknown atom.
        atom: usize,
        /// Index of the ground formula that could not be satisfied.
        factor: usize,
    },
    /// WalkSAT found no world satisfying every hard formula.
    #[error("no world satisfying every hard formula was found in {flips} WalkSAT flips ({violated} hard ground formulas still violated); the hard formulas may be unsatisfiable")]
    NoHardSolution {
        /// Flips tried.
        flips: usize,
        /// Hard ground formulas violated by the best world found.
        violated: usize,
    },
    /// No world satisfies every hard formula (exact enumeration tried them all).
    #[error("no world satisfies every hard formula")]
    Unsatisfiable,
    /// The ground problem has more formulas or literals than the sampler indexes.
    #[error("{factors} ground formulas with {literals} literals are more than MC-SAT indexes (2^29 formulas, 2^32 literals)")]
    TooLarge {
        /// Distinct ground formulas over two or more atoms.
        factors: usize,
        /// Their literals.
        literals: usize,
    },
    /// Exact enumeration was asked for too many atoms.
    #[error("exact marginals enumerate 2^n worlds: {atoms} unknown atoms is more than the {limit} allowed")]
    TooManyAtoms {
        /// Unknown atoms.
        atoms: usize,
        /// The limit.
        limit: usize,
    },
}

/// Options of [`mc_sat`].
#[derive(Debug, Clone, PartialEq)]
pub struct McSatOptions {
    /// Samples per chain that are counted (after burn-in).
    pub samples: usize,
    /// Steps per chain before counting starts.
    pub burn_in: usize,
    /// Independent chains, run in parallel.
    pub chains: usize,
    /// Paired flips proposed inside the slice per step, in units of half the free atoms.
    pub sweeps: usize,
    /// WalkSAT flips allowed to find each chain's first world satisfying the hard formulas.
    pub init_flips: usize,
    /// Base seed.
    pub seed: u64,
}

impl Default for McSatOptions {
    fn default() -> Self {
        McSatOptions {
            samples: 5000,
            burn_in: 500,
            chains: 2,
            sweeps: 1,
            init_flips: 1_000_000,
            seed: 0,
        }
    }
}

/// The marginal probabilities of a ground problem's unknown atoms.
#[derive(Debug, Clone, PartialEq)]
pub struct Marginals {
    /// P(atom i true), per unknown atom of the ground problem.
    pub probabilities: Vec<f64>,
    /// Atoms the hard formulas force (their probability is exactly 0 or 1).
    pub fixed_atoms: usize,
    /// Unforced atoms in no formula with another unforced atom: exactly σ(their one-atom
    /// formulas' weight), not sampled.
    pub independent_atoms: usize,
    /// Distinct ground formulas over two or more unforced atoms the chains sample.
    pub slice_formulas: usize,
    /// Chains run.
    pub chains: usize,
    /// Counted samples per chain.
    pub samples: usize,
    /// Convergence diagnostic: the largest difference between two chains' estimates of one
    /// atom (0 with one chain).
    pub max_chain_spread: f64,
    /// The mean over atoms of that difference.
    pub mean_chain_spread: f64,
    /// Per unknown atom: the largest difference between two chains' estimates of it (0
    /// with one chain); where it is large the chains have not settled on the atom.
    pub spread: Vec<f64>,
    /// Share of proposed moves inside the slice that were kept.
    pub acceptance: f64,
    /// Seconds sampling (all chains).
    pub seconds: f64,
}

/// Tag bits of an [`Occ`]: the factor has one clause.
const OCC_SINGLE: u32 = 1 << 31;
/// The factor is hard.
const OCC_HARD: u32 = 1 << 30;
/// The literal is negated.
const OCC_NEG: u32 = 1 << 29;
/// The factor index's bits.
const OCC_FACTOR: u32 = OCC_NEG - 1;

/// One occurrence of a variable in a slice factor, with everything a Gibbs update reads of
/// the factor, so a one-clause factor (most of them) costs one look-up of its clause count.
#[derive(Debug, Clone, Copy)]
struct Occ {
    /// The factor's index and the `OCC_*` flags.
    tag: u32,
    /// The clause's index.
    clause: u32,
    /// The factor's soft weight (0 for hard factors).
    weight: f64,
}

impl Occ {
    /// The literal's value when its variable has value `value`.
    #[inline]
    fn eval(self, value: bool) -> bool {
        value != (self.tag & OCC_NEG != 0)
    }
    #[inline]
    fn index(self) -> usize {
        (self.tag & OCC_FACTOR) as usize
    }
    #[inline]
    fn single(self) -> bool {
        self.tag & OCC_SINGLE != 0
    }
    #[inline]
    fn hard(self) -> bool {
        self.tag & OCC_HARD != 0
    }
}

/// A ground formula after the forced atoms are substituted: its clauses (sorted, no
/// literal twice, no tautology), or that it is constant.
enum Simplified {
    /// Holds, or fails, in every world the hard formulas allow.
    Constant(bool),
    /// The clauses left.
    Clauses(Vec<Vec<Literal>>),
}

/// Substitutes the forced atoms into a formula's clauses.
fn simplify(clauses: &[Vec<Literal>], fixed: &[Option<bool>]) -> Simplified {
    let mut out: Vec<Vec<Literal>> = Vec::with_capacity(clauses.len());
    'clauses: for c in clauses {
        let mut ls: Vec<Literal> = Vec::with_capacity(c.len());
        for &l in c {
            match fixed[l.var() as usize] {
                Some(b) if l.eval(b) => continue 'clauses,
                Some(_) => {}
                None => ls.push(l),
            }
        }
        ls.sort_unstable();
        ls.dedup();
        // Sorted, x and x̄ are neighbours: x ∨ x̄ always holds.
        if ls.windows(2).any(|w| w[0].var() == w[1].var()) {
            continue;
        }
        if ls.is_empty() {
            return Simplified::Constant(false);
        }
        out.push(ls);
    }
    if out.is_empty() {
        return Simplified::Constant(true);
    }
    out.sort_unstable();
    out.dedup();
    Simplified::Clauses(out)
}

/// The factor and clause structure of a ground problem in flat arrays, shared by the chains.
///
/// Built from the formulas with the forced atoms substituted; soft formulas left over one
/// atom become that atom's bias, and formulas equal up to the order of their clauses and
/// literals are merged into one whose weight is their sum (hard if one of them is): the
/// distribution is the same, and a step visits each distinct formula once.
struct Flat {
    /// Per factor: its first clause index (`factors + 1` entries).
    clause_start: Vec<u32>,
    /// Per clause: its literals, flattened (`clauses + 1` start entries).
    lit_start: Vec<u32>,
    lits: Vec<Literal>,
    /// Per variable: its occurrences, grouped by factor (CSR).
    occ_start: Vec<u32>,
    occ: Vec<Occ>,
    /// Per factor: its distinct free variables (CSR), for paired moves.
    var_start: Vec<u32>,
    vars: Vec<u32>,
    /// Free variables in a factor with another free variable.
    pair_vars: usize,
    /// Factors with two or more free variables, where paired moves are made.
    pair_factors: Vec<u32>,
    /// Per factor: the probability 1 − e^{−|w|} of keeping it when satisfied.
    keep: Vec<f64>,
    /// Free (not forced) variables in a slice factor: the Gibbs sweep redraws them.
    linked: Vec<u32>,
    /// Free variables in no slice factor, with their exact probability σ(bias): each is
    /// independent of every other atom.
    isolated: Vec<(u32, f64)>,
    /// Per variable: the log-odds its one-atom soft formulas add to x = 1.
    unary_bias: Vec<f64>,
}

impl Flat {
    fn new(problem: &GroundProblem, fixed: &[Option<bool>]) -> Result<Flat, MarginalError> {
        let n = problem.atoms.len();
        let nf = problem.factors.len();
        // Factors renumbered in the order the atoms first reach them, so the factors of one
        // atom, and of consecutive atoms, sit together in memory: a sweep over the atoms
        // then reads the per-factor counts nearly in order (on KB, 3.4× fewer cycles).
        let order = {
            let mut first: Vec<Vec<u32>> = vec![Vec::new(); n];
            for (fi, f) in problem.factors.iter().enumerate() {
                let v = f.clauses.iter().flatten().map(|l| l.var()).min();
                if let Some(v) = v {
                    first[v as usize].push(fi as u32);
                }
            }
            let mut order: Vec<u32> = first.into_iter().flatten().collect();
            let mut seen = vec![false; nf];
            for &f in &order {
                seen[f as usize] = true;
            }
            order.extend((0..nf as u32).filter(|&f| !seen[f as usize]));
            order
        };
        let mut unary_bias = vec![0.0f64; n];
        // Distinct slice factors: clauses → (position, weight, hard).
        let mut distinct: HashMap<Vec<Vec<Literal>>, (u32, f64, bool)> = HashMap::new();
        let mut scratch: Vec<u32> = Vec::new();
        for &orig in &order {
            let f = &problem.factors[orig as usize];
            let clauses = match simplify(&f.clauses, fixed) {
                Simplified::Clauses(c) => c,
                Simplified::Constant(true) => continue,
                Simplified::Constant(false) if f.hard => {
                    return Err(MarginalError::HardConflict {
                        atom: 0,
                        factor: orig as usize,
                    })
                }
                Simplified::Constant(false) => continue,
            };
            scratch.clear();
            scratch.extend(clauses.iter().flatten().map(|l| l.var()));
            scratch.sort_unstable();
            scratch.dedup();
            // A soft formula over one free atom is folded into that atom's bias: no
            // occurrences to visit, and no slice constraint.
            if !f.hard && scratch.len() == 1 {
                let v = scratch[0];
                let truth = |b: bool| clauses.iter().all(|c| c.iter().any(|l| l.eval(b)));
                let (t0, t1) = (truth(false), truth(true));
                if t0 != t1 {
                    unary_bias[v as usize] += f.weight * if t1 { 1.0 } else { -1.0 };
                }
                continue;
            }
            let next = distinct.len() as u32;
            let entry = distinct.entry(clauses).or_insert((next, 0.0, false));
            if f.hard {
                entry.2 = true;
            } else {
                entry.1 += f.weight;
            }
        }
        // Back in the order the atoms first reached them.
        let mut merged: Vec<(u32, Vec<Vec<Literal>>, f64, bool)> = distinct
            .into_iter()
            .map(|(clauses, (pos, w, hard))| (pos, clauses, w, hard))
            .collect();
        merged.sort_unstable_by_key(|m| m.0);
        let mut weight = Vec::with_capacity(merged.len());
        let mut hard = Vec::with_capacity(merged.len());
        let mut keep = Vec::with_capacity(merged.len());
        let mut clause_start = Vec::with_capacity(merged.len() + 1);
        let mut lit_start = vec![0u32];
        let mut lits = Vec::new();
        let mut var_start = vec![0u32];
        let mut vars = Vec::new();
        let mut pairable_var = vec![false; n];
        let mut occ_count = vec![0u32; n + 1];
        for (_, clauses, w, is_hard) in &merged {
            let w = if *is_hard { 0.0 } else { *w };
            if !*is_hard && w == 0.0 {
                continue; // weights that cancel: the formula does not change the distribution
            }
            clause_start.push((lit_start.len() - 1) as u32);
            weight.push(w);
            hard.push(*is_hard);
            keep.push(if *is_hard { 1.0 } else { -(-w.abs()).exp_m1() });
            scratch.clear();
            for c in clauses {
                for &l in c {
                    lits.push(l);
                    occ_count[l.var() as usize] += 1;
                    scratch.push(l.var());
                }
                lit_start.push(lits.len() as u32);
            }
            scratch.sort_unstable();
            scratch.dedup();
            vars.extend_from_slice(&scratch);
            var_start.push(vars.len() as u32);
            if scratch.len() >= 2 {
                for &v in scratch.iter() {
                    pairable_var[v as usize] = true;
                }
            }
        }
        drop(merged);
        clause_start.push((lit_start.len() - 1) as u32);
        if weight.len() > OCC_FACTOR as usize || lits.len() > u32::MAX as usize {
            return Err(MarginalError::TooLarge {
                factors: weight.len(),
                literals: lits.len(),
            });
        }
        // Occurrences per variable, in factor order (so each factor's are adjacent).
        let mut occ_start = vec![0u32; n + 1];
        for v in 0..n {
            occ_start[v + 1] = occ_start[v] + occ_count[v];
        }
        let mut fill = occ_start.clone();
        let blank = Occ {
            tag: 0,
            clause: 0,
            weight: 0.0,
        };
        let mut occ = vec![blank; lits.len()];
        for fi in 0..weight.len() {
            let (c0, c1) = (clause_start[fi], clause_start[fi + 1]);
            let mut tag = fi as u32;
            if c1 - c0 == 1 {
                tag |= OCC_SINGLE;
            }
            if hard[fi] {
                tag |= OCC_HARD;
            }
            for ci in c0..c1 {
                for k in lit_start[ci as usize]..lit_start[ci as usize + 1] {
                    let l = lits[k as usize];
                    let v = l.var() as usize;
                    occ[fill[v] as usize] = Occ {
                        tag: tag | if l.is_negated() { OCC_NEG } else { 0 },
                        clause: ci,
                        weight: weight[fi],
                    };
                    fill[v] += 1;
                }
            }
        }
        let (mut linked, mut isolated) = (Vec::new(), Vec::new());
        for v in (0..n).filter(|&v| fixed[v].is_none()) {
            if occ_start[v] == occ_start[v + 1] {
                isolated.push((v as u32, sigmoid(unary_bias[v])));
            } else {
                linked.push(v as u32);
            }
        }
        let pair_factors = (0..var_start.len() - 1)
            .filter(|&f| var_start[f + 1] - var_start[f] >= 2)
            .map(|f| f as u32)
            .collect();
        Ok(Flat {
            unary_bias,
            clause_start,
            lit_start,
            lits,
            occ_start,
            occ,
            var_start,
            vars,
            pair_vars: pairable_var.iter().filter(|&&p| p).count(),
            pair_factors,
            keep,
            linked,
            isolated,
        })
    }

    fn num_clauses(&self, f: usize) -> u32 {
        self.clause_start[f + 1] - self.clause_start[f]
    }

    fn occurrences(&self, v: usize) -> &[Occ] {
        &self.occ[self.occ_start[v] as usize..self.occ_start[v + 1] as usize]
    }
}

/// What the slice requires of a factor in the current step.
const FREE: u8 = 0;
const MUST_HOLD: u8 = 1;
const MUST_FAIL: u8 = 2;

/// One chain's world and its incremental clause counts.
struct Chain<'a> {
    flat: &'a Flat,
    x: Vec<bool>,
    /// Per clause: true literals.
    true_lits: Vec<u32>,
    /// Per factor: satisfied clauses.
    sat: Vec<u32>,
    /// Per factor: [`FREE`], [`MUST_HOLD`] or [`MUST_FAIL`], valid where `drawn` is `step`.
    required: Vec<u8>,
    /// Per factor: the step its requirement was drawn in.
    drawn: Vec<u32>,
    /// The current step.
    step: u32,
    /// The next of [`Flat::pair_factors`] a paired move is made in.
    cursor: usize,
    rng: ChaCha8Rng,
}

impl<'a> Chain<'a> {
    fn new(flat: &'a Flat, x: Vec<bool>, rng: ChaCha8Rng) -> Chain<'a> {
        let nc = flat.lit_start.len() - 1;
        let mut true_lits = vec![0u32; nc];
        for (c, t) in true_lits.iter_mut().enumerate() {
            let ls = &flat.lits[flat.lit_start[c] as usize..flat.lit_start[c + 1] as usize];
            *t = ls.iter().filter(|l| l.eval(x[l.var() as usize])).count() as u32;
        }
        let nf = flat.keep.len();
        let sat = (0..nf)
            .map(|f| {
                (flat.clause_start[f]..flat.clause_start[f + 1])
                    .filter(|&c| true_lits[c as usize] > 0)
                    .count() as u32
            })
            .collect();
        Chain {
            flat,
            x,
            true_lits,
            sat,
            required: vec![FREE; nf],
            drawn: vec![u32::MAX; nf],
            step: 0,
            cursor: 0,
            rng,
        }
    }

    /// Whether the factor of occurrence `o` holds.
    #[inline]
    fn holds(&self, o: Occ) -> bool {
        if o.single() {
            self.true_lits[o.clause as usize] > 0
        } else {
            let f = o.index();
            self.sat[f] == self.flat.num_clauses(f)
        }
    }

    /// Flips variable v, updating the counts (satisfied clauses only of factors with more
    /// than one: a one-clause factor holds iff its clause has a true literal).
    fn flip(&mut self, v: usize) {
        let flat = self.flat;
        let now = self.x[v];
        for &o in flat.occurrences(v) {
            let t = &mut self.true_lits[o.clause as usize];
            if o.eval(now) {
                *t -= 1;
                if *t == 0 && !o.single() {
                    self.sat[o.index()] -= 1;
                }
            } else {
                *t += 1;
                if *t == 1 && !o.single() {
                    self.sat[o.index()] += 1;
                }
            }
        }
        self.x[v] = !now;
    }

    /// Whether every constrained factor containing v meets its requirement.
    fn meets(&self, v: usize) -> bool {
        self.flat
            .occurrences(v)
            .iter()
            .all(|&o| match self.required[o.index()] {
                MUST_HOLD => self.holds(o),
                MUST_FAIL => !self.holds(o),
                _ => true,
            })
    }

    /// Draws the slice's requirement of every factor containing v that has none yet this
    /// step: hard factors always hold; a soft one the world satisfies is kept with
    /// probability 1 − e^{−|w|}. Drawn lazily, before any variable of the factor flips in
    /// the step, so each factor is judged on the step's starting world as MC-SAT requires.
    fn draw_around(&mut self, v: usize) {
        let flat = self.flat;
        for &o in flat.occurrences(v) {
            let f = o.index();
            if self.drawn[f] == self.step {
                continue;
            }
            self.drawn[f] = self.step;
            self.required[f] = if o.hard() {
                MUST_HOLD
            } else {
                let w = o.weight;
                let holds = self.holds(o);
                let satisfied = (w > 0.0 && holds) || (w < 0.0 && !holds);
                if satisfied && self.rng.gen::<f64>() < flat.keep[f] {
                    if holds {
                        MUST_HOLD
                    } else {
                        MUST_FAIL
                    }
                } else {
                    FREE
                }
            };
        }
    }

    /// One slice step: a new slice, then Metropolis moves inside it that flip two variables
    /// of one formula (`pairs` proposals, fewer once their atoms' occurrences exceed
    /// `budget`); returns the proposals made and kept. (Single flips inside
    /// the slice would add nothing: the Gibbs sweep that follows redraws every atom from its
    /// full conditional.)
    fn slice_step(&mut self, pairs: usize, budget: usize) -> (u64, u64) {
        let flat = self.flat;
        self.step = self.step.wrapping_add(1);
        if self.step == u32::MAX {
            self.drawn.fill(u32::MAX - 1);
            self.step = 0;
        }
        let (mut proposed, mut kept) = (0u64, 0u64);
        if flat.pair_factors.is_empty() {
            return (0, 0);
        }
        let mut budget = budget as i64;
        for _ in 0..pairs {
            if budget <= 0 {
                break;
            }
            // A pair drawn independently of the world (so the move is its own reverse with
            // the same probability): the next formula of a scan that goes on from step to
            // step (in memory order: the accesses stay near each other), two of its atoms.
            let f = flat.pair_factors[self.cursor] as usize;
            self.cursor += 1;
            if self.cursor == flat.pair_factors.len() {
                self.cursor = 0;
            }
            let vs = &flat.vars[flat.var_start[f] as usize..flat.var_start[f + 1] as usize];
            let a = self.rng.gen_range(0..vs.len());
            let mut b = self.rng.gen_range(0..vs.len() - 1);
            if b >= a {
                b += 1;
            }
            let (u, v) = (vs[a] as usize, vs[b] as usize);
            budget -= (flat.occurrences(u).len() + flat.occurrences(v).len()) as i64;
            proposed += 1;
            self.draw_around(u);
            self.draw_around(v);
            // The one-atom formulas are not in the slice: their log-weight change decides
            // by Metropolis (the slice's target is ∝ e^{bias·x} on the kept worlds).
            let sign = |x: bool| if x { -1.0 } else { 1.0 };
            let gain = flat.unary_bias[u] * sign(self.x[u]) + flat.unary_bias[v] * sign(self.x[v]);
            self.flip(u);
            self.flip(v);
            if self.meets(u) && self.meets(v) && (gain >= 0.0 || self.rng.gen::<f64>() < gain.exp())
            {
                kept += 1;
            } else {
                self.flip(v);
                self.flip(u);
            }
        }
        (proposed, kept)
    }

    /// The log-odds of x_v = 1 given the rest of the world under the MLN (±∞ where a hard
    /// formula allows one value only).
    fn log_odds(&self, v: usize) -> f64 {
        let flat = self.flat;
        let occ = flat.occurrences(v);
        let now = self.x[v];
        // Log-weight of the flipped value minus the current one. A variable occurs at most
        // once in a clause (`simplify`), so each occurrence is one clause's change.
        let change = |o: Occ| -> i32 {
            let t = self.true_lits[o.clause as usize];
            let lit = o.eval(now);
            i32::from(!lit & (t == 0)) - i32::from(lit & (t == 1))
        };
        let mut gain = 0.0;
        let mut k = 0;
        while k < occ.len() {
            let o = occ[k];
            k += 1;
            let d = if o.single() {
                change(o)
            } else {
                let f = o.index();
                let n = flat.num_clauses(f) as i32;
                let now_sat = self.sat[f] as i32;
                let mut sat = now_sat + change(o);
                while k < occ.len() && occ[k].index() == f {
                    sat += change(occ[k]);
                    k += 1;
                }
                i32::from(sat == n) - i32::from(now_sat == n)
            };
            if o.hard() && d < 0 {
                // The flipped value breaks a hard formula: it has probability 0.
                return if now {
                    f64::INFINITY
                } else {
                    f64::NEG_INFINITY
                };
            }
            gain += o.weight * f64::from(d);
        }
        gain += if now {
            -flat.unary_bias[v]
        } else {
            flat.unary_bias[v]
        };
        if now {
            -gain
        } else {
            gain
        }
    }
}

/// The logistic function 1 / (1 + e^{−g}).
#[inline]
fn sigmoid(g: f64) -> f64 {
    1.0 / (1.0 + (-g).exp())
}

/// Forces atoms by unit propagation over the hard formulas' clauses.
fn propagate_hard(problem: &GroundProblem) -> Result<Vec<Option<bool>>, MarginalError> {
    let n = problem.atoms.len();
    let mut value: Vec<Option<bool>> = vec![None; n];
    // Hard clauses, deduplicated, tautologies dropped; (factor, literals).
    let mut clauses: Vec<(usize, Vec<Literal>)> = Vec::new();
    for (fi, f) in problem.factors.iter().enumerate() {
        if !f.hard {
            continue;
        }
        for c in &f.clauses {
            let mut ls = c.clone();
            ls.sort_unstable();
            ls.dedup();
            if ls.windows(2).any(|w| w[0].var() == w[1].var()) {
                continue; // x ∨ x̄
            }
            clauses.push((fi, ls));
        }
    }
    let mut watch: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (ci, (_, ls)) in clauses.iter().enumerate() {
        for l in ls {
            watch[l.var() as usize].push(ci as u32);
        }
    }
    let mut unassigned: Vec<u32> = clauses.iter().map(|(_, ls)| ls.len() as u32).collect();
    let mut satisfied = vec![false; clauses.len()];
    let mut queue: Vec<usize> = Vec::new();
    let assign = |v: usize,
                  b: bool,
                  fi: usize,
                  value: &mut Vec<Option<bool>>,
                  queue: &mut Vec<usize>|
     -> Result<(), MarginalError> {
        match value[v] {
            Some(old) if old != b => Err(MarginalError::HardConflict {
                atom: v,
                factor: fi,
            }),
            Some(_) => Ok(()),
            None => {
                value[v] = Some(b);
                queue.push(v);
                Ok(())
            }
        }
    };
    for (ci, (fi, ls)) in clauses.iter().enumerate() {
        if ls.len() == 1 {
            assign(
                ls[0].var() as usize,
                !ls[0].is_negated(),
                *fi,
                &mut value,
                &mut queue,
            )?;
        }
        if ls.is_empty() {
            return Err(MarginalError::HardConflict {
                atom: 0,
                factor: clauses[ci].0,
            });
        }
    }
    while let Some(v) = queue.pop() {
        let b = value[v].unwrap_or(false);
        for &ci in &watch[v] {
            let ci = ci as usize;
            if satisfied[ci] {
                continue;
            }
            let (fi, ls) = &clauses[ci];
            if ls.iter().any(|l| l.var() as usize == v && l.eval(b)) {
                satisfied[ci] = true;
                continue;
            }
            unassigned[ci] -= 1;
            match unassigned[ci] {
                0 => {
                    return Err(MarginalError::HardConflict {
                        atom: v,
                        factor: *fi,
                    })
                }
                1 => {
                    if let Some(l) = ls.iter().find(|l| value[l.var() as usize].is_none()) {
                        assign(
                            l.var() as usize,
                            !l.is_negated(),
                            *fi,
                            &mut value,
                            &mut queue,
                        )?;
                    }
                }
                _ => {}
            }
        }
    }
    Ok(value)
}

/// A world satisfying every hard formula, with the forced atoms set (WalkSAT from random).
fn hard_world(
    problem: &GroundProblem,
    hard: &[Factor],
    fixed: &[Option<bool>],
    options: &McSatOptions,
    rng: &mut ChaCha8Rng,
    seed: u64,
) -> Result<Vec<bool>, MarginalError> {
    let start: Vec<bool> = fixed
        .iter()
        .map(|f| f.unwrap_or_else(|| rng.gen_bool(0.5)))
        .collect();
    if hard.is_empty() {
        return Ok(start);
    }
    let frozen: Vec<bool> = fixed.iter().map(Option::is_some).collect();
    let (x, _) = max_walk_sat_frozen(
        hard,
        start.len(),
        Some(&start),
        Some(&frozen),
        &WalkSatOptions {
            max_flips: options.init_flips,
            chains: 1,
            noise: 0.5,
            seed,
        },
    );
    let violated = problem
        .factors
        .iter()
        .filter(|f| f.hard && !f.is_true(&x))
        .count();
    if violated > 0 {
        return Err(MarginalError::NoHardSolution {
            flips: options.init_flips,
            violated,
        });
    }
    Ok(x)
}

/// One chain's estimates, its (proposed, kept) moves, and per counted sample the true
/// counts of the first `formulas` formulas (none when 0).
type ChainRun = (Vec<f64>, u64, u64, Vec<Vec<f64>>);

/// Runs one chain (see [`ChainRun`]).
fn run_chain(
    problem: &GroundProblem,
    hard: &[Factor],
    flat: &Flat,
    fixed: &[Option<bool>],
    options: &McSatOptions,
    chain: usize,
    formulas: usize,
) -> Result<ChainRun, MarginalError> {
    let seed = options
        .seed
        .wrapping_mul(0x9E37_79B9_7F4A_7C15)
        .wrapping_add(chain as u64);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let x = hard_world(problem, hard, fixed, options, &mut rng, seed ^ 0x5A5A_5A5A)?;
    let mut c = Chain::new(flat, x, rng);
    let pairs = options.sweeps.max(1) * flat.pair_vars;
    // Occurrences of the paired atoms per step: an eighth of what one Gibbs sweep visits (a
    // pair visits them up to five times, so the pairs cost at most 5/8 of a sweep; an atom
    // in many formulas makes its pairs dear); small problems get at least 4 096, as many
    // pairs as atoms.
    let budget = options.sweeps.max(1)
        * flat
            .linked
            .iter()
            .map(|&v| flat.occurrences(v as usize).len())
            .sum::<usize>()
            .div_ceil(8)
            .max(4096);
    let mut sums = vec![0.0f64; problem.atoms.len()];
    // Per linked atom: the last log-odds seen and its probability (most atoms' neighbourhood
    // is the same as a step before, so e^x is mostly skipped).
    let mut last: Vec<(f64, f64)> = vec![(0.0, 0.5); flat.linked.len()];
    let mut counts = Vec::new();
    let (mut proposed, mut kept) = (0u64, 0u64);
    for step in 0..options.burn_in + options.samples {
        let (p, k) = c.slice_step(pairs, budget);
        proposed += p;
        kept += k;
        let counting = step >= options.burn_in;
        for (&v, last) in flat.linked.iter().zip(last.iter_mut()) {
            let v = v as usize;
            let lo = c.log_odds(v);
            let p1 = if lo == last.0 {
                last.1
            } else {
                // In single precision: e^x in f32 costs a third of f64's, and its relative
                // error (1e-7) is far below the sampling error of any estimate.
                let p = f64::from(1.0 / (1.0 + (-lo as f32).exp()));
                *last = (lo, p);
                p
            };
            if counting {
                sums[v] += p1;
            }
            if (c.rng.gen::<f64>() < p1) != c.x[v] {
                c.flip(v);
            }
        }
        if formulas > 0 {
            // The counts read every atom: the isolated ones are drawn too (nothing else
            // reads them, so they are skipped otherwise).
            for &(v, p1) in &flat.isolated {
                c.x[v as usize] = c.rng.gen::<f64>() < p1;
            }
        }
        if counting && formulas > 0 {
            counts.push(problem.true_counts(formulas, &c.x));
        }
    }
    let denom = options.samples.max(1) as f64;
    let mut p: Vec<f64> = sums.into_iter().map(|s| s / denom).collect();
    for &(v, p1) in &flat.isolated {
        p[v as usize] = p1;
    }
    for (v, f) in fixed.iter().enumerate() {
        if let Some(b) = f {
            p[v] = if *b { 1.0 } else { 0.0 };
        }
    }
    Ok((p, proposed, kept, counts))
}

/// Marginal probabilities of every unknown atom by MC-SAT.
pub fn mc_sat(problem: &GroundProblem, options: &McSatOptions) -> Result<Marginals, MarginalError> {
    Ok(sample(problem, options, 0)?.0)
}

/// MC-SAT's samples as the true counts n_i(x) of the first `formulas` formulas' soft ground
/// factors (the sufficient statistics of weight learning), one vector per counted sample of
/// every chain, with the marginals.
pub fn mc_sat_counts(
    problem: &GroundProblem,
    formulas: usize,
    options: &McSatOptions,
) -> Result<(Marginals, Vec<Vec<f64>>), MarginalError> {
    sample(problem, options, formulas.max(1))
}

/// Runs the chains; counts per sample when `formulas` > 0.
fn sample(
    problem: &GroundProblem,
    options: &McSatOptions,
    formulas: usize,
) -> Result<(Marginals, Vec<Vec<f64>>), MarginalError> {
    let t = Instant::now();
    let fixed = propagate_hard(problem)?;
    let flat = Flat::new(problem, &fixed)?;
    // The hard formulas as WalkSAT factors, once for every chain's first world.
    let hard: Vec<Factor> = problem
        .factors
        .iter()
        .filter(|f| f.hard)
        .map(|f| Factor {
            weight: 1.0,
            clauses: f.clauses.clone(),
        })
        .collect();
    let chains = options.chains.max(1);
    let mut runs: Vec<ChainRun> = (0..chains)
        .into_par_iter()
        .map(|c| run_chain(problem, &hard, &flat, &fixed, options, c, formulas))
        .collect::<Result<_, _>>()?;
    let counts: Vec<Vec<f64>> = runs
        .iter_mut()
        .flat_map(|r| std::mem::take(&mut r.3))
        .collect();
    let n = problem.atoms.len();
    let mut probabilities = vec![0.0; n];
    let mut spread = vec![0.0; n];
    let (mut max_spread, mut sum_spread) = (0.0f64, 0.0f64);
    for (i, p) in probabilities.iter_mut().enumerate() {
        let (mut lo, mut hi, mut sum) = (f64::INFINITY, f64::NEG_INFINITY, 0.0);
        for r in &runs {
            lo = lo.min(r.0[i]);
            hi = hi.max(r.0[i]);
            sum += r.0[i];
        }
        *p = sum / chains as f64;
        max_spread = max_spread.max(hi - lo);
        sum_spread += hi - lo;
        spread[i] = hi - lo;
    }
    let proposed: u64 = runs.iter().map(|r| r.1).sum();
    let kept: u64 = runs.iter().map(|r| r.2).sum();
    let marginals = Marginals {
        probabilities,
        fixed_atoms: fixed.iter().filter(|f| f.is_some()).count(),
        independent_atoms: flat.isolated.len(),
        slice_formulas: flat.keep.len(),
        chains,
        samples: options.samples,
        max_chain_spread: max_spread,
        mean_chain_spread: if n == 0 { 0.0 } else { sum_spread / n as f64 },
        spread,
        acceptance: if proposed == 0 {
            1.0
        } else {
            kept as f64 / proposed as f64
        },
        seconds: t.elapsed().as_secs_f64(),
    };
    Ok((marginals, counts))
}

/// The most unknown atoms [`exact_marginals`] enumerates.
pub const EXACT_MAX_ATOMS: usize = 24;

/// Exact marginal probabilities by enumerating every world (at most [`EXACT_MAX_ATOMS`]
/// unknown atoms).
pub fn exact_marginals(problem: &GroundProblem) -> Result<Vec<f64>, MarginalError> {
    let n = problem.atoms.len();
    if n > EXACT_MAX_ATOMS {
        return Err(MarginalError::TooManyAtoms {
            atoms: n,
            limit: EXACT_MAX_ATOMS,
        });
    }
    let worlds = 1usize << n;
    let log_weight = |w: usize| -> Option<f64> {
        let x: Vec<bool> = (0..n).map(|i| w >> i & 1 == 1).collect();
        let mut s = 0.0;
        for f in &problem.factors {
            let t = f.is_true(&x);
            if f.hard {
                if !t {
                    return None;
                }
            } else if t {
                s += f.weight;
            }
        }
        Some(s)
    };
    let logs: Vec<Option<f64>> = (0..worlds).into_par_iter().map(log_weight).collect();
    let max = logs
        .iter()
        .flatten()
        .copied()
        .fold(f64::NEG_INFINITY, f64::max);
    if max == f64::NEG_INFINITY {
        return Err(MarginalError::Unsatisfiable);
    }
    let mut z = 0.0;
    let mut ones = vec![0.0; n];
    for (w, l) in logs.iter().enumerate() {
        if let Some(l) = l {
            let p = (l - max).exp();
            z += p;
            for (i, o) in ones.iter_mut().enumerate() {
                if w >> i & 1 == 1 {
                    *o += p;
                }
            }
        }
    }
    Ok(ones.into_iter().map(|o| o / z).collect())
}
