//! Discriminative weight learning: the voted perceptron on MAP counts (or MC-SAT's), and
//! diagonal Newton on MC-SAT samples.
//!
//! Singla & Domingos, "Discriminative training of Markov logic networks", AAAI 2005: the
//! gradient of the conditional log-likelihood of the query atoms y given the evidence x with
//! respect to the weight of formula i is n_i(x, y) − E_w[n_i(x, Y)], with n_i the number of
//! true groundings; the perceptron replaces the expectation by the counts in the MAP state
//! y_w (found here by [`map_inference`], so QSSR and tabu search on our PBMLN), steps
//! `w_i += η_i (n_i(y) − n_i(y_w)) − η_i λ w_i` and returns the average of the epochs'
//! weights (the "voted" perceptron). Counts of formulas differ by orders of magnitude, so the
//! step of formula i is η / gᵢ with gᵢ its number of ground factors (Lowd & Domingos, ECML
//! 2007, §3: per-weight learning rates); λ is a Gaussian prior's 1/σ² per grounding.
//!
//! The training database holds the evidence and the labels: every atom of a query predicate
//! in it is a label (true, or false with `!`); unlisted atoms of query predicates are false,
//! as in inference's canopy convention. The program is grounded once with unit weights
//! (hard formulas stay hard, Tuffy's fixed `@w` weights stay fixed), and each epoch only
//! re-weights the ground factors ([`GroundProblem::with_formula_weights`]) and runs MAP.
//!
//! Cost per epoch: one MAP inference on the ground problem plus one pass over its factors;
//! with MC-SAT expectations one [`mc_sat_counts`] run instead (a pass over the factors per
//! sample). Diagonal Newton (Lowd & Domingos, PKDD 2007) is documented at its function.
//!
//! ```
//! use mln::learn::{learn_weights, training_problem, LearnOptions};
//! use mln::parse::{parse_evidence, parse_program, parse_query_predicates};
//! let p = parse_program("E(item)\nQ(item)\n0 E(x) => Q(x)\n0 Q(x)\n", "t.mln").unwrap();
//! let db = parse_evidence("E(A)\nE(B)\nQ(A)\nQ(B)\n!Q(C)\nE(D)\n", "t.db", &p).unwrap();
//! let q = parse_query_predicates("Q", &p).unwrap();
//! let training = training_problem(&p, &db, "t.db", &q).unwrap();
//! let learnt = learn_weights(&p, &training, &LearnOptions::default()).unwrap();
//! assert!(learnt.weights[0].unwrap() > 0.0);
//! ```

use crate::ground::{ground, GroundError, GroundOptions, GroundProblem};
use crate::infer::{map_inference, InferOptions};
use crate::marginal::{mc_sat_counts, MarginalError, McSatOptions};
use crate::parse::{Atom, EvidenceAtom, Origin, Program, Term, Weight};
use rustc_hash::{FxHashMap, FxHashSet};
use thiserror::Error;

/// Why training data could not be set up, or learning failed.
#[derive(Debug, Error)]
pub enum LearnError {
    /// MC-SAT could not sample the training problem (for expectations).
    #[error("sampling the training problem")]
    Sampling(#[from] MarginalError),
    /// Grounding the program failed.
    #[error(transparent)]
    Ground(#[from] GroundError),
    /// Unknown atoms of a predicate that has no labels (a hidden, open-world predicate).
    #[error("{path}: {atoms} unknown atoms of `{predicate}`, which is open-world but not a query predicate: learning needs labels for every unknown atom (mark it closed with `*` or add it to the query predicates)")]
    HiddenPredicate {
        /// Program file.
        path: String,
        /// The predicate.
        predicate: String,
        /// Its unknown atoms.
        atoms: usize,
    },
    /// The training database has no atom of a query predicate.
    #[error("{path}: no atom of a query predicate ({predicates}): the training database must list the labels")]
    NoLabels {
        /// Training database.
        path: String,
        /// The query predicates.
        predicates: String,
    },
}

/// The ground training problem: unit-weight factors and the labelled truth.
#[derive(Debug, Clone)]
pub struct Training {
    /// The program grounded with unit soft weights (fixed weights kept).
    pub problem: GroundProblem,
    /// The label of every unknown atom of `problem`.
    pub truth: Vec<bool>,
    /// Labels given in the database (true and false).
    pub labels: usize,
    /// Labels that are not unknown atoms of the ground problem (outside the canopy, or in
    /// no grounding that evidence leaves open).
    pub labels_unused: usize,
}

impl Training {
    /// Unknown atoms whose value in `x` differs from the label.
    pub fn errors(&self, x: &[bool]) -> usize {
        x.iter().zip(&self.truth).filter(|(a, b)| a != b).count()
    }
}

/// Splits a training database into evidence and labels (the atoms of query predicates).
pub fn split_labels(
    database: &[EvidenceAtom],
    query: &[Atom],
) -> (Vec<EvidenceAtom>, Vec<EvidenceAtom>) {
    let query_preds: FxHashSet<usize> = query.iter().map(|a| a.predicate).collect();
    database
        .iter()
        .cloned()
        .partition(|a| !query_preds.contains(&a.predicate))
}

/// The program with every learnable soft weight set to 1 (hard and fixed ones kept).
fn unit_weight_program(program: &Program) -> Program {
    let mut unit = program.clone();
    for f in &mut unit.formulas {
        if !f.fixed_weight && matches!(f.weight, Weight::Soft(_)) {
            f.weight = Weight::Soft(1.0);
        }
    }
    unit
}

/// Grounds a training database (evidence + labels, see the module doc) for learning.
pub fn training_problem(
    program: &Program,
    database: &[EvidenceAtom],
    database_path: &str,
    query: &[Atom],
) -> Result<Training, LearnError> {
    let (evidence, labels) = split_labels(database, query);
    let query_preds: FxHashSet<usize> = query.iter().map(|a| a.predicate).collect();
    if labels.is_empty() {
        let mut names: Vec<&str> = query_preds
            .iter()
            .map(|&p| program.predicates[p].name.as_str())
            .collect();
        names.sort_unstable();
        return Err(LearnError::NoLabels {
            path: database_path.to_owned(),
            predicates: names.join(", "),
        });
    }
    // Labels name constants too: list them as ground query atoms where the predicate is
    // queried in full (a canopy stays as given).
    let queried_in_full: FxHashSet<usize> = query
        .iter()
        .filter(|a| a.args.iter().any(|t| matches!(t, Term::Var(_))))
        .map(|a| a.predicate)
        .collect();
    let mut query = query.to_vec();
    query.extend(
        labels
            .iter()
            .filter(|l| queried_in_full.contains(&l.predicate))
            .map(|l| Atom {
                predicate: l.predicate,
                args: l
                    .args
                    .iter()
                    .map(|c| Term::Const(c.as_str().into()))
                    .collect(),
            }),
    );
    let unit = unit_weight_program(program);
    let problem = ground(
        &unit,
        &evidence,
        database_path,
        &query,
        &GroundOptions::default(),
    )?;
    let mut hidden: FxHashMap<usize, usize> = FxHashMap::default();
    for a in &problem.atoms {
        if !query_preds.contains(&a.predicate) {
            *hidden.entry(a.predicate).or_default() += 1;
        }
    }
    if let Some((&p, &atoms)) = hidden.iter().min_by_key(|(&p, _)| p) {
        return Err(LearnError::HiddenPredicate {
            path: program.path.clone(),
            predicate: program.predicates[p].name.to_string(),
            atoms,
        });
    }
    let const_ids: FxHashMap<&str, u32> = problem
        .constants
        .iter()
        .enumerate()
        .map(|(i, c)| (c.as_str(), i as u32))
        .collect();
    let atom_ids: FxHashMap<(usize, &[u32]), usize> = problem
        .atoms
        .iter()
        .enumerate()
        .map(|(i, a)| ((a.predicate, &a.args[..]), i))
        .collect();
    let mut truth = vec![false; problem.atoms.len()];
    let mut labels_unused = 0;
    for l in &labels {
        let args: Option<Vec<u32>> = l
            .args
            .iter()
            .map(|c| const_ids.get(c.as_str()).copied())
            .collect();
        match args.and_then(|args| atom_ids.get(&(l.predicate, &args[..])).copied()) {
            Some(i) => truth[i] = l.value,
            None => labels_unused += 1,
        }
    }
    Ok(Training {
        problem,
        truth,
        labels: labels.len(),
        labels_unused,
    })
}

/// The learning algorithm.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum LearnMethod {
    /// The voted perceptron (averaged weights).
    #[default]
    Perceptron,
    /// Diagonal Newton with a trust region (Lowd & Domingos 2007); needs MC-SAT samples.
    DiagonalNewton,
}

impl std::str::FromStr for LearnMethod {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "perceptron" => Ok(LearnMethod::Perceptron),
            "newton" | "diagonal-newton" => Ok(LearnMethod::DiagonalNewton),
            _ => Err(format!(
                "unknown learning method `{s}`: perceptron or newton"
            )),
        }
    }
}

/// Where the expected counts E_w\[nᵢ\] come from.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum Expectations {
    /// The counts of the MAP state (the voted perceptron's approximation).
    #[default]
    Map,
    /// The mean counts of MC-SAT samples.
    McSat,
}

impl std::str::FromStr for Expectations {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s {
            "map" => Ok(Expectations::Map),
            "mcsat" | "mc-sat" => Ok(Expectations::McSat),
            _ => Err(format!("unknown expectations `{s}`: map or mcsat")),
        }
    }
}

/// Options of [`learn_weights`].
#[derive(Debug, Clone)]
pub struct LearnOptions {
    /// Perceptron epochs (one MAP inference each).
    pub epochs: usize,
    /// Base step η; formula i steps η / (its ground factors) per unit of count difference.
    pub learning_rate: f64,
    /// Gaussian prior: 1/σ² per grounding, pulling each weight towards 0.
    pub l2: f64,
    /// Start from the program's weights (else from 0).
    pub start_from_program: bool,
    /// MAP inference in each epoch (its `walksat.seed` seeds every random step).
    pub infer: InferOptions,
    /// The algorithm.
    pub method: LearnMethod,
    /// Expected counts from MAP or MC-SAT (diagonal Newton always samples).
    pub expectations: Expectations,
    /// MC-SAT per epoch (its seed is offset by the epoch).
    pub mcsat: McSatOptions,
}

impl Default for LearnOptions {
    fn default() -> Self {
        LearnOptions {
            epochs: 30,
            learning_rate: 1.0,
            l2: 0.0,
            start_from_program: false,
            infer: InferOptions {
                tabu_moves: 5_000,
                ..InferOptions::default()
            },
            method: LearnMethod::Perceptron,
            expectations: Expectations::Map,
            mcsat: McSatOptions {
                samples: 500,
                burn_in: 100,
                ..McSatOptions::default()
            },
        }
    }
}

impl LearnOptions {
    /// The same options with every random step seeded by `seed`: MAP inference's and
    /// MC-SAT's.
    pub fn seeded(mut self, seed: u64) -> Self {
        self.infer.walksat.seed = seed;
        self.mcsat.seed = seed;
        self
    }
}

/// What one epoch saw: the MAP state under the epoch's starting weights.
#[derive(Debug, Clone, PartialEq)]
pub struct EpochStats {
    /// Unknown atoms whose MAP value differs from the label.
    pub errors: usize,
    /// Σ_i |n_i(y) − n_i(y_w)| over learnable formulas.
    pub count_gap: f64,
}

/// Learnt weights and the learning curve.
#[derive(Debug, Clone)]
pub struct Learnt {
    /// Per formula of the program: the learnt soft weight (fixed ones as given); `None`
    /// for hard formulas.
    pub weights: Vec<Option<f64>>,
    /// Per epoch (under the epoch's weights before its step).
    pub epochs: Vec<EpochStats>,
    /// Errors of the MAP state under the returned (averaged) weights.
    pub final_errors: usize,
    /// Ground factors per formula.
    pub groundings: Vec<usize>,
    /// The method and where its expectations came from, e.g. `perceptron/map`.
    pub method: &'static str,
}

/// The per-formula weights to ground with: learnable ones from `w`, fixed ones as given.
fn effective(program: &Program, w: &[f64]) -> Vec<f64> {
    program
        .formulas
        .iter()
        .zip(w)
        .map(|(f, &wi)| match f.weight {
            Weight::Soft(given) if f.fixed_weight => given,
            _ => wi,
        })
        .collect()
}

/// What learning needs of the training problem under any weights.
struct Setup<'a> {
    program: &'a Program,
    training: &'a Training,
    options: &'a LearnOptions,
    /// Formulas.
    k: usize,
    /// Soft formulas whose weight is not fixed.
    learnable: Vec<bool>,
    /// Soft ground factors per formula.
    groundings: Vec<usize>,
    /// n_i of the labels.
    truth_counts: Vec<f64>,
}

impl<'a> Setup<'a> {
    fn new(program: &'a Program, training: &'a Training, options: &'a LearnOptions) -> Self {
        let k = program.formulas.len();
        let mut groundings = vec![0usize; k];
        for f in training.problem.factors.iter().filter(|f| !f.hard) {
            groundings[f.formula] += 1;
        }
        Setup {
            program,
            training,
            options,
            k,
            learnable: program
                .formulas
                .iter()
                .map(|f| matches!(f.weight, Weight::Soft(_)) && !f.fixed_weight)
                .collect(),
            groundings,
            truth_counts: training.problem.true_counts(k, &training.truth),
        }
    }

    /// The starting weights: 0, or the program's (fixed weights always as given).
    fn start(&self) -> Vec<f64> {
        self.program
            .formulas
            .iter()
            .map(|f| match f.weight {
                Weight::Soft(given) if self.options.start_from_program || f.fixed_weight => given,
                _ => 0.0,
            })
            .collect()
    }

    fn map_under(&self, w: &[f64]) -> Vec<bool> {
        let p = self
            .training
            .problem
            .with_formula_weights(&effective(self.program, w));
        map_inference(&p, &self.options.infer).assignment
    }

    /// MC-SAT under `w` (seed offset by `epoch`): the marginals' errors (rounded at ½)
    /// and the per-sample counts.
    fn sample_under(&self, w: &[f64], epoch: usize) -> Result<(usize, Vec<Vec<f64>>), LearnError> {
        let p = self
            .training
            .problem
            .with_formula_weights(&effective(self.program, w));
        let options = McSatOptions {
            seed: self.options.mcsat.seed.wrapping_add(epoch as u64),
            ..self.options.mcsat.clone()
        };
        let (m, samples) = mc_sat_counts(&p, self.k, &options)?;
        let rounded: Vec<bool> = m.probabilities.iter().map(|&q| q > 0.5).collect();
        Ok((self.training.errors(&rounded), samples))
    }

    /// The learnt weights as reported: learnable ones from `w`, `None` for hard formulas.
    fn finish(&self, w: &[f64], epochs: Vec<EpochStats>) -> Learnt {
        let w = effective(self.program, w);
        let final_errors = self.training.errors(&self.map_under(&w));
        Learnt {
            weights: self
                .program
                .formulas
                .iter()
                .zip(&w)
                .map(|(f, &wi)| matches!(f.weight, Weight::Soft(_)).then_some(wi))
                .collect(),
            epochs,
            final_errors,
            groundings: self.groundings.clone(),
            method: match (self.options.method, self.options.expectations) {
                (LearnMethod::Perceptron, Expectations::Map) => "perceptron/map",
                (LearnMethod::Perceptron, Expectations::McSat) => "perceptron/mcsat",
                (LearnMethod::DiagonalNewton, _) => "newton/mcsat",
            },
        }
    }
}

/// Mean and variance per formula over count samples.
fn moments(samples: &[Vec<f64>], k: usize) -> (Vec<f64>, Vec<f64>) {
    let n = samples.len().max(1) as f64;
    let mut mean = vec![0.0; k];
    for s in samples {
        for (m, v) in mean.iter_mut().zip(s) {
            *m += v / n;
        }
    }
    let mut var = vec![0.0; k];
    for s in samples {
        for ((q, v), m) in var.iter_mut().zip(s).zip(&mean) {
            *q += (v - m) * (v - m) / n;
        }
    }
    (mean, var)
}

/// Learns the soft weights of `program` on one training problem: the voted perceptron
/// (MAP or MC-SAT expectations) or diagonal Newton (MC-SAT), as `options` says.
pub fn learn_weights(
    program: &Program,
    training: &Training,
    options: &LearnOptions,
) -> Result<Learnt, LearnError> {
    let setup = Setup::new(program, training, options);
    match options.method {
        LearnMethod::Perceptron => perceptron(&setup),
        LearnMethod::DiagonalNewton => diagonal_newton(&setup),
    }
}

/// Voted-perceptron weight learning (see the module doc).
fn perceptron(setup: &Setup<'_>) -> Result<Learnt, LearnError> {
    let (k, options) = (setup.k, setup.options);
    let mut w = setup.start();
    let mut sum = vec![0.0; k];
    let mut epochs = Vec::new();
    let total = options.epochs.max(1);
    for epoch in 0..total {
        let (errors, counts) = match options.expectations {
            Expectations::Map => {
                let y = setup.map_under(&w);
                (
                    setup.training.errors(&y),
                    setup.training.problem.true_counts(k, &y),
                )
            }
            Expectations::McSat => {
                let (errors, samples) = setup.sample_under(&w, epoch)?;
                (errors, moments(&samples, k).0)
            }
        };
        let mut gap = 0.0;
        for i in (0..k).filter(|&i| setup.learnable[i]) {
            let g = setup.truth_counts[i] - counts[i];
            gap += g.abs();
            let step = options.learning_rate / setup.groundings[i].max(1) as f64;
            w[i] += step * g - step * options.l2 * w[i];
        }
        epochs.push(EpochStats {
            errors,
            count_gap: gap,
        });
        for (s, wi) in sum.iter_mut().zip(&w) {
            *s += wi;
        }
        if gap == 0.0 && options.l2 == 0.0 {
            // A fixed point: the remaining epochs would add the same weights.
            let rest = (total - epoch - 1) as f64;
            for (s, wi) in sum.iter_mut().zip(&w) {
                *s += rest * wi;
            }
            break;
        }
    }
    let averaged: Vec<f64> = sum.iter().map(|s| s / total as f64).collect();
    Ok(setup.finish(&averaged, epochs))
}

/// Largest change of one weight in one diagonal-Newton step.
const NEWTON_MAX_STEP: f64 = 2.0;

/// Diagonal Newton (Lowd & Domingos, "Efficient weight learning for Markov logic networks",
/// PKDD 2007, §4): the gradient g = n(labels) − E_w[n] − λ₂w and the diagonal of the
/// Hessian −Var_w[n] − λ₂ from MC-SAT samples; direction dᵢ = gᵢ / (Var[nᵢ] + λ₂), step
/// α = dᵀg / (dᵀ Cov[n] d + λ dᵀd), with the trust-region λ halved when the gain in
/// conditional log-likelihood (estimated as Δwᵀ(g + g′)/2 from the gradients before and after
/// the step) exceeds ¾ of the predicted one, quadrupled when below ¼, and a step that loses
/// taken back. Returns the last accepted weights.
fn diagonal_newton(setup: &Setup<'_>) -> Result<Learnt, LearnError> {
    let (k, options) = (setup.k, setup.options);
    let l2 = options.l2;
    // Gradient and the samples' moments at w.
    let evaluate = |w: &[f64], epoch: usize| -> Result<_, LearnError> {
        let (errors, samples) = setup.sample_under(w, epoch)?;
        let (mean, var) = moments(&samples, k);
        let g: Vec<f64> = (0..k)
            .map(|i| {
                if setup.learnable[i] {
                    setup.truth_counts[i] - mean[i] - l2 * w[i]
                } else {
                    0.0
                }
            })
            .collect();
        Ok((errors, g, var, samples, mean))
    };
    let dot = |a: &[f64], b: &[f64]| a.iter().zip(b).map(|(x, y)| x * y).sum::<f64>();
    let mut w = setup.start();
    let mut lambda = 1.0f64;
    let (errors, mut g, mut var, mut samples, mut mean) = evaluate(&w, 0)?;
    let mut epochs = vec![EpochStats {
        errors,
        count_gap: g.iter().map(|x| x.abs()).sum(),
    }];
    for epoch in 1..options.epochs.max(1) {
        // Step from the accepted point.
        let d: Vec<f64> = (0..k)
            .map(|i| {
                if setup.learnable[i] {
                    g[i] / (var[i] + l2 + 1e-6)
                } else {
                    0.0
                }
            })
            .collect();
        let dg = dot(&d, &g);
        if dg <= 0.0 {
            break;
        }
        // dᵀ Cov[n] d: the variance of the projected counts.
        let proj: Vec<f64> = samples.iter().map(|s| dot(&d, s)).collect();
        let pm = dot(&d, &mean);
        let dcd = proj.iter().map(|p| (p - pm) * (p - pm)).sum::<f64>() / proj.len().max(1) as f64
            + l2 * dot(&d, &d);
        let alpha = dg / (dcd + lambda * dot(&d, &d));
        let step: Vec<f64> = d
            .iter()
            .map(|di| (alpha * di).clamp(-NEWTON_MAX_STEP, NEWTON_MAX_STEP))
            .collect();
        let predicted = dot(&step, &g) - 0.5 * alpha * alpha * dcd;
        let candidate: Vec<f64> = w.iter().zip(&step).map(|(a, b)| a + b).collect();
        let (errors, g2, var2, samples2, mean2) = evaluate(&candidate, epoch)?;
        let actual = 0.5 * (dot(&step, &g) + dot(&step, &g2));
        epochs.push(EpochStats {
            errors,
            count_gap: g2.iter().map(|x| x.abs()).sum(),
        });
        if actual < 0.0 {
            // The step lost: stay, and shrink the region.
            lambda *= 4.0;
            continue;
        }
        let ratio = actual / predicted.max(1e-12);
        if ratio > 0.75 {
            lambda = (lambda / 2.0).max(1e-6);
        } else if ratio < 0.25 {
            lambda *= 4.0;
        }
        (w, g, var, samples, mean) = (candidate, g2, var2, samples2, mean2);
    }
    Ok(setup.finish(&w, epochs))
}

/// Errors of the MAP state under the given per-formula weights (hard formulas ignored).
pub fn map_errors(training: &Training, weights: &[f64], infer: &InferOptions) -> usize {
    let p = training.problem.with_formula_weights(weights);
    training.errors(&map_inference(&p, infer).assignment)
}

/// The program's text with the soft weights of its formulas replaced. `sources[i]` is the
/// text of `program.sources[i]`; formula i is on its source's line `program.formulas[i].line`.
/// A written formula's leading weight is replaced (an absent one added); a line that Alchemy's
/// `*` or `+` expands is written out as its formulas, one per line, each with its weight;
/// hard formulas, fixed `@w` weights and `!` constraints are left as written; an
/// `#include` line is replaced by the included file's text, weights written in.
pub fn with_weights(sources: &[&str], program: &Program, weights: &[Option<f64>]) -> String {
    let mut files: Vec<Vec<String>> = sources
        .iter()
        .map(|s| s.lines().map(str::to_owned).collect())
        .collect();
    // Formulas by (file, line), in program order.
    let mut by_line: FxHashMap<(usize, usize), Vec<usize>> = FxHashMap::default();
    for (i, f) in program.formulas.iter().enumerate() {
        if f.origin != Origin::Block {
            by_line.entry((f.source, f.line)).or_default().push(i);
        }
    }
    let mut keys: Vec<_> = by_line.keys().copied().collect();
    keys.sort_unstable();
    for key in keys {
        let group = &by_line[&key];
        let Some(line) = files
            .get_mut(key.0)
            .and_then(|f| key.1.checked_sub(1).and_then(|i| f.get_mut(i)))
        else {
            continue;
        };
        let first = &program.formulas[group[0]];
        if first.origin == Origin::Written {
            let (Some(Some(w)), false) = (weights.get(group[0]), first.fixed_weight) else {
                continue;
            };
            let body = line.trim_start();
            let head = body.split_whitespace().next().unwrap_or("");
            let rest = if !head.is_empty() && head.parse::<f64>().is_ok() {
                body[head.len()..].trim_start()
            } else {
                body
            };
            *line = format!("{w:.6} {rest}");
            continue;
        }
        // An expanded line: its formulas written out.
        let mut out = Vec::with_capacity(group.len());
        for &i in group {
            let f = &program.formulas[i];
            let text = program.formula_text(&f.formula);
            out.push(match (f.weight, weights.get(i).copied().flatten()) {
                (Weight::Hard, _) => format!("{text}."),
                (Weight::Soft(given), _) if f.fixed_weight => format!("@{given} {text}"),
                (Weight::Soft(_), Some(w)) => format!("{w:.6} {text}"),
                (Weight::Soft(given), None) => format!("{given} {text}"),
            });
        }
        *line = out.join("\n");
    }
    // Included files into their #include lines, innermost first (a file's includes come
    // after it in `sources`).
    for j in (1..files.len()).rev() {
        let Some((parent, line)) = program.sources.get(j).and_then(|s| s.included_at) else {
            continue;
        };
        let text = std::mem::take(&mut files[j]).join("\n");
        if let Some(l) = files
            .get_mut(parent)
            .and_then(|f| line.checked_sub(1).and_then(|i| f.get_mut(i)))
        {
            *l = text;
        }
    }
    let mut out = files.first().map(|f| f.join("\n")).unwrap_or_default();
    out.push('\n');
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::parse::{parse_evidence, parse_program, parse_query_predicates};
    use rand::{Rng, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Items with a hidden label Q and three noisy observations: E1 agrees with Q 90 % of
    /// the time, E2 70 %, E3 15 % (mostly the opposite).
    fn noisy_copies(items: usize, seed: u64) -> (Program, Vec<EvidenceAtom>) {
        let program = parse_program(
            "E1(item)\nE2(item)\nE3(item)\nQ(item)\n\
             0 E1(x) <=> Q(x)\n0 E2(x) <=> Q(x)\n0 E3(x) <=> Q(x)\n0 Q(x)\n",
            "noisy.mln",
        )
        .unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut db = String::new();
        for i in 0..items {
            let q = rng.gen_bool(0.5);
            db += &format!("{}Q(I{i})\n", if q { "" } else { "!" });
            for (e, agree) in [("E1", 0.9), ("E2", 0.7), ("E3", 0.15)] {
                let v = if rng.gen_bool(agree) { q } else { !q };
                if v {
                    db += &format!("{e}(I{i})\n");
                }
            }
        }
        let database = parse_evidence(&db, "noisy.db", &program).unwrap();
        (program, database)
    }

    #[test]
    fn labels_are_split_from_evidence_and_mapped_to_atoms() {
        let (program, db) = noisy_copies(20, 1);
        let q = parse_query_predicates("Q", &program).unwrap();
        let (evidence, labels) = split_labels(&db, &q);
        assert_eq!(labels.len(), 20);
        assert!(evidence.iter().all(|a| a.predicate != 3));
        let t = training_problem(&program, &db, "noisy.db", &q).unwrap();
        assert_eq!(t.problem.atoms.len(), 20);
        assert_eq!(t.labels_unused, 0);
        assert_eq!(
            t.truth.iter().filter(|&&v| v).count(),
            labels.iter().filter(|a| a.value).count()
        );
    }

    #[test]
    fn perceptron_recovers_sign_and_order_of_the_observations() {
        let (program, db) = noisy_copies(300, 7);
        let q = parse_query_predicates("Q", &program).unwrap();
        let t = training_problem(&program, &db, "noisy.db", &q).unwrap();
        let learnt = learn_weights(&program, &t, &LearnOptions::default()).unwrap();
        let w: Vec<f64> = learnt.weights.iter().map(|w| w.unwrap()).collect();
        assert!(w[0] > w[1] && w[1] > 0.0 && w[2] < 0.0, "weights {w:?}");
        // The learnt weights predict the labels better than zero weights, and about as well
        // as the best single observation (E1, 10 % noise) allows.
        let zero = map_errors(&t, &[0.0; 4], &LearnOptions::default().infer);
        assert!(
            learnt.final_errors < zero,
            "{} vs {zero}",
            learnt.final_errors
        );
        assert!(
            learnt.final_errors <= 300 / 10 + 15,
            "{}",
            learnt.final_errors
        );
    }

    /// The exact conditional-likelihood optimum of the noisy copies (items independent,
    /// two states each), by gradient ascent on the exact gradient.
    fn exact_optimum(db: &[EvidenceAtom], items: usize) -> Vec<f64> {
        let mut e = vec![[false; 3]; items];
        let mut y = vec![false; items];
        for a in db {
            let i: usize = a.args[0][1..].parse().unwrap();
            match a.predicate {
                3 => y[i] = a.value,
                k => e[i][k] = a.value,
            }
        }
        // Features of (item, q): [e_k == q] for k < 3, and q.
        let f = |ei: &[bool; 3], q: bool| -> [f64; 4] {
            let b = |v: bool| f64::from(u8::from(v));
            [b(ei[0] == q), b(ei[1] == q), b(ei[2] == q), b(q)]
        };
        let mut w = [0.0f64; 4];
        for _ in 0..20_000 {
            let mut g = [0.0f64; 4];
            for (ei, &yi) in e.iter().zip(&y) {
                let (f1, f0) = (f(ei, true), f(ei, false));
                let s: f64 = (0..4).map(|k| w[k] * (f1[k] - f0[k])).sum();
                let p1 = 1.0 / (1.0 + (-s).exp());
                let fy = f(ei, yi);
                for k in 0..4 {
                    g[k] += fy[k] - (p1 * f1[k] + (1.0 - p1) * f0[k]);
                }
            }
            for k in 0..4 {
                w[k] += 2.0 * g[k] / items as f64;
            }
        }
        w.to_vec()
    }

    #[test]
    fn diagonal_newton_reaches_the_exact_likelihood_optimum() {
        let items = 300;
        let (program, db) = noisy_copies(items, 7);
        let q = parse_query_predicates("Q", &program).unwrap();
        let t = training_problem(&program, &db, "noisy.db", &q).unwrap();
        let exact = exact_optimum(&db, items);
        let options = LearnOptions {
            method: LearnMethod::DiagonalNewton,
            epochs: 40,
            ..LearnOptions::default()
        };
        let learnt = learn_weights(&program, &t, &options).unwrap();
        assert_eq!(learnt.method, "newton/mcsat");
        let w: Vec<f64> = learnt.weights.iter().map(|w| w.unwrap()).collect();
        for (a, b) in w.iter().zip(&exact) {
            assert!((a - b).abs() < 0.05, "newton {w:?} vs exact {exact:?}");
        }
        // The perceptron on MC-SAT expectations moves the same way (averaged: less far).
        let options = LearnOptions {
            expectations: Expectations::McSat,
            ..LearnOptions::default()
        };
        let p = learn_weights(&program, &t, &options).unwrap();
        let w: Vec<f64> = p.weights.iter().map(|w| w.unwrap()).collect();
        assert!(w[0] > w[1] && w[1] > 0.0 && w[2] < 0.0, "weights {w:?}");
    }

    #[test]
    fn collective_rule_gets_a_positive_weight() {
        // Linked items share their label; only half of the items have an observation.
        let program = parse_program(
            "Obs(item)\nLink(item,item)\nQ(item)\n\
             0 Obs(x) => Q(x)\n0 Q(x) ^ Link(x,y) => Q(y)\n0 Q(x)\n",
            "collective.mln",
        )
        .unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(3);
        let mut db = String::new();
        for group in 0..40 {
            let q = rng.gen_bool(0.5);
            for k in 0..4 {
                let i = group * 4 + k;
                if q {
                    db += &format!("Q(I{i})\n");
                    if k == 0 {
                        db += &format!("Obs(I{i})\n");
                    }
                }
                if k > 0 {
                    db += &format!("Link(I{},I{i})\nLink(I{i},I{})\n", i - 1, i - 1);
                }
            }
        }
        let database = parse_evidence(&db, "c.db", &program).unwrap();
        let q = parse_query_predicates("Q", &program).unwrap();
        let t = training_problem(&program, &database, "c.db", &q).unwrap();
        let learnt = learn_weights(&program, &t, &LearnOptions::default()).unwrap();
        let w: Vec<f64> = learnt.weights.iter().map(|w| w.unwrap()).collect();
        assert!(w[0] > 0.0 && w[1] > 0.0 && w[2] < 0.0, "weights {w:?}");
        assert_eq!(learnt.final_errors, 0, "weights {w:?}");
    }

    #[test]
    fn hidden_open_predicate_and_missing_labels_are_errors() {
        let program = parse_program(
            "*E(item)\nH(item)\nQ(item)\n0 E(x) ^ H(x) => Q(x)\n",
            "h.mln",
        )
        .unwrap();
        let db = parse_evidence("E(A)\nQ(A)\n", "h.db", &program).unwrap();
        let q = parse_query_predicates("Q", &program).unwrap();
        let e = training_problem(&program, &db, "h.db", &q).unwrap_err();
        assert!(
            matches!(e, LearnError::HiddenPredicate { ref predicate, .. } if predicate == "H"),
            "{e}"
        );
        let db = parse_evidence("E(A)\n", "h.db", &program).unwrap();
        let e = training_problem(&program, &db, "h.db", &q).unwrap_err();
        assert!(
            e.to_string().contains("no atom of a query predicate (Q)"),
            "{e}"
        );
    }

    #[test]
    fn weights_are_written_back_into_the_source() {
        let source =
            "// c\nE(item)\nQ(item)\n1.5 E(x) => Q(x)\nQ(x) ^ E(x)\n@2 Q(x)\nE(x) => !Q(x).\n";
        let program = parse_program(source, "w.mln").unwrap();
        let text = with_weights(
            &[source],
            &program,
            &[Some(-0.25), Some(3.0), Some(9.0), None],
        );
        let back = parse_program(&text, "w2.mln").unwrap();
        let weights: Vec<Weight> = back.formulas.iter().map(|f| f.weight).collect();
        assert_eq!(
            weights,
            [
                Weight::Soft(-0.25),
                Weight::Soft(3.0),
                Weight::Soft(2.0),
                Weight::Hard
            ]
        );
        assert!(back.formulas[2].fixed_weight);
        assert!(text.starts_with("// c\n"));
    }
}
