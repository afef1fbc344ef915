//! `urbansem mln …`: MAP and marginal inference on Markov logic networks.

use anyhow::Context;
use clap::{Args, Subcommand};
use mln::files::{
    benchmark_problem, learn_program, load_and_ground, marginal_text, result_text, score_answer,
    Benchmark, InferReport, LearnReport, MarginalReport, ProblemFiles, QuerySource, ScoreReport,
};
use mln::infer::{map_inference, InferOptions, Method, Representation};
use mln::marginal::{mc_sat, McSatOptions};
use pbo::quadratize::Quadratizer;
use std::path::PathBuf;
use std::time::Instant;

/// Subcommands of `urbansem mln`.
#[derive(Subcommand)]
pub enum MlnCommand {
    /// MAP inference (the most probable truth values of the query atoms) or, with
    /// `--marginal`, the probability of every query atom (MC-SAT).
    Infer(InferArgs),
    /// Generate a synthetic problem of the thesis (prog.mln, evidence.db, query.db).
    Generate(GenerateArgs),
    /// Score another engine's MAP answer (its true query atoms, one per line) with our evaluator.
    Score(ScoreArgs),
    /// Learn the soft weights discriminatively (voted perceptron on MAP counts).
    Learn(LearnArgs),
}

/// Options of `urbansem mln learn`.
#[derive(Args)]
pub struct LearnArgs {
    /// Program, training database (evidence plus labels: every atom of a query predicate in
    /// it is a label; unlisted ones are false) and query.
    #[command(flatten)]
    pub problem: ProblemArgs,
    /// Write the program with the learnt weights here.
    #[arg(short = 'o', long = "output")]
    pub output: PathBuf,
    /// Learning method: perceptron (voted perceptron) or newton (diagonal Newton, Lowd &
    /// Domingos 2007; always on MC-SAT samples).
    #[arg(long, default_value = "perceptron", value_parser = parse_learn_method)]
    pub method: mln::learn::LearnMethod,
    /// Expected counts of the perceptron from the MAP state (map) or MC-SAT samples (mcsat).
    #[arg(long, default_value = "map", value_parser = parse_expectations)]
    pub expectations: mln::learn::Expectations,
    /// MC-SAT samples per chain and epoch (mcsat expectations, newton).
    #[arg(long, default_value_t = 500)]
    pub samples: usize,
    /// Epochs (one MAP inference or MC-SAT run each).
    #[arg(long, default_value_t = 30)]
    pub epochs: usize,
    /// Base learning rate (per formula divided by its number of ground factors).
    #[arg(long, default_value_t = 1.0)]
    pub rate: f64,
    /// Gaussian prior strength (1/σ² per grounding; 0: none).
    #[arg(long, default_value_t = 0.0)]
    pub l2: f64,
    /// Start from the program's weights instead of 0.
    #[arg(long)]
    pub warm_start: bool,
    /// Seed of every random step of MAP inference.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// The ground problem's inputs, shared by `infer` and `score`.
#[derive(Args)]
pub struct ProblemArgs {
    /// The MLN program (Alchemy/Tuffy/RockIt syntax).
    #[arg(short = 'i', long = "input")]
    pub program: PathBuf,
    /// Evidence files (repeat or separate with commas).
    #[arg(short = 'e', long = "evidence", value_delimiter = ',')]
    pub evidence: Vec<PathBuf>,
    /// Query predicates, comma-separated.
    #[arg(short = 'q', long = "queries", conflicts_with = "query_file")]
    pub queries: Option<String>,
    /// A query file: one atom per line (variables allowed; ground atoms list a canopy).
    #[arg(long)]
    pub query_file: Option<PathBuf>,
    /// Refuse a formula with more groundings than this (about 100 bytes each).
    #[arg(long, default_value_t = mln::ground::GroundOptions::default().max_groundings, value_name = "N")]
    pub max_groundings: usize,
}

impl ProblemArgs {
    /// Grounding options: the cap, and lazy grounding (MAP-exact) when `lazy`.
    fn ground_options(&self, lazy: bool) -> mln::ground::GroundOptions {
        mln::ground::GroundOptions {
            max_groundings: self.max_groundings,
            lazy,
        }
    }
}

/// Options of `urbansem mln score`.
#[derive(Args)]
pub struct ScoreArgs {
    /// Program, evidence and query.
    #[command(flatten)]
    pub problem: ProblemArgs,
    /// The answer: ground atoms that are true (`P(A,B)`; `!P(A,B)` lines are false); every
    /// other unknown atom is false.
    #[arg(long)]
    pub answer: PathBuf,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Which synthetic problem to generate.
#[derive(Clone, Copy, Debug, clap::ValueEnum)]
pub enum Problem {
    /// Friends & Smokers (Table 3.1).
    Fs,
    /// Friends & Smokers with every weight negated.
    NegFs,
    /// Image denoising with triple smoothing rules.
    Id,
    /// IE: Tuffy's program with its evidence rebuilt from mfoilp's facts (`<data>/ie`).
    Ie,
    /// KB3: third-order webKB from `<data>/kb/mlcnn` (weights 0; also writes training.db).
    Kb3,
}

/// Options of `urbansem mln generate`.
#[derive(Args)]
pub struct GenerateArgs {
    /// fs, neg-fs or id.
    #[arg(value_enum)]
    pub problem: Problem,
    /// Persons (fs, neg-fs; thesis: 200) or image side in pixels (id; thesis: 90).
    #[arg(long)]
    pub size: Option<usize>,
    /// Seed of the evidence.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output folder.
    #[arg(long)]
    pub out: PathBuf,
    /// Folder of the MLN benchmark sets (ie, kb3 read their facts from it).
    #[arg(long, default_value = "../shared/data/mln")]
    pub data: PathBuf,
}

/// Options of `urbansem mln infer`.
#[derive(Args)]
pub struct InferArgs {
    /// Program, evidence and query.
    #[command(flatten)]
    pub problem: ProblemArgs,
    /// Write the MAP state of the query atoms here (Alchemy's format: `Atom(A,B) 1`); with
    /// `--marginal`, their probabilities (Tuffy's format: `0.7300<TAB>Atom(A,B)`).
    #[arg(short = 'r', long = "result")]
    pub result: Option<PathBuf>,
    /// Marginal inference (Alchemy's -ms, Tuffy's -marginal): the probability of every query
    /// atom by MC-SAT, instead of the MAP state.
    #[arg(long)]
    pub marginal: bool,
    /// MAP: ground every atom of the open predicates. By default, predicates that no formula
    /// could profit from making true are left false without grounding them (lazy, MAP-exact);
    /// marginal inference always grounds every atom.
    #[arg(long)]
    pub eager: bool,
    /// Marginal inference: counted samples per chain.
    #[arg(long, default_value_t = 5000, requires = "marginal")]
    pub samples: usize,
    /// Marginal inference: steps per chain before counting.
    #[arg(long, default_value_t = 500, requires = "marginal")]
    pub burn_in: usize,
    /// MAP algorithm: qpbo, maxwalksat, maxwalksat-monomials.
    #[arg(long, default_value = "qpbo", value_parser = parse_method)]
    pub method: Method,
    /// Order reduction for the qpbo method: ish, asm, fix, grd.
    #[arg(long, default_value = "asm", value_parser = parse_quadratizer)]
    pub quadratize: Quadratizer,
    /// Run probing (QPBO-P) in the QSSR rounds of the qpbo method (slower; rarely lowers the cost).
    #[arg(long)]
    pub probe: bool,
    /// Polynomial form for the qpbo method: literal, multinomial, or auto (= multinomial, which labels at least as much on every benchmark).
    #[arg(long, default_value = "auto", value_parser = parse_representation)]
    pub representation: Representation,
    /// Shorthand for --representation multinomial.
    #[arg(long)]
    pub multinomial: bool,
    /// QPBO-I rounds on the residue before tabu search (qpbo method).
    #[arg(long, default_value_t = 0)]
    pub improve: usize,
    /// Tabu-search flips per chain on each residue component of the qpbo method that is too
    /// large to enumerate (0: none).
    #[arg(long, default_value_t = 20_000, value_name = "MOVES")]
    pub tabu: usize,
    /// MaxWalkSAT flips polishing the qpbo answer (persistent atoms frozen; 0: none).
    #[arg(long, default_value_t = 0, value_name = "FLIPS")]
    pub polish: usize,
    /// Flips per MaxWalkSAT chain.
    #[arg(long, default_value_t = 1_000_000)]
    pub flips: usize,
    /// MaxWalkSAT (or, with --marginal, MC-SAT) chains run in parallel.
    #[arg(long, default_value_t = 2)]
    pub chains: usize,
    /// Seed of every random step.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Also write the ground problem as weighted partial MaxSAT (`p wcnf`) to this file.
    #[arg(long, value_name = "FILE")]
    pub export_wcnf: Option<PathBuf>,
    /// Soft weights in the WCNF are round(|w| · scale).
    #[arg(long, default_value_t = 1e6)]
    pub wcnf_scale: f64,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

fn parse_learn_method(s: &str) -> Result<mln::learn::LearnMethod, String> {
    s.parse()
}

fn parse_expectations(s: &str) -> Result<mln::learn::Expectations, String> {
    s.parse()
}

fn parse_method(s: &str) -> Result<Method, String> {
    s.parse()
}

fn parse_representation(s: &str) -> Result<Representation, String> {
    s.parse()
}

fn parse_quadratizer(s: &str) -> Result<Quadratizer, String> {
    s.parse()
}

/// Runs one `urbansem mln` subcommand.
pub fn run(command: MlnCommand) -> anyhow::Result<()> {
    match command {
        MlnCommand::Infer(args) => infer(&args),
        MlnCommand::Generate(args) => generate(&args),
        MlnCommand::Score(args) => score(&args),
        MlnCommand::Learn(args) => learn(&args),
    }
}

impl ProblemArgs {
    /// The problem's files; a usage error without a query.
    pub fn files(&self) -> anyhow::Result<ProblemFiles> {
        let query = match (self.queries.as_ref(), self.query_file.as_ref()) {
            (Some(list), _) => QuerySource::Predicates(list.clone()),
            (None, Some(f)) => QuerySource::File(f.clone()),
            (None, None) => super::usage!("no query: give -q Pred1,Pred2 or --query-file FILE"),
        };
        Ok(ProblemFiles {
            program: self.program.clone(),
            evidence: self.evidence.clone(),
            query,
        })
    }
}

impl From<Problem> for Benchmark {
    fn from(p: Problem) -> Self {
        match p {
            Problem::Fs => Benchmark::FriendsSmokers,
            Problem::NegFs => Benchmark::NegatedFriendsSmokers,
            Problem::Id => Benchmark::ImageDenoising,
            Problem::Ie => Benchmark::Ie,
            Problem::Kb3 => Benchmark::Kb3,
        }
    }
}

fn score(args: &ScoreArgs) -> anyhow::Result<()> {
    // Lazily, unless the answer makes an atom true that lazy grounding fixed false.
    let files = args.problem.files()?;
    let loaded = load_and_ground(&files, &args.problem.ground_options(true))?;
    let (a, s) = score_answer(&files, &loaded, &args.answer, args.problem.max_groundings)?;
    let report = ScoreReport {
        answer: args.answer.display().to_string(),
        answer_atoms: a.atoms,
        answer_atoms_not_unknown: a.not_unknown,
        cost: s.cost,
        violated_weight: s.violated_weight,
        hard_violations: s.hard_violations,
    };
    if args.json {
        super::print_json(&report)?;
    } else {
        print!("{}", report.text());
    }
    Ok(())
}

fn generate(args: &GenerateArgs) -> anyhow::Result<()> {
    write_generated(args.problem, args.size, args.seed, &args.data, &args.out)?;
    println!(
        "wrote prog.mln, evidence.db and query.db to {}",
        args.out.display()
    );
    Ok(())
}

/// Generates a synthetic problem (default size: the thesis') into `out`; IE and KB3 read
/// their facts from the data folder `data`.
fn write_generated(
    problem: Problem,
    size: Option<usize>,
    seed: u64,
    data: &std::path::Path,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let g = benchmark_problem(problem.into(), size, seed, data)?;
    for (name, text) in g.named_files() {
        let path = out.join(name);
        geodata::fsio::write_atomic(&path, text)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn learn(args: &LearnArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let mut options = mln::learn::LearnOptions {
        epochs: args.epochs,
        learning_rate: args.rate,
        l2: args.l2,
        start_from_program: args.warm_start,
        method: args.method,
        expectations: args.expectations,
        ..mln::learn::LearnOptions::default()
    }
    .seeded(args.seed);
    options.mcsat.samples = args.samples;
    let learnt = learn_program(&args.problem.files()?, &options)?;
    geodata::fsio::write_atomic(&args.output, &learnt.text)
        .with_context(|| format!("writing {}", args.output.display()))?;
    let r = LearnReport::new(
        &args.problem.program,
        &args.output,
        &learnt,
        t0.elapsed().as_secs_f64(),
    );
    if args.json {
        super::print_json(&r)?;
    } else {
        print!("{}", r.text());
    }
    Ok(())
}

fn infer(args: &InferArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let lazy = !args.marginal && !args.eager;
    let loaded = load_and_ground(&args.problem.files()?, &args.problem.ground_options(lazy))?;
    let problem = &loaded.problem;
    if let Some(path) = &args.export_wcnf {
        let mut w = geodata::fsio::AtomicFile::create(path)
            .with_context(|| format!("creating the WCNF file {}", path.display()))?;
        let summary = mln::wcnf::write_wcnf(problem, args.wcnf_scale, &mut w)
            .and_then(|s| w.commit().map(|()| s))
            .with_context(|| format!("writing {}", path.display()))?;
        eprintln!(
            "wrote {}: {} variables ({} auxiliary), {} hard and {} soft clauses; cost = optimum / {} {:+}",
            path.display(),
            summary.variables,
            summary.auxiliaries,
            summary.hard_clauses,
            summary.soft_clauses,
            args.wcnf_scale,
            summary.offset
        );
    }
    if args.marginal {
        return infer_marginal(args, &loaded, t0);
    }
    let mut options = InferOptions {
        method: args.method,
        quadratizer: args.quadratize,
        representation: if args.multinomial {
            Representation::Multinomial
        } else {
            args.representation
        },
        probe: args.probe,
        improve_rounds: args.improve,
        polish_flips: args.polish,
        tabu_moves: args.tabu,
        ..InferOptions::default()
    };
    options.walksat.seed = args.seed;
    options.walksat.max_flips = args.flips;
    options.walksat.chains = args.chains;
    let r = map_inference(problem, &options);
    let total_s = t0.elapsed().as_secs_f64();

    if let Some(path) = &args.result {
        let text = result_text(&loaded.program, problem, &loaded.query, &r.assignment);
        geodata::fsio::write_atomic(path, text)
            .with_context(|| format!("writing the result file {}", path.display()))?;
    }
    let report = InferReport::new(&loaded, &args.problem.program, &options, &r, total_s);
    if args.json {
        super::print_json(&report)?;
    } else {
        print!("{}", report.text());
    }
    Ok(())
}

/// `mln infer --marginal`: MC-SAT marginals of the query atoms.
fn infer_marginal(
    args: &InferArgs,
    loaded: &mln::files::Loaded,
    t0: Instant,
) -> anyhow::Result<()> {
    if args.samples == 0 {
        super::usage!("--samples must be at least 1");
    }
    let options = McSatOptions {
        samples: args.samples,
        burn_in: args.burn_in,
        chains: args.chains.max(1),
        seed: args.seed,
        ..McSatOptions::default()
    };
    let m = mc_sat(&loaded.problem, &options)
        .with_context(|| format!("marginal inference on {}", args.problem.program.display()))?;
    if let Some(path) = &args.result {
        let text = marginal_text(
            &loaded.program,
            &loaded.problem,
            &loaded.query,
            &m.probabilities,
        );
        geodata::fsio::write_atomic(path, text)
            .with_context(|| format!("writing the result file {}", path.display()))?;
    }
    let report = MarginalReport::new(
        loaded,
        &args.problem.program,
        &options,
        &m,
        t0.elapsed().as_secs_f64(),
    );
    if args.json {
        super::print_json(&report)?;
    } else {
        print!("{}", report.text());
    }
    Ok(())
}
