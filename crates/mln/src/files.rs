//! A problem on disk: program, evidence and query files read and grounded, another engine's
//! answer read as an assignment, the benchmark problems generated, weights learnt from a
//! training database — and the typed reports the command line and the Python package print.
//!
//! This module reads files and returns values; writing them (result files, generated
//! folders, learnt programs) is the caller's, which gets their text from here.

use crate::generate::{self, GenerateError, GeneratedMln};
use crate::ground::{
    expand_per_constant, ground, GroundError, GroundOptions, GroundProblem, Scores,
};
use crate::infer::MapResult;
use crate::learn::{self, LearnError, LearnOptions, Learnt, Training};
use crate::marginal::{Marginals, McSatOptions};
use crate::parse::{
    parse_query_predicates, read_evidence, read_program_sources, read_query, Atom, EvidenceAtom,
    ParseError, Program,
};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;
use thiserror::Error;

/// Why a problem's files could not be read, grounded or generated.
#[derive(Debug, Error)]
pub enum FilesError {
    /// The program does not parse (or cannot be read).
    #[error("reading the program")]
    Program(#[source] ParseError),
    /// An evidence file does not parse (or cannot be read).
    #[error("reading {}", path.display())]
    Evidence {
        /// The evidence file.
        path: PathBuf,
        /// What is wrong in it.
        #[source]
        source: ParseError,
    },
    /// A query predicate list names an unknown predicate.
    #[error(transparent)]
    QueryList(ParseError),
    /// The query file does not parse (or cannot be read).
    #[error("reading the query file")]
    QueryFile(#[source] ParseError),
    /// Grounding failed (a type clash, an empty domain…).
    #[error("grounding")]
    Ground(#[source] GroundError),
    /// The answer file does not parse (or cannot be read).
    #[error("reading the answer")]
    Answer(#[source] ParseError),
    /// A data file cannot be read.
    #[error("reading {}", path.display())]
    Read {
        /// The file.
        path: PathBuf,
        /// The I/O error.
        #[source]
        source: std::io::Error,
    },
    /// A benchmark's data files do not hold the facts expected.
    #[error("in {}", path.display())]
    Data {
        /// The data folder.
        path: PathBuf,
        /// What is wrong.
        #[source]
        source: GenerateError,
    },
    /// The training database cannot serve for learning.
    #[error("setting up the training problem")]
    Training(#[source] LearnError),
}

/// Where the query atoms come from.
#[derive(Debug, Clone, PartialEq)]
pub enum QuerySource {
    /// Query predicates, comma-separated (`Cancer,Smokes`): all their atoms.
    Predicates(String),
    /// A query file: one atom per line (variables allowed; ground atoms list a canopy).
    File(PathBuf),
}

/// The files of one MLN problem.
#[derive(Debug, Clone, PartialEq)]
pub struct ProblemFiles {
    /// The program (Alchemy/Tuffy/RockIt syntax).
    pub program: PathBuf,
    /// Evidence files, read in order.
    pub evidence: Vec<PathBuf>,
    /// The query.
    pub query: QuerySource,
}

impl ProblemFiles {
    /// The label grounding errors name for the evidence: its first file.
    fn evidence_label(&self, none: &str) -> String {
        self.evidence
            .first()
            .map_or_else(|| none.to_owned(), |p| p.display().to_string())
    }

    /// Reads the evidence files and the query against `program`.
    pub fn read_evidence_and_query(
        &self,
        program: &Program,
    ) -> Result<(Vec<EvidenceAtom>, Vec<Atom>), FilesError> {
        let mut evidence = Vec::new();
        for e in &self.evidence {
            evidence.extend(
                read_evidence(e, program).map_err(|source| FilesError::Evidence {
                    path: e.clone(),
                    source,
                })?,
            );
        }
        let query = match &self.query {
            QuerySource::Predicates(list) => {
                parse_query_predicates(list, program).map_err(FilesError::QueryList)?
            }
            QuerySource::File(f) => read_query(f, program).map_err(FilesError::QueryFile)?,
        };
        Ok((evidence, query))
    }
}

/// A problem read and grounded, with the seconds each step took.
#[derive(Debug, Clone)]
pub struct Loaded {
    /// The program.
    pub program: Program,
    /// The ground problem.
    pub problem: GroundProblem,
    /// The query atoms as read.
    pub query: Vec<Atom>,
    /// Seconds reading program, evidence and query.
    pub parse_seconds: f64,
    /// Seconds grounding.
    pub ground_seconds: f64,
}

impl ProblemFiles {
    /// Reads program, evidence and query, with the program's `+` formulas written out for
    /// the evidence's constants; also the text of every program file (`Program::sources`).
    pub fn read(&self) -> Result<ReadProblem, FilesError> {
        let (program, sources) =
            read_program_sources(&self.program).map_err(FilesError::Program)?;
        let (evidence, query) = self.read_evidence_and_query(&program)?;
        let program =
            expand_per_constant(program, &evidence, &query).map_err(FilesError::Ground)?;
        Ok(ReadProblem {
            program,
            sources,
            evidence,
            query,
        })
    }
}

/// A problem's files as read ([`ProblemFiles::read`]).
#[derive(Debug, Clone)]
pub struct ReadProblem {
    /// The program, `+` formulas written out.
    pub program: Program,
    /// The text of each of `program.sources`.
    pub sources: Vec<String>,
    /// The evidence (or training database).
    pub evidence: Vec<EvidenceAtom>,
    /// The query atoms.
    pub query: Vec<Atom>,
}

/// Reads program, evidence and query and grounds them.
pub fn load_and_ground(
    files: &ProblemFiles,
    options: &GroundOptions,
) -> Result<Loaded, FilesError> {
    let t0 = Instant::now();
    let ReadProblem {
        program,
        evidence,
        query,
        ..
    } = files.read()?;
    let parse_seconds = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let problem = ground(
        &program,
        &evidence,
        &files.evidence_label("(no evidence)"),
        &query,
        options,
    )
    .map_err(FilesError::Ground)?;
    Ok(Loaded {
        program,
        problem,
        query,
        parse_seconds,
        ground_seconds: t1.elapsed().as_secs_f64(),
    })
}

/// Another engine's MAP answer as an assignment of a ground problem's unknown atoms.
#[derive(Debug, Clone, PartialEq)]
pub struct AnswerAssignment {
    /// Truth value per unknown atom (atoms the answer does not list are false).
    pub assignment: Vec<bool>,
    /// Atoms (lines) in the answer.
    pub atoms: usize,
    /// Answer atoms that are not unknown atoms of the ground problem.
    pub not_unknown: usize,
    /// True answer atoms of predicates the problem grounded lazily (fixed false there):
    /// score such an answer on an eagerly grounded problem.
    pub lazily_false: usize,
}

/// The assignment an answer's atoms (true ones, `!` ones false) give the unknown atoms of
/// `problem`; atoms it does not list are false.
pub fn assignment_from_atoms(
    program: &Program,
    problem: &GroundProblem,
    answer: &[EvidenceAtom],
) -> AnswerAssignment {
    let index: HashMap<String, usize> = (0..problem.atoms.len())
        .map(|i| (problem.atom_name(program, i), i))
        .collect();
    let mut assignment = vec![false; problem.atoms.len()];
    let mut not_unknown = 0usize;
    let mut lazily_false = 0usize;
    for a in answer {
        let name = format!(
            "{}({})",
            program.predicates[a.predicate].name,
            a.args.join(",")
        );
        match index.get(&name) {
            Some(&i) => assignment[i] = a.value,
            None => {
                not_unknown += 1;
                if a.value && problem.inactive_predicates.contains(&a.predicate) {
                    lazily_false += 1;
                }
            }
        }
    }
    AnswerAssignment {
        assignment,
        atoms: answer.len(),
        not_unknown,
        lazily_false,
    }
}

/// Reads another engine's MAP answer file (true atoms, `!` lines false; Tuffy's and
/// Alchemy's result files) as an assignment of `problem`.
pub fn read_answer(
    program: &Program,
    problem: &GroundProblem,
    path: &Path,
) -> Result<AnswerAssignment, FilesError> {
    let answer = read_evidence(path, program).map_err(FilesError::Answer)?;
    Ok(assignment_from_atoms(program, problem, &answer))
}

/// Scores another engine's MAP answer on `loaded`, or, when it makes atoms true that lazy
/// grounding left out there, on `files` grounded eagerly with the same cap.
pub fn score_answer(
    files: &ProblemFiles,
    loaded: &Loaded,
    path: &Path,
    max_groundings: usize,
) -> Result<(AnswerAssignment, Scores), FilesError> {
    let a = read_answer(&loaded.program, &loaded.problem, path)?;
    if a.lazily_false == 0 {
        let s = loaded.problem.score(&a.assignment);
        return Ok((a, s));
    }
    let eager = load_and_ground(
        files,
        &GroundOptions {
            max_groundings,
            lazy: false,
        },
    )?;
    let a = read_answer(&eager.program, &eager.problem, path)?;
    let s = eager.problem.score(&a.assignment);
    Ok((a, s))
}

/// The MAP state of the query atoms in Alchemy's result format (`Atom(A,B) 1`, one per
/// line, sorted).
pub fn result_text(
    program: &Program,
    problem: &GroundProblem,
    query: &[Atom],
    assignment: &[bool],
) -> String {
    let mut text = String::new();
    for (atom, value) in query_values(program, problem, query, assignment) {
        text.push_str(&atom);
        text.push(' ');
        text.push(if value { '1' } else { '0' });
        text.push('\n');
    }
    text
}

/// Every ground atom of a query predicate with its truth value in `assignment`, sorted by
/// name (atoms written as in evidence files).
pub fn query_values(
    program: &Program,
    problem: &GroundProblem,
    query: &[Atom],
    assignment: &[bool],
) -> Vec<(String, bool)> {
    query_atoms(program, problem, query, assignment, false)
}

/// Every unknown atom of a query predicate with its value in `values` (`missing` past its
/// end), sorted by name.
fn query_atoms<T: Copy>(
    program: &Program,
    problem: &GroundProblem,
    query: &[Atom],
    values: &[T],
    missing: T,
) -> Vec<(String, T)> {
    let query_preds: Vec<usize> = query.iter().map(|a| a.predicate).collect();
    let mut out: Vec<(String, T)> = (0..problem.atoms.len())
        .filter(|&i| query_preds.contains(&problem.atoms[i].predicate))
        .map(|i| {
            (
                problem.atom_name(program, i),
                values.get(i).copied().unwrap_or(missing),
            )
        })
        .collect();
    out.sort_by(|a, b| a.0.cmp(&b.0));
    out
}

/// Every unknown atom of a query predicate with its probability, sorted by name (atoms
/// written as in evidence files).
pub fn query_probabilities(
    program: &Program,
    problem: &GroundProblem,
    query: &[Atom],
    probabilities: &[f64],
) -> Vec<(String, f64)> {
    query_atoms(program, problem, query, probabilities, 0.0)
}

/// The query atoms' probabilities in Tuffy's marginal result format (`0.7300<TAB>Atom(A,B)`,
/// one per line, sorted by atom).
pub fn marginal_text(
    program: &Program,
    problem: &GroundProblem,
    query: &[Atom],
    probabilities: &[f64],
) -> String {
    let mut text = String::new();
    for (atom, p) in query_probabilities(program, problem, query, probabilities) {
        let _ = writeln!(text, "{p:.4}\t{atom}");
    }
    text
}

/// A benchmark problem of the thesis that [`benchmark_problem`] generates.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Benchmark {
    /// Friends & Smokers (Table 3.1).
    FriendsSmokers,
    /// Friends & Smokers with every weight negated.
    NegatedFriendsSmokers,
    /// Image denoising with triple smoothing rules.
    ImageDenoising,
    /// IE: Tuffy's program with its evidence rebuilt from mfoilp's facts (`<data>/ie`).
    Ie,
    /// KB3: third-order webKB from `<data>/kb/mlcnn` (weights 0, learnt from its training
    /// database).
    Kb3,
}

/// A generated benchmark: the three files' contents and, for KB3, the training database.
#[derive(Debug, Clone, PartialEq)]
pub struct GeneratedBenchmark {
    /// `prog.mln`, `evidence.db`, `query.db`.
    pub files: GeneratedMln,
    /// `training.db` (KB3 only).
    pub training: Option<String>,
}

impl GeneratedBenchmark {
    /// The files of the problem folder as (name, text), in the order to write them.
    pub fn named_files(&self) -> Vec<(&'static str, &str)> {
        let mut out = Vec::with_capacity(4);
        if let Some(t) = &self.training {
            out.push(("training.db", t.as_str()));
        }
        out.push(("prog.mln", self.files.program.as_str()));
        out.push(("evidence.db", self.files.evidence.as_str()));
        out.push(("query.db", self.files.query.as_str()));
        out
    }
}

/// Reads a data file with its path in the error.
fn read_data(path: &Path) -> Result<String, FilesError> {
    std::fs::read_to_string(path).map_err(|source| FilesError::Read {
        path: path.to_owned(),
        source,
    })
}

/// Generates a benchmark problem (default size: the thesis'; persons for F&S, image side
/// for ID); IE and KB3 read their facts from the benchmark data folder `data`.
pub fn benchmark_problem(
    kind: Benchmark,
    size: Option<usize>,
    seed: u64,
    data: &Path,
) -> Result<GeneratedBenchmark, FilesError> {
    Ok(match kind {
        Benchmark::Ie => {
            let facts = data.join("ie/partial-evidence-mfoilp");
            GeneratedBenchmark {
                files: GeneratedMln {
                    program: read_data(&data.join("ie/tuffy/prog.mln"))?,
                    evidence: generate::ie_evidence_from_mfoilp(
                        &read_data(&facts.join("tokens"))?,
                        &read_data(&facts.join("similartitles"))?,
                        &read_data(&facts.join("jntinfcandidates"))?,
                    )
                    .map_err(|source| FilesError::Data {
                        path: facts.clone(),
                        source,
                    })?,
                    query: read_data(&data.join("ie/tuffy/query.db"))?,
                },
                training: None,
            }
        }
        Benchmark::Kb3 => {
            let dir = data.join("kb/mlcnn");
            let k = generate::kb3(
                &read_data(&dir.join("evidence.db"))?,
                &read_data(&dir.join("labels.db"))?,
                &generate::Kb3Options::default(),
                seed,
            )
            .map_err(|source| FilesError::Data {
                path: dir.clone(),
                source,
            })?;
            GeneratedBenchmark {
                files: k.files,
                training: Some(k.training),
            }
        }
        Benchmark::FriendsSmokers | Benchmark::NegatedFriendsSmokers => GeneratedBenchmark {
            files: generate::friends_smokers(
                &generate::FriendsSmokersOptions {
                    persons: size.unwrap_or(200),
                    negate: kind == Benchmark::NegatedFriendsSmokers,
                    ..generate::FriendsSmokersOptions::default()
                },
                seed,
            ),
            training: None,
        },
        Benchmark::ImageDenoising => GeneratedBenchmark {
            files: generate::image_denoising(size.unwrap_or(90), seed),
            training: None,
        },
    })
}

/// Weights learnt from a training database, with the program text carrying them.
#[derive(Debug, Clone)]
pub struct LearntProgram {
    /// The ground training problem.
    pub training: Training,
    /// The learnt weights and learning curve.
    pub learnt: Learnt,
    /// The program's source with the learnt weights written in.
    pub text: String,
}

/// Learns the soft weights of `files.program` from the training database `files.evidence`
/// (every atom of a query predicate in it is a label).
pub fn learn_program(
    files: &ProblemFiles,
    options: &LearnOptions,
) -> Result<LearntProgram, FilesError> {
    let ReadProblem {
        program,
        sources,
        evidence: database,
        query,
    } = files.read()?;
    let training = learn::training_problem(
        &program,
        &database,
        &files.evidence_label("(no database)"),
        &query,
    )
    .map_err(FilesError::Training)?;
    let learnt =
        learn::learn_weights(&program, &training, options).map_err(FilesError::Training)?;
    let sources: Vec<&str> = sources.iter().map(String::as_str).collect();
    let text = learn::with_weights(&sources, &program, &learnt.weights);
    Ok(LearntProgram {
        training,
        learnt,
        text,
    })
}

/// Seconds per phase of one `mln infer` run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct InferSeconds {
    /// Reading the files.
    pub parse: f64,
    /// Grounding.
    pub ground: f64,
    /// Quadratizing.
    pub quadratize: f64,
    /// Solving.
    pub solve: f64,
    /// Everything.
    pub total: f64,
}

/// What MAP inference on one problem found (`mln infer --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct InferReport {
    /// The program file.
    pub program: String,
    /// MAP algorithm.
    pub method: String,
    /// Order reduction.
    pub quadratize: String,
    /// Polynomial form.
    pub representation: String,
    /// Seed of every random step.
    pub seed: u64,
    /// Cost of the MAP state (violated soft weight, signed).
    pub cost: f64,
    /// Weight of the violated soft formulas.
    pub violated_weight: f64,
    /// Violated hard formulas.
    pub hard_violations: usize,
    /// A lower bound on the cost (QPBO method).
    pub lower_bound: Option<f64>,
    /// Unknown ground atoms.
    pub ground_atoms: usize,
    /// Ground formulas.
    pub ground_factors: usize,
    /// Ground formulas of order above two.
    pub higher_order_factors: usize,
    /// Share of atoms fixed by persistencies.
    pub persistent_fraction: f64,
    /// Atoms true in the MAP state.
    pub true_atoms: usize,
    /// Open predicates that lazy grounding left false (no formula gains from them true).
    pub lazily_false_predicates: Vec<String>,
    /// Seconds per phase.
    pub seconds: InferSeconds,
}

impl InferReport {
    /// The report of `result` on `loaded` (`total_seconds` from the start of reading).
    pub fn new(
        loaded: &Loaded,
        program: &Path,
        options: &crate::infer::InferOptions,
        result: &MapResult,
        total_seconds: f64,
    ) -> Self {
        Self {
            program: program.display().to_string(),
            method: options.method.name().to_owned(),
            quadratize: options.quadratizer.name().to_owned(),
            representation: options.representation.name().to_owned(),
            seed: options.walksat.seed,
            cost: result.scores.cost,
            violated_weight: result.scores.violated_weight,
            hard_violations: result.scores.hard_violations,
            lower_bound: result.lower_bound,
            ground_atoms: loaded.problem.atoms.len(),
            ground_factors: loaded.problem.factors.len(),
            higher_order_factors: loaded.problem.higher_order_factors(),
            persistent_fraction: result.persistent_fraction,
            true_atoms: result.assignment.iter().filter(|&&v| v).count(),
            lazily_false_predicates: loaded
                .problem
                .inactive_predicates
                .iter()
                .map(|&p| loaded.program.predicates[p].name.to_string())
                .collect(),
            seconds: InferSeconds {
                parse: loaded.parse_seconds,
                ground: loaded.ground_seconds,
                quadratize: result.seconds_quadratize,
                solve: result.seconds_solve,
                total: total_seconds,
            },
        }
    }

    /// The ground problem's size, the MAP state's cost and bound, and seconds per phase.
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{}: {} ground atoms, {} ground formulas ({} higher-order)",
            self.program, self.ground_atoms, self.ground_factors, self.higher_order_factors
        );
        let _ = writeln!(out, "method            {}", self.method);
        let _ = writeln!(out, "cost              {}", self.cost);
        let _ = writeln!(out, "violated weight   {}", self.violated_weight);
        let _ = writeln!(out, "hard violations   {}", self.hard_violations);
        if !self.lazily_false_predicates.is_empty() {
            let _ = writeln!(
                out,
                "left false        {} (lazy grounding: no formula gains from their atoms true)",
                self.lazily_false_predicates.join(", ")
            );
        }
        if let Some(lb) = self.lower_bound {
            let _ = writeln!(
                out,
                "lower bound       {lb}  (of cost + hard weight × violations)"
            );
            let _ = writeln!(
                out,
                "persistent        {:.2} %",
                100.0 * self.persistent_fraction
            );
        }
        let s = &self.seconds;
        let _ = writeln!(
            out,
            "seconds           parse {:.3}  ground {:.3}  quadratize {:.3}  solve {:.3}  total {:.3}",
            s.parse, s.ground, s.quadratize, s.solve, s.total
        );
        out
    }
}

/// Seconds per phase of one `mln infer --marginal` run.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MarginalSeconds {
    /// Reading the files.
    pub parse: f64,
    /// Grounding.
    pub ground: f64,
    /// Sampling (all chains).
    pub sample: f64,
    /// Everything.
    pub total: f64,
}

/// What marginal inference on one problem found (`mln infer --marginal --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct MarginalReport {
    /// The program file.
    pub program: String,
    /// The algorithm (`mc-sat`).
    pub method: String,
    /// Seed of every random step.
    pub seed: u64,
    /// Counted samples per chain.
    pub samples: usize,
    /// Steps per chain before counting.
    pub burn_in: usize,
    /// Chains run in parallel.
    pub chains: usize,
    /// Unknown ground atoms.
    pub ground_atoms: usize,
    /// Ground formulas.
    pub ground_factors: usize,
    /// Atoms the hard formulas force (probability exactly 0 or 1).
    pub fixed_atoms: usize,
    /// Atoms in no formula with another unforced atom (exact probability, not sampled).
    pub independent_atoms: usize,
    /// Distinct ground formulas over two or more unforced atoms, which the chains sample.
    pub slice_formulas: usize,
    /// The largest difference between two chains' estimates of one atom.
    pub max_chain_spread: f64,
    /// Its mean over atoms.
    pub mean_chain_spread: f64,
    /// Share of the moves inside the slice that were kept.
    pub acceptance: f64,
    /// Query atoms whose chains' estimates lie more than [`UNSETTLED_SPREAD`] apart: their
    /// probability is not to be trusted without more samples.
    pub unsettled_atoms: usize,
    /// The least settled of them (the [`UNSETTLED_LISTED`] of largest spread), by atom:
    /// atom → spread between the chains' estimates.
    pub unsettled: BTreeMap<String, f64>,
    /// Probability of every unknown query atom, by atom.
    pub marginals: BTreeMap<String, f64>,
    /// Seconds per phase.
    pub seconds: MarginalSeconds,
}

/// The chain spread above which a query atom counts as unsettled.
pub const UNSETTLED_SPREAD: f64 = 0.1;

/// How many unsettled atoms a marginal report lists.
pub const UNSETTLED_LISTED: usize = 20;

impl MarginalReport {
    /// The report of `result` on `loaded` (`total_seconds` from the start of reading).
    pub fn new(
        loaded: &Loaded,
        program: &Path,
        options: &McSatOptions,
        result: &Marginals,
        total_seconds: f64,
    ) -> Self {
        let mut unsettled: Vec<(String, f64)> = query_atoms(
            &loaded.program,
            &loaded.problem,
            &loaded.query,
            &result.spread,
            0.0,
        )
        .into_iter()
        .filter(|(_, s)| *s > UNSETTLED_SPREAD)
        .collect();
        unsettled.sort_by(|a, b| b.1.total_cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
        Self {
            program: program.display().to_string(),
            method: "mc-sat".to_owned(),
            seed: options.seed,
            samples: result.samples,
            burn_in: options.burn_in,
            chains: result.chains,
            ground_atoms: loaded.problem.atoms.len(),
            ground_factors: loaded.problem.factors.len(),
            fixed_atoms: result.fixed_atoms,
            independent_atoms: result.independent_atoms,
            slice_formulas: result.slice_formulas,
            max_chain_spread: result.max_chain_spread,
            mean_chain_spread: result.mean_chain_spread,
            acceptance: result.acceptance,
            unsettled_atoms: unsettled.len(),
            unsettled: unsettled.into_iter().take(UNSETTLED_LISTED).collect(),
            marginals: query_probabilities(
                &loaded.program,
                &loaded.problem,
                &loaded.query,
                &result.probabilities,
            )
            .into_iter()
            .collect(),
            seconds: MarginalSeconds {
                parse: loaded.parse_seconds,
                ground: loaded.ground_seconds,
                sample: result.seconds,
                total: total_seconds,
            },
        }
    }

    /// The problem's size, the sampler's diagnostics, seconds per phase and the most
    /// probable query atoms.
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{}: {} ground atoms, {} ground formulas",
            self.program, self.ground_atoms, self.ground_factors
        );
        let _ = writeln!(
            out,
            "method            mc-sat, {} chains × {} samples (burn-in {}), seed {}",
            self.chains, self.samples, self.burn_in, self.seed
        );
        let _ = writeln!(
            out,
            "fixed by hard     {} atoms (probability 0 or 1)",
            self.fixed_atoms
        );
        let _ = writeln!(
            out,
            "independent       {} atoms (exact, not sampled); {} distinct formulas sampled",
            self.independent_atoms, self.slice_formulas
        );
        let _ = writeln!(
            out,
            "chain spread      max {:.4}  mean {:.4}  (difference between chains' estimates)",
            self.max_chain_spread, self.mean_chain_spread
        );
        let _ = writeln!(out, "slice moves kept  {:.1} %", 100.0 * self.acceptance);
        let _ = writeln!(
            out,
            "unsettled         {} query atoms (chains > {UNSETTLED_SPREAD} apart; more samples or chains)",
            self.unsettled_atoms
        );
        let mut listed: Vec<(&String, &f64)> = self.unsettled.iter().collect();
        listed.sort_by(|a, b| b.1.total_cmp(a.1).then_with(|| a.0.cmp(b.0)));
        for (atom, s) in listed.into_iter().take(5) {
            let _ = writeln!(out, "  spread {s:.3}  {atom}");
        }
        let s = &self.seconds;
        let _ = writeln!(
            out,
            "seconds           parse {:.3}  ground {:.3}  sample {:.3}  total {:.3}",
            s.parse, s.ground, s.sample, s.total
        );
        let mut top: Vec<(&String, &f64)> = self.marginals.iter().collect();
        top.sort_by(|a, b| b.1.total_cmp(a.1).then_with(|| a.0.cmp(b.0)));
        let _ = writeln!(
            out,
            "query atoms       {} (the 10 most probable below; -r FILE or --json for all)",
            top.len()
        );
        for (atom, p) in top.into_iter().take(10) {
            let _ = writeln!(out, "  {p:.4}  {atom}");
        }
        out
    }
}

/// Another engine's answer scored by our evaluator (`mln score --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScoreReport {
    /// The answer file.
    pub answer: String,
    /// Atoms in the answer.
    pub answer_atoms: usize,
    /// Answer atoms that are not unknown atoms of the ground problem.
    pub answer_atoms_not_unknown: usize,
    /// Cost of the answer.
    pub cost: f64,
    /// Weight of the violated soft formulas.
    pub violated_weight: f64,
    /// Violated hard formulas.
    pub hard_violations: usize,
}

impl ScoreReport {
    /// The answer's size, cost and violations.
    pub fn text(&self) -> String {
        format!(
            "{}: {} atoms ({} are not unknown atoms of this ground problem)\n\
             cost              {}\n\
             violated weight   {}\n\
             hard violations   {}\n",
            self.answer,
            self.answer_atoms,
            self.answer_atoms_not_unknown,
            self.cost,
            self.violated_weight,
            self.hard_violations
        )
    }
}

/// One epoch of weight learning in a [`LearnReport`].
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LearnEpoch {
    /// Unknown atoms whose MAP value differs from the label.
    pub errors: usize,
    /// Σ_i |n_i(y) − n_i(y_w)| over learnable formulas.
    pub count_gap: f64,
}

/// What weight learning did (`mln learn --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LearnReport {
    /// The program file.
    pub program: String,
    /// The program written with the learnt weights.
    pub output: String,
    /// Unknown ground atoms of the training problem.
    pub ground_atoms: usize,
    /// Its ground formulas.
    pub ground_factors: usize,
    /// Labels in the database.
    pub labels: usize,
    /// Labels that are not unknown atoms.
    pub labels_unused: usize,
    /// Unknown atoms labelled true.
    pub true_atoms: usize,
    /// The method and its expectations (`perceptron/map`, `perceptron/mcsat`, `newton/mcsat`).
    pub method: String,
    /// The learning curve.
    pub epochs: Vec<LearnEpoch>,
    /// Training errors under the starting weights (MAP state, or rounded MC-SAT marginals).
    pub errors_start: usize,
    /// Training errors of the MAP state under the learnt weights.
    pub errors_learnt: usize,
    /// Per formula: the learnt weight (`None` for hard formulas).
    pub weights: Vec<Option<f64>>,
    /// Seconds.
    pub seconds: f64,
}

impl LearnReport {
    /// The report of a learnt program (`output`: where its text was written).
    pub fn new(program: &Path, output: &Path, learnt: &LearntProgram, seconds: f64) -> Self {
        let LearntProgram {
            training, learnt, ..
        } = learnt;
        Self {
            program: program.display().to_string(),
            output: output.display().to_string(),
            ground_atoms: training.problem.atoms.len(),
            ground_factors: training.problem.factors.len(),
            labels: training.labels,
            labels_unused: training.labels_unused,
            true_atoms: training.truth.iter().filter(|&&v| v).count(),
            method: learnt.method.to_owned(),
            epochs: learnt
                .epochs
                .iter()
                .map(|e| LearnEpoch {
                    errors: e.errors,
                    count_gap: e.count_gap,
                })
                .collect(),
            errors_start: learnt.epochs.first().map_or(0, |e| e.errors),
            errors_learnt: learnt.final_errors,
            weights: learnt.weights.clone(),
            seconds,
        }
    }

    /// The training problem's size, the training errors before and after, the output file.
    pub fn text(&self) -> String {
        format!(
            "{}: {} unknown atoms ({} true in the labels), {} ground formulas; {} labels ({} not unknown atoms)\n\
             training errors   {} (starting weights) -> {} (MAP under the learnt weights), {} epochs of {}\n\
             wrote {} in {:.2} s\n",
            self.program,
            self.ground_atoms,
            self.true_atoms,
            self.ground_factors,
            self.labels,
            self.labels_unused,
            self.errors_start,
            self.errors_learnt,
            self.epochs.len(),
            self.method,
            self.output,
            self.seconds
        )
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::parse::{parse_evidence, parse_program, parse_query};

    fn smokers() -> (Program, GroundProblem, Vec<Atom>) {
        let program = parse_program(
            "Smokes(person)\nCancer(person)\n1.5 Smokes(x) => Cancer(x)\n0.5 !Cancer(x)\n",
            "t.mln",
        )
        .unwrap();
        let evidence = parse_evidence("Smokes(Anna)\n!Smokes(Bob)\n", "e.db", &program).unwrap();
        let query = parse_query("Cancer(x)\n", "q.db", &program).unwrap();
        let problem = ground(
            &program,
            &evidence,
            "e.db",
            &query,
            &GroundOptions::default(),
        )
        .unwrap();
        (program, problem, query)
    }

    #[test]
    fn answer_atoms_map_to_unknown_atoms_and_the_rest_are_counted() {
        let (program, problem, _) = smokers();
        let answer = parse_evidence(
            "Cancer(Anna)\n!Cancer(Bob)\nSmokes(Anna)\n",
            "a.db",
            &program,
        )
        .unwrap();
        let a = assignment_from_atoms(&program, &problem, &answer);
        assert_eq!(a.atoms, 3);
        assert_eq!(a.not_unknown, 1, "Smokes(Anna) is evidence, not unknown");
        let names: Vec<(String, bool)> = (0..problem.atoms.len())
            .map(|i| (problem.atom_name(&program, i), a.assignment[i]))
            .collect();
        assert!(names.contains(&("Cancer(Anna)".to_owned(), true)));
        assert!(names.contains(&("Cancer(Bob)".to_owned(), false)));
    }

    #[test]
    fn result_text_lists_query_atoms_sorted_with_their_values() {
        let (program, problem, query) = smokers();
        let x: Vec<bool> = (0..problem.atoms.len())
            .map(|i| problem.atom_name(&program, i) == "Cancer(Anna)")
            .collect();
        assert_eq!(
            result_text(&program, &problem, &query, &x),
            "Cancer(Anna) 1\nCancer(Bob) 0\n"
        );
    }

    #[test]
    fn reports_print_one_value_per_line() {
        let score = ScoreReport {
            answer: "a.db".into(),
            answer_atoms: 3,
            answer_atoms_not_unknown: 1,
            cost: -1.5,
            violated_weight: 0.5,
            hard_violations: 0,
        };
        assert_eq!(
            score.text(),
            "a.db: 3 atoms (1 are not unknown atoms of this ground problem)\n\
             cost              -1.5\nviolated weight   0.5\nhard violations   0\n"
        );
    }

    #[test]
    fn missing_files_name_their_step() {
        let files = ProblemFiles {
            program: PathBuf::from("/nonexistent/prog.mln"),
            evidence: vec![],
            query: QuerySource::Predicates("Cancer".into()),
        };
        let err = load_and_ground(&files, &GroundOptions::default()).unwrap_err();
        assert!(matches!(err, FilesError::Program(_)), "{err}");
        let err = benchmark_problem(Benchmark::Ie, None, 0, Path::new("/nonexistent")).unwrap_err();
        assert!(
            err.to_string().contains("/nonexistent/ie/tuffy/prog.mln"),
            "{err}"
        );
    }
}
