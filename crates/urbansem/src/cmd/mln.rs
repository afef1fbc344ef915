//! `urbansem mln …`: MAP inference on Markov logic networks.

use anyhow::Context;
use clap::{Args, Subcommand};
use mln::ground::{ground, GroundOptions};
use mln::infer::{map_inference, InferOptions, Method, Representation};
use mln::parse::{parse_query_predicates, read_evidence, read_program, read_query};
use pbo::quadratize::Quadratizer;
use serde_json::json;
use std::io::Write as _;
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
    }
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
    let mut evidence = Vec::new();
    for e in &args.evidence {
        evidence.extend(read_evidence(e, &program).context("reading evidence")?);
    }
    let query = match (args.queries.as_deref(), args.query_file.as_deref()) {
        (Some(list), _) => parse_query_predicates(list, &program)?,
        (None, Some(f)) => read_query(f, &program).context("reading the query file")?,
        (None, None) => anyhow::bail!("no query: give -q Pred1,Pred2 or --query-file FILE"),
    };
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
    write_generated(args.problem, args.size, args.seed, &args.out)?;
    println!(
        "wrote prog.mln, evidence.db and query.db to {}",
        args.out.display()
    );
    Ok(())
}

/// Generates a synthetic problem (default size: the thesis') into `out`.
pub(crate) fn write_generated(
    problem: Problem,
    size: Option<usize>,
    seed: u64,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    use mln::generate::{friends_smokers, image_denoising, FriendsSmokersOptions};
    let g = match problem {
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
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    for (name, text) in [
        ("prog.mln", &g.program),
        ("evidence.db", &g.evidence),
        ("query.db", &g.query),
    ] {
        let path = out.join(name);
        std::fs::write(&path, text).with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

fn infer(args: &InferArgs) -> anyhow::Result<()> {
    let t0 = Instant::now();
    let (program, problem, query, parse_s, ground_s) = load_and_ground(&args.problem)?;
    if let Some(path) = &args.export_wcnf {
        let file = std::fs::File::create(path)
            .with_context(|| format!("creating the WCNF file {}", path.display()))?;
        let mut w = std::io::BufWriter::new(file);
        let summary = mln::wcnf::write_wcnf(&problem, args.wcnf_scale, &mut w)
            .and_then(|s| w.flush().map(|()| s))
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
        let mut f = std::fs::File::create(path)
            .with_context(|| format!("creating the result file {}", path.display()))?;
        for l in lines {
            writeln!(f, "{l}").with_context(|| format!("writing {}", path.display()))?;
        }
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
