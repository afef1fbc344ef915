//! `urbansem mln …`: MAP inference on Markov logic networks.

use anyhow::Context;
use clap::{Args, Subcommand};
use mln::ground::{ground, GroundOptions};
use mln::infer::{map_inference, InferOptions, Method, Representation};
use mln::parse::{parse_query_predicates, read_evidence, read_program, read_query};
use pbo::quadratize::Quadratizer;
use serde_json::json;
use std::path::PathBuf;
use std::time::Instant;

/// Subcommands of `urbansem mln`.
#[derive(Subcommand)]
pub enum MlnCommand {
    /// MAP inference: the most probable truth values of the query atoms.
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
    /// Perceptron epochs (one MAP inference each).
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
    /// Write the MAP state of the query atoms here (Alchemy's format: `Atom(A,B) 1`).
    #[arg(short = 'r', long = "result")]
    pub result: Option<PathBuf>,
    /// MAP algorithm: qpbo, maxwalksat, maxwalksat-monomials.
    #[arg(long, default_value = "qpbo", value_parser = parse_method)]
    pub method: Method,
    /// Order reduction for the qpbo method: ish, asm, fix.
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
    /// MaxWalkSAT chains run in parallel.
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

/// Reads the evidence files and the query (`-q` list or query file) of a program.
fn read_evidence_and_query(
    args: &ProblemArgs,
    program: &mln::parse::Program,
) -> anyhow::Result<(Vec<mln::parse::EvidenceAtom>, Vec<mln::parse::Atom>)> {
    let mut evidence = Vec::new();
    for e in &args.evidence {
        evidence
            .extend(read_evidence(e, program).with_context(|| format!("reading {}", e.display()))?);
    }
    let query = match (args.queries.as_deref(), args.query_file.as_deref()) {
        (Some(list), _) => parse_query_predicates(list, program)?,
        (None, Some(f)) => read_query(f, program).context("reading the query file")?,
        (None, None) => super::usage!("no query: give -q Pred1,Pred2 or --query-file FILE"),
    };
    Ok((evidence, query))
}

/// Reads program, evidence and query and grounds them (shared by infer, score and
/// `bench mln`); also returns the seconds parsing and grounding.
pub(crate) fn load_and_ground(
    args: &ProblemArgs,
) -> anyhow::Result<(
    mln::parse::Program,
    mln::ground::GroundProblem,
    Vec<mln::parse::Atom>,
    f64,
    f64,
)> {
    let t0 = Instant::now();
    let program = read_program(&args.program).context("reading the program")?;
    let (evidence, query) = read_evidence_and_query(args, &program)?;
    let parse_s = t0.elapsed().as_secs_f64();
    let t1 = Instant::now();
    let evidence_label = args
        .evidence
        .first()
        .map_or_else(|| "(no evidence)".to_owned(), |p| p.display().to_string());
    let problem = ground(
        &program,
        &evidence,
        &evidence_label,
        &query,
        &GroundOptions::default(),
    )
    .context("grounding")?;
    Ok((program, problem, query, parse_s, t1.elapsed().as_secs_f64()))
}

fn score(args: &ScoreArgs) -> anyhow::Result<()> {
    let (program, problem, _query, _, _) = load_and_ground(&args.problem)?;
    let (x, answer_atoms, not_unknown) = read_answer(&program, &problem, &args.answer)?;
    let s = problem.score(&x);
    if args.json {
        let out = json!({
            "answer": args.answer.display().to_string(),
            "answer_atoms": answer_atoms,
            "answer_atoms_not_unknown": not_unknown,
            "cost": s.cost,
            "violated_weight": s.violated_weight,
            "hard_violations": s.hard_violations,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "{}: {} atoms ({} are not unknown atoms of this ground problem)",
            args.answer.display(),
            answer_atoms,
            not_unknown
        );
        println!("cost              {}", s.cost);
        println!("violated weight   {}", s.violated_weight);
        println!("hard violations   {}", s.hard_violations);
    }
    Ok(())
}

/// Reads another engine's MAP answer (true atoms, `!` lines false) as an assignment of
/// the unknown atoms; also returns the number of answer lines and how many of them are not
/// unknown atoms of `problem`.
pub(crate) fn read_answer(
    program: &mln::parse::Program,
    problem: &mln::ground::GroundProblem,
    path: &std::path::Path,
) -> anyhow::Result<(Vec<bool>, usize, usize)> {
    let answer = read_evidence(path, program).context("reading the answer")?;
    let index: std::collections::HashMap<String, usize> = (0..problem.atoms.len())
        .map(|i| (problem.atom_name(program, i), i))
        .collect();
    let mut x = vec![false; problem.atoms.len()];
    let mut not_unknown = 0usize;
    for a in &answer {
        let name = format!(
            "{}({})",
            program.predicates[a.predicate].name,
            a.args.join(",")
        );
        match index.get(&name) {
            Some(&i) => x[i] = a.value,
            None => not_unknown += 1,
        }
    }
    Ok((x, answer.len(), not_unknown))
}

fn generate(args: &GenerateArgs) -> anyhow::Result<()> {
    write_generated(args.problem, args.size, args.seed, &args.data, &args.out)?;
    println!(
        "wrote prog.mln, evidence.db and query.db to {}",
        args.out.display()
    );
    Ok(())
}

/// Reads a data file with its path in the error.
fn read_data(path: &std::path::Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).with_context(|| format!("reading {}", path.display()))
}

/// Generates a synthetic problem (default size: the thesis') into `out`; IE and KB3 read
/// their facts from the data folder `data`.
pub(crate) fn write_generated(
    problem: Problem,
    size: Option<usize>,
    seed: u64,
    data: &std::path::Path,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    use mln::generate::{
        friends_smokers, ie_evidence_from_mfoilp, image_denoising, kb3, FriendsSmokersOptions,
        GeneratedMln, Kb3Options,
    };
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let g = match problem {
        Problem::Ie => {
            let facts = data.join("ie/partial-evidence-mfoilp");
            GeneratedMln {
                program: read_data(&data.join("ie/tuffy/prog.mln"))?,
                evidence: ie_evidence_from_mfoilp(
                    &read_data(&facts.join("tokens"))?,
                    &read_data(&facts.join("similartitles"))?,
                    &read_data(&facts.join("jntinfcandidates"))?,
                )
                .with_context(|| format!("in {}", facts.display()))?,
                query: read_data(&data.join("ie/tuffy/query.db"))?,
            }
        }
        Problem::Kb3 => {
            let dir = data.join("kb/mlcnn");
            let k = kb3(
                &read_data(&dir.join("evidence.db"))?,
                &read_data(&dir.join("labels.db"))?,
                &Kb3Options::default(),
                seed,
            )
            .with_context(|| format!("in {}", dir.display()))?;
            let path = out.join("training.db");
            geodata::fsio::write_atomic(&path, &k.training)
                .with_context(|| format!("writing {}", path.display()))?;
            k.files
        }
        Problem::Fs | Problem::NegFs => friends_smokers(
            &FriendsSmokersOptions {
                persons: size.unwrap_or(200),
                negate: matches!(problem, Problem::NegFs),
                ..FriendsSmokersOptions::default()
            },
            seed,
        ),
        Problem::Id => image_denoising(size.unwrap_or(90), seed),
    };
    for (name, text) in [
        ("prog.mln", &g.program),
        ("evidence.db", &g.evidence),
        ("query.db", &g.query),
    ] {
        let path = out.join(name);
        geodata::fsio::write_atomic(&path, text)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

/// Learns the weights of `args.problem` and writes the program with them; returns the
/// learnt weights (also used by `bench mln` for KB3).
pub(crate) fn learn_program(
    args: &ProblemArgs,
    options: &mln::learn::LearnOptions,
    output: &std::path::Path,
) -> anyhow::Result<(mln::learn::Training, mln::learn::Learnt)> {
    let source = read_data(&args.program)?;
    let program = mln::parse::parse_program(&source, &args.program.display().to_string())
        .context("reading the program")?;
    let (database, query) = read_evidence_and_query(args, &program)?;
    let label = args
        .evidence
        .first()
        .map_or_else(|| "(no database)".to_owned(), |p| p.display().to_string());
    let training = mln::learn::training_problem(&program, &database, &label, &query)
        .context("setting up the training problem")?;
    let learnt = mln::learn::learn_weights(&program, &training, options);
    let text = mln::learn::with_weights(&source, &program, &learnt.weights);
    geodata::fsio::write_atomic(output, text)
        .with_context(|| format!("writing {}", output.display()))?;
    Ok((training, learnt))
}

fn learn(args: &LearnArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let mut options = mln::learn::LearnOptions {
        epochs: args.epochs,
        learning_rate: args.rate,
        l2: args.l2,
        start_from_program: args.warm_start,
        ..mln::learn::LearnOptions::default()
    };
    options.infer.walksat.seed = args.seed;
    let (training, learnt) = learn_program(&args.problem, &options, &args.output)?;
    let seconds = t0.elapsed().as_secs_f64();
    let first_errors = learnt.epochs.first().map_or(0, |e| e.errors);
    if args.json {
        let out = json!({
            "program": args.problem.program.display().to_string(),
            "output": args.output.display().to_string(),
            "ground_atoms": training.problem.atoms.len(),
            "ground_factors": training.problem.factors.len(),
            "labels": training.labels,
            "labels_unused": training.labels_unused,
            "true_atoms": training.truth.iter().filter(|&&v| v).count(),
            "epochs": learnt.epochs.iter().map(|e| json!({"errors": e.errors, "count_gap": e.count_gap})).collect::<Vec<_>>(),
            "errors_start": first_errors,
            "errors_learnt": learnt.final_errors,
            "weights": learnt.weights,
            "seconds": seconds,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "{}: {} unknown atoms ({} true in the labels), {} ground formulas; {} labels ({} not unknown atoms)",
            args.problem.program.display(),
            training.problem.atoms.len(),
            training.truth.iter().filter(|&&v| v).count(),
            training.problem.factors.len(),
            training.labels,
            training.labels_unused
        );
        println!(
            "training errors   {} (MAP under the starting weights) -> {} (MAP under the learnt weights), {} epochs",
            first_errors,
            learnt.final_errors,
            learnt.epochs.len()
        );
        println!("wrote {} in {seconds:.2} s", args.output.display());
    }
    Ok(())
}

fn infer(args: &InferArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let (program, problem, query, parse_s, ground_s) = load_and_ground(&args.problem)?;
    if let Some(path) = &args.export_wcnf {
        let mut w = geodata::fsio::AtomicFile::create(path)
            .with_context(|| format!("creating the WCNF file {}", path.display()))?;
        let summary = mln::wcnf::write_wcnf(&problem, args.wcnf_scale, &mut w)
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
    let r = map_inference(&problem, &options);
    let total_s = t0.elapsed().as_secs_f64();

    if let Some(path) = &args.result {
        let query_preds: Vec<usize> = query.iter().map(|a| a.predicate).collect();
        let mut lines: Vec<String> = (0..problem.atoms.len())
            .filter(|&i| query_preds.contains(&problem.atoms[i].predicate))
            .map(|i| {
                format!(
                    "{} {}",
                    problem.atom_name(&program, i),
                    u8::from(r.assignment[i])
                )
            })
            .collect();
        lines.sort();
        let mut text = String::new();
        for l in lines {
            text.push_str(&l);
            text.push('\n');
        }
        geodata::fsio::write_atomic(path, text)
            .with_context(|| format!("writing the result file {}", path.display()))?;
    }
    let higher = problem.higher_order_factors();
    if args.json {
        let out = json!({
            "program": args.problem.program.display().to_string(),
            "method": args.method.name(),
            "quadratize": args.quadratize.name(),
            "representation": if args.multinomial { "multinomial" } else { args.representation.name() },
            "seed": args.seed,
            "cost": r.scores.cost,
            "violated_weight": r.scores.violated_weight,
            "hard_violations": r.scores.hard_violations,
            "lower_bound": r.lower_bound,
            "ground_atoms": problem.atoms.len(),
            "ground_factors": problem.factors.len(),
            "higher_order_factors": higher,
            "persistent_fraction": r.persistent_fraction,
            "true_atoms": r.assignment.iter().filter(|&&v| v).count(),
            "seconds": {
                "parse": parse_s,
                "ground": ground_s,
                "quadratize": r.seconds_quadratize,
                "solve": r.seconds_solve,
                "total": total_s,
            },
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
    } else {
        println!(
            "{}: {} ground atoms, {} ground formulas ({} higher-order)",
            args.problem.program.display(),
            problem.atoms.len(),
            problem.factors.len(),
            higher
        );
        println!("method            {}", args.method.name());
        println!("cost              {}", r.scores.cost);
        println!("violated weight   {}", r.scores.violated_weight);
        println!("hard violations   {}", r.scores.hard_violations);
        if let Some(lb) = r.lower_bound {
            println!("lower bound       {lb}  (of cost + hard weight × violations)");
            println!("persistent        {:.2} %", 100.0 * r.persistent_fraction);
        }
        println!(
            "seconds           parse {parse_s:.3}  ground {ground_s:.3}  quadratize {:.3}  solve {:.3}  total {total_s:.3}",
            r.seconds_quadratize, r.seconds_solve
        );
    }
    Ok(())
}
