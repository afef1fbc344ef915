//! MAP inference on a ground MLN: QPBO/QSSR (thesis §3.2.4) followed by exact enumeration or
//! tabu search on each component of the residue, or MaxWalkSAT on ground formulas or monomials.

use crate::ground::{GroundProblem, Scores};
use crate::walksat::{max_walk_sat, max_walk_sat_frozen, monomial_factors, Factor, WalkSatOptions};
use pbo::qssr::{search_residue, solve, QssrOptions, QssrRound};
use pbo::quadratize::Quadratizer;
use pbo::tabu::TabuOptions;
use std::time::Instant;

/// Which MAP algorithm to run.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Method {
    /// Quadratize → QPBO → QSSR → probe → improve; then each residue component is
    /// enumerated (≤ 20 atoms) or improved by tabu search.
    #[default]
    Qpbo,
    /// MaxWalkSAT on ground formulas (Alchemy style).
    MaxWalkSat,
    /// MaxWalkSAT on the monomials of the cost polynomial (thesis §3.2.4).
    MaxWalkSatMonomials,
}

impl Method {
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Method::Qpbo => "qpbo",
            Method::MaxWalkSat => "maxwalksat",
            Method::MaxWalkSatMonomials => "maxwalksat-monomials",
        }
    }
}

impl std::str::FromStr for Method {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [
            Method::Qpbo,
            Method::MaxWalkSat,
            Method::MaxWalkSatMonomials,
        ]
        .into_iter()
        .find(|m| m.name() == s)
        .ok_or_else(|| {
            format!("unknown method {s:?}: expected qpbo, maxwalksat or maxwalksat-monomials")
        })
    }
}

/// Terms with more negated literals stay in literal form in the multinomial representation.
const MULTINOMIAL_MAX_NEGATED: usize = 12;

/// Tabu-search flips per chain and residue variable at most: PR's residue is 1 773
/// components of about 40 atoms, each at its best cost within 2 000 flips (Tuffy's answer's
/// cost); 20 000 each took 124 s. Components above 200 atoms keep the full budget.
const TABU_MOVES_PER_VAR: usize = 100;

/// Which polynomial form QSSR minimises.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Representation {
    /// Literal monomials as grounded (x and x̄).
    Literal,
    /// Positive literals where affordable: x̄ expanded as 1 − x in terms of at most 12
    /// negated literals, so opposite-polarity terms merge (this makes the thesis' ID problem
    /// submodular); longer terms stay in literal form.
    Multinomial,
    /// The multinomial form: on LP, RC, ER, F&S and −F&S it labels exactly the atoms the
    /// literal form labels, and it solves ID, which the literal form leaves unlabelled.
    #[default]
    Auto,
}

impl Representation {
    /// The command-line name.
    pub fn name(self) -> &'static str {
        match self {
            Representation::Literal => "literal",
            Representation::Multinomial => "multinomial",
            Representation::Auto => "auto",
        }
    }
}

impl std::str::FromStr for Representation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        [
            Representation::Literal,
            Representation::Multinomial,
            Representation::Auto,
        ]
        .into_iter()
        .find(|r| r.name() == s)
        .ok_or_else(|| {
            format!("unknown representation {s:?}: expected literal, multinomial or auto")
        })
    }
}

/// Options of [`map_inference`].
#[derive(Debug, Clone)]
pub struct InferOptions {
    /// The algorithm.
    pub method: Method,
    /// Order reduction for the QPBO method.
    pub quadratizer: Quadratizer,
    /// Polynomial form for the QPBO method.
    pub representation: Representation,
    /// Probing in every QSSR round (off by default: on LP it adds 0.1 % persistencies
    /// for a 30× longer solve).
    pub probe: bool,
    /// QPBO-I rounds on the residue before tabu search (0 by default: tabu search from the
    /// zero-filled residue does as well on LP and ER, and QPBO-I costs 1.4 s on ER).
    pub improve_rounds: usize,
    /// QPBO method: tabu-search flips per chain on each residue component too large to
    /// enumerate (0: none); chains as in `walksat.chains`.
    pub tabu_moves: usize,
    /// MaxWalkSAT settings (also the seed of every random step).
    pub walksat: WalkSatOptions,
    /// QPBO method: flips of a MaxWalkSAT polish on the ground formulas, started from the
    /// QSSR answer with persistent atoms frozen (0: no polish). The polish never worsens it;
    /// on LP 200 000 flips lower the cost by 0.2 % for 1.4 s more.
    pub polish_flips: usize,
}

impl Default for InferOptions {
    fn default() -> Self {
        InferOptions {
            method: Method::Qpbo,
            quadratizer: Quadratizer::Asm,
            representation: Representation::Auto,
            probe: false,
            improve_rounds: 0,
            tabu_moves: 20_000,
            walksat: WalkSatOptions::default(),
            polish_flips: 0,
        }
    }
}

/// The MAP state and how it was found.
#[derive(Debug, Clone)]
pub struct MapResult {
    /// Truth value per unknown atom.
    pub assignment: Vec<bool>,
    /// Cost, violated weight and hard violations of `assignment`.
    pub scores: Scores,
    /// A lower bound on the cost (QPBO method only; hard weights included).
    pub lower_bound: Option<f64>,
    /// Atoms fixed by persistencies (QPBO method; 0 otherwise).
    pub persistent_fraction: f64,
    /// What each QSSR round did (QPBO method; empty otherwise).
    pub qssr_rounds: Vec<QssrRound>,
    /// Seconds quadratizing.
    pub seconds_quadratize: f64,
    /// Seconds solving (QPBO, probing, improve or WalkSAT).
    pub seconds_solve: f64,
}

/// The ground formulas as WalkSAT factors.
fn formula_factors(problem: &GroundProblem) -> Vec<Factor> {
    problem
        .factors
        .iter()
        .map(|f| Factor {
            weight: f.weight,
            clauses: f.clauses.clone(),
        })
        .collect()
}

/// Runs MAP inference on a ground problem.
pub fn map_inference(problem: &GroundProblem, options: &InferOptions) -> MapResult {
    let n = problem.atoms.len();
    let t = Instant::now();
    let mut qssr_rounds = Vec::new();
    let (assignment, lower_bound, persistent_fraction, seconds_quadratize) = match options.method {
        Method::Qpbo => {
            let qssr = QssrOptions {
                quadratizer: options.quadratizer,
                probe: options.probe,
                improve_rounds: options.improve_rounds,
                seed: options.walksat.seed,
                ..QssrOptions::default()
            };
            let run = |multinomial: bool| {
                let poly = if multinomial {
                    // Long clauses (EXIST expansions) stay in literal form.
                    problem.cost.to_multinomial_partial(MULTINOMIAL_MAX_NEGATED)
                } else {
                    problem.cost.clone()
                };
                solve(&poly, &qssr)
            };
            let r = match options.representation {
                Representation::Literal => run(false),
                Representation::Multinomial => run(true),
                // Measured on LP, RC, ER, F&S and −F&S: both forms give the same persistencies,
                // bound and (after tabu search) cost; only the multinomial form solves ID.
                Representation::Auto => run(true),
            };
            let mut assignment = r.assignment;
            qssr_rounds = r.rounds;
            if options.tabu_moves > 0 && !r.exact {
                // On the literal form whichever representation won: the same function,
                // and no 2^k expansion of long clauses.
                search_residue(
                    &problem.cost,
                    &r.persistent,
                    &mut assignment,
                    qssr.exact_residue_vars,
                    &TabuOptions {
                        moves: options.tabu_moves,
                        moves_per_var: TABU_MOVES_PER_VAR,
                        chains: options.walksat.chains,
                        seed: options.walksat.seed,
                        ..TabuOptions::default()
                    },
                );
            }
            if options.polish_flips > 0 && r.labelled_fraction < 1.0 {
                let frozen: Vec<bool> = r.persistent.iter().map(Option::is_some).collect();
                let (x, _) = max_walk_sat_frozen(
                    &formula_factors(problem),
                    n,
                    Some(&assignment),
                    Some(&frozen),
                    &WalkSatOptions {
                        max_flips: options.polish_flips,
                        ..options.walksat.clone()
                    },
                );
                if problem.cost.evaluate(&x) < problem.cost.evaluate(&assignment) {
                    assignment = x;
                }
            }
            (
                assignment,
                Some(r.lower_bound),
                r.labelled_fraction,
                r.seconds.quadratize,
            )
        }
        Method::MaxWalkSat => (
            max_walk_sat(&formula_factors(problem), n, None, &options.walksat).0,
            None,
            0.0,
            0.0,
        ),
        Method::MaxWalkSatMonomials => {
            let factors = monomial_factors(&problem.cost);
            (
                max_walk_sat(&factors, n, None, &options.walksat).0,
                None,
                0.0,
                0.0,
            )
        }
    };
    let total = t.elapsed().as_secs_f64();
    MapResult {
        scores: problem.score(&assignment),
        assignment,
        lower_bound,
        persistent_fraction,
        qssr_rounds,
        seconds_quadratize,
        seconds_solve: total - seconds_quadratize,
    }
}
