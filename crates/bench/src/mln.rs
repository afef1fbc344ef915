//! `urbansem bench mln` runs MAP inference (default QSSR + tabu) on the real MLN sets of
//! `../shared/data/mln` (LP, RC, KB, ER; IE with its evidence rebuilt from mfoilp's facts)
//! and on the generated F&S, −F&S, ID and KB3 (weights learnt first by `mln::learn`), reports
//! sizes, persistencies, cost, bound and seconds per phase (fastest of `--repeat` runs),
//! re-scores Tuffy's shipped MAP answers with the same evaluator, and quotes Tuffy's logged
//! run time (another machine) and the time target (thesis Table 3.5 / 10).

use crate::metrics::{timed_on, Clock};
use crate::pbo::fmt_opt;
use anyhow::{bail, Context};
use clap::Args;
use mln::files::{
    benchmark_problem, learn_program, load_and_ground, score_answer, AnswerAssignment, Benchmark,
    LearntProgram, Loaded, ProblemFiles, QuerySource,
};
use mln::ground::GroundOptions;
use pbo::quadratize::Quadratizer;
use serde_json::Value;
use std::path::PathBuf;
use std::time::Instant;

/// Options of `urbansem bench mln`.
#[derive(Args)]
pub struct MlnBenchArgs {
    /// Folder of the MLN benchmark sets (see its SOURCES.md).
    #[arg(long, default_value = "../shared/data/mln")]
    data: PathBuf,
    /// Folder for the generated F&S, −F&S and ID problems.
    #[arg(long, default_value = "target/bench-data/mln")]
    data_dir: PathBuf,
    /// Runs per set; the fastest is reported (the answer is the same for a seed).
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Only these sets (comma-separated): ie, lp, rc, kb, er, fs, neg-fs, id, kb3, pr.
    #[arg(long, value_delimiter = ',')]
    sets: Vec<String>,
    /// MAP methods to run per set (comma-separated): qpbo, maxwalksat, maxwalksat-monomials.
    #[arg(long, value_delimiter = ',', default_value = "qpbo", value_parser = parse_mln_method)]
    methods: Vec<mln::infer::Method>,
    /// Quadratizers for the qpbo method (comma-separated): ish, asm, fix, grd.
    #[arg(long, value_delimiter = ',', default_value = "asm", value_parser = parse_quadratizer)]
    quadratizers: Vec<Quadratizer>,
    /// Flips per MaxWalkSAT chain (maxwalksat methods).
    #[arg(long, default_value_t = 1_000_000)]
    flips: usize,
    /// Seed of the generated problems and of inference.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Also run the qpbo method with probing once per set and quadratizer (Table 3.4's step
    /// 3: `persistent_fraction_probe`, `seconds_probe_run`).
    #[arg(long)]
    probe: bool,
    /// Ground every atom of the open predicates, as `mln infer --eager` (PR then exceeds
    /// the grounding cap); by default lazily, as `mln infer`.
    #[arg(long)]
    eager: bool,
    /// Print one JSON object instead of the table.
    #[arg(long)]
    json: bool,
    /// Marginal inference instead: MC-SAT (`mln infer --marginal`) beside MAP (`mln infer`)
    /// on each set, CPU and wall seconds of both (parse + ground + infer) and their ratio
    /// (issue 20's target: 1 000 samples within 10 × MAP's time). PR is skipped: marginal
    /// inference grounds every atom.
    #[arg(long)]
    marginal: bool,
    /// With --marginal: counted samples per chain (the default, 2 chains × 500, is 1 000).
    #[arg(long, default_value_t = 500, requires = "marginal")]
    samples: usize,
    /// With --marginal: steps per chain before counting.
    #[arg(long, default_value_t = 100, requires = "marginal")]
    burn_in: usize,
    /// With --marginal: MC-SAT chains, run in parallel.
    #[arg(long, default_value_t = 2, requires = "marginal")]
    chains: usize,
}

fn parse_quadratizer(s: &str) -> Result<Quadratizer, String> {
    s.parse()
}

fn parse_mln_method(s: &str) -> Result<mln::infer::Method, String> {
    s.parse()
}

/// One MLN benchmark set: files relative to the data folder (or the generated folder).
struct MlnSet {
    name: &'static str,
    dir: &'static str,
    program: &'static str,
    generated: Option<Benchmark>,
    /// Tuffy's MAP answer (true atoms), relative to the data folder.
    reference: Option<&'static str>,
    /// Tuffy's run log, relative to the data folder.
    tuffy_log: Option<&'static str>,
    /// The time target in seconds (thesis Table 3.5 / 10).
    target_s: f64,
    /// The weights are learnt first (`urbansem mln learn` on `training.db` → `learnt.mln`).
    learn: bool,
}

const MLN_SETS: [MlnSet; 10] = [
    MlnSet {
        name: "ie",
        dir: "ie",
        program: "prog.mln",
        generated: Some(Benchmark::Ie),
        reference: Some("ie/reference_outputs/tuffy_map_output_from_xeggora.db"),
        tuffy_log: Some("ie/reference_outputs/tuffy_run_log_from_xeggora.txt"),
        target_s: 2.2,
        learn: false,
    },
    MlnSet {
        name: "lp",
        dir: "lp/rockit",
        program: "prog.mln",
        generated: None,
        reference: Some("lp/reference_outputs/tuffy_map_output_from_xeggora.db"),
        tuffy_log: Some("lp/reference_outputs/tuffy_run_log_from_xeggora.txt"),
        target_s: 0.9,
        learn: false,
    },
    MlnSet {
        name: "rc",
        dir: "rc/rockit",
        program: "prog.mln",
        generated: None,
        reference: None,
        tuffy_log: Some("rc/reference_outputs/tuffy_run_log_from_xeggora.txt"),
        target_s: 0.9,
        learn: false,
    },
    MlnSet {
        name: "kb",
        dir: "kb/mlcnn",
        program: "prog.mln",
        generated: None,
        reference: Some("kb/reference_outputs/tuffy_map_output_from_mlcnn.txt"),
        tuffy_log: None,
        target_s: 0.6,
        learn: false,
    },
    MlnSet {
        name: "er",
        dir: "er/rockit",
        program: "prog.mln",
        generated: None,
        reference: Some("er/reference_outputs/tuffy_map_output_from_xeggora.db"),
        tuffy_log: Some("er/reference_outputs/tuffy_run_log_from_xeggora.txt"),
        target_s: 10.0,
        learn: false,
    },
    MlnSet {
        name: "fs",
        dir: "fs",
        program: "prog.mln",
        generated: Some(Benchmark::FriendsSmokers),
        reference: None,
        tuffy_log: None,
        target_s: 0.6,
        learn: false,
    },
    MlnSet {
        name: "neg-fs",
        dir: "neg-fs",
        program: "prog.mln",
        generated: Some(Benchmark::NegatedFriendsSmokers),
        reference: None,
        tuffy_log: None,
        target_s: 1.2,
        learn: false,
    },
    MlnSet {
        name: "id",
        dir: "id",
        program: "prog.mln",
        generated: Some(Benchmark::ImageDenoising),
        reference: None,
        tuffy_log: None,
        target_s: 0.5,
        learn: false,
    },
    MlnSet {
        name: "kb3",
        dir: "kb3",
        program: "learnt.mln",
        generated: Some(Benchmark::Kb3),
        reference: None,
        tuffy_log: None,
        target_s: 5.7,
        learn: true,
    },
    MlnSet {
        name: "pr",
        dir: "pr/rockit",
        program: "prog.mln",
        generated: None,
        reference: Some("pr/reference_outputs/tuffy_map_output_from_xeggora.db"),
        tuffy_log: Some("pr/reference_outputs/tuffy_run_log_from_xeggora.txt"),
        // Issue 20's target: ground and solve within 60 s.
        target_s: 60.0,
        learn: false,
    },
];

/// Tuffy's total run time from its log line `… after running for [3 min, 50.630 sec]`.
fn tuffy_logged_seconds(text: &str) -> Option<f64> {
    let start = text.find("after running for [")? + "after running for [".len();
    let inner = &text[start..start + text[start..].find(']')?];
    let mut total = 0.0;
    for part in inner.split(',') {
        let mut words = part.split_whitespace();
        let value: f64 = words.next()?.parse().ok()?;
        total += value
            * match words.next()? {
                "hr" | "hour" | "hours" => 3600.0,
                "min" => 60.0,
                "sec" => 1.0,
                _ => return None,
            };
    }
    Some(total)
}

/// Runs `urbansem bench mln`.
pub fn bench_mln(args: &MlnBenchArgs) -> anyhow::Result<()> {
    use mln::infer::{map_inference, InferOptions};
    if !args.data.exists() {
        bail!(
            "MLN data folder {} not found (give --data ../shared/data/mln)",
            args.data.display()
        );
    }
    let unknown: Vec<&String> = args
        .sets
        .iter()
        .filter(|s| !MLN_SETS.iter().any(|m| m.name == s.as_str()))
        .collect();
    if !unknown.is_empty() {
        crate::usage!(
            "unknown MLN set(s) {unknown:?}: expected ie, lp, rc, kb, er, fs, neg-fs, id, kb3"
        );
    }
    let mut rows: Vec<Value> = Vec::new();
    for set in MLN_SETS
        .iter()
        .filter(|m| args.sets.is_empty() || args.sets.iter().any(|s| s == m.name))
    {
        let dir = match set.generated {
            Some(problem) => {
                let out = args.data_dir.join(set.dir);
                write_generated(problem, args.seed, &args.data, &out)?;
                out
            }
            None => args.data.join(set.dir),
        };
        let problem_files = ProblemFiles {
            program: dir.join(set.program),
            evidence: vec![dir.join("evidence.db")],
            query: QuerySource::File(dir.join("query.db")),
        };
        if args.marginal && set.learn {
            eprintln!(
                "{}: skipped (its weights are learnt first; see bench mln)",
                set.name
            );
            continue;
        }
        if args.marginal && set.name == "pr" {
            eprintln!("pr: skipped (marginal inference grounds every atom; PR is grounded lazily)");
            continue;
        }
        if args.marginal {
            rows.push(marginal_row(set.name, &problem_files, args)?);
            if !args.json {
                eprintln!("{}: done", set.name);
            }
            continue;
        }
        let mut learning = Value::Null;
        if set.learn {
            let t = Instant::now();
            let training_files = ProblemFiles {
                program: dir.join("prog.mln"),
                evidence: vec![dir.join("training.db")],
                query: QuerySource::File(dir.join("query.db")),
            };
            let options = mln::learn::LearnOptions::default().seeded(args.seed);
            let LearntProgram {
                training,
                learnt,
                text,
            } = learn_program(&training_files, &options)
                .with_context(|| format!("learning the weights of set {}", set.name))?;
            let out = &problem_files.program;
            geodata::fsio::write_atomic(out, text)
                .with_context(|| format!("writing {}", out.display()))?;
            learning = serde_json::json!({
                "labels": training.labels,
                "epochs": learnt.epochs.len(),
                "errors_start": learnt.epochs.first().map(|e| e.errors),
                "errors_learnt": learnt.final_errors,
                "seconds": t.elapsed().as_secs_f64(),
            });
        }
        let runs: Vec<(mln::infer::Method, Quadratizer)> = args
            .methods
            .iter()
            .flat_map(|&m| {
                let qs: Vec<Quadratizer> = if m == mln::infer::Method::Qpbo {
                    args.quadratizers.clone()
                } else {
                    vec![Quadratizer::Asm]
                };
                qs.into_iter().map(move |q| (m, q))
            })
            .collect();
        let grounding = GroundOptions {
            lazy: !args.eager,
            ..GroundOptions::default()
        };
        for (method, quadratizer) in &runs {
            let mut options = InferOptions {
                method: *method,
                quadratizer: *quadratizer,
                ..InferOptions::default()
            };
            options.walksat.seed = args.seed;
            options.walksat.max_flips = args.flips;
            let mut best: Option<serde_json::Value> = None;
            let mut best_total = f64::INFINITY;
            let mut reference = serde_json::Value::Null;
            for run in 0..args.repeat.max(1) {
                let t0 = Instant::now();
                let loaded = load_and_ground(&problem_files, &grounding)
                    .with_context(|| format!("set {}", set.name))?;
                let r = map_inference(&loaded.problem, &options);
                let total_s = t0.elapsed().as_secs_f64();
                let Loaded {
                    problem,
                    parse_seconds: parse_s,
                    ground_seconds: ground_s,
                    ..
                } = &loaded;
                if run == 0 {
                    if let Some(rel) = set.reference {
                        let path = args.data.join(rel);
                        // Scored eagerly if it sets atoms lazy grounding left out.
                        let (
                            AnswerAssignment {
                                atoms: lines,
                                not_unknown,
                                ..
                            },
                            s,
                        ) = score_answer(&problem_files, &loaded, &path, grounding.max_groundings)?;
                        reference = serde_json::json!({
                            "answer": path.display().to_string(),
                            "answer_atoms": lines,
                            "answer_atoms_not_unknown": not_unknown,
                            "cost": s.cost,
                            "hard_violations": s.hard_violations,
                        });
                    }
                }
                if total_s < best_total {
                    best_total = total_s;
                    best = Some(serde_json::json!({
                        "set": set.name,
                        "method": method.name(),
                        "program": problem_files.program.display().to_string(),
                        "ground_atoms": problem.atoms.len(),
                        "ground_factors": problem.factors.len(),
                        "higher_order_factors": problem.higher_order_factors(),
                        "cost": r.scores.cost,
                        "hard_violations": r.scores.hard_violations,
                        "lower_bound": r.lower_bound,
                        "persistent_fraction": r.persistent_fraction,
                        "quadratize": options.quadratizer.name(),
                        "qssr_rounds": r.qssr_rounds.len(),
                        // Table 3.2's "after QPBO": the first round's share of the atoms.
                        "persistent_fraction_first_qpbo": r.qssr_rounds.first().map(|q| {
                            q.fixed_by_qpbo as f64 / q.free_variables.max(1) as f64
                        }),
                        "seconds": {
                            "parse": parse_s,
                            "ground": ground_s,
                            "quadratize": r.seconds_quadratize,
                            "solve": r.seconds_solve,
                            "total": total_s,
                        },
                    }));
                }
            }
            let Some(mut row) = best else { continue };
            row["learning"] = learning.clone();
            if args.probe && *method == mln::infer::Method::Qpbo {
                let problem = load_and_ground(&problem_files, &grounding)?.problem;
                let t = Instant::now();
                let r = map_inference(
                    &problem,
                    &InferOptions {
                        probe: true,
                        ..options.clone()
                    },
                );
                row["persistent_fraction_probe"] = serde_json::json!(r.persistent_fraction);
                row["cost_probe_run"] = serde_json::json!(r.scores.cost);
                row["seconds_probe_run"] = serde_json::json!(t.elapsed().as_secs_f64());
            }
            let tuffy_s = match set.tuffy_log {
                Some(rel) => {
                    let path = args.data.join(rel);
                    let text = std::fs::read_to_string(&path)
                        .with_context(|| format!("reading {}", path.display()))?;
                    tuffy_logged_seconds(&text)
                }
                None => None,
            };
            let ref_cost = reference.get("cost").and_then(Value::as_f64);
            let our_cost = row["cost"].as_f64();
            row["reference"] = reference;
            row["cost_minus_reference"] =
                serde_json::json!(our_cost.zip(ref_cost).map(|(a, b)| a - b));
            row["tuffy_logged_seconds"] = serde_json::json!(tuffy_s);
            row["seconds_over_tuffy"] = serde_json::json!(tuffy_s.map(|t| best_total / t));
            row["target_seconds"] = serde_json::json!(set.target_s);
            row["seconds_over_target"] = serde_json::json!(best_total / set.target_s);
            if !args.json {
                eprintln!("{} {}: done", set.name, method.name());
            }
            rows.push(row);
        }
    }
    if args.marginal {
        return print_marginal_rows(rows, args);
    }
    if args.json {
        let out = serde_json::json!({
            "repeat": args.repeat.max(1),
            "seed": args.seed,
            "sets": rows,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{:<7} {:<22} {:>7} {:>8} {:>6} {:>7} {:>7} | {:>13} {:>13} {:>10} {:>13} | {:>7} {:>7} {:>6} {:>8} {:>7}",
        "set", "method (1st QPBO %)", "atoms", "factors", "h.o.", "pers %", "probe %", "cost", "Tuffy cost", "diff", "bound",
        "ground", "total", "target", "/target", "Tuffy s"
    );
    for r in &rows {
        let f = |v: &Value| v.as_f64();
        let secs = &r["seconds"];
        println!(
            "{:<7} {:<22} {:>7} {:>8} {:>6} {:>7.2} {:>7} | {:>13.2} {:>13} {:>10} {:>13} | {:>7.3} {:>7.3} {:>6.1} {:>8.2} {:>7}",
            r["set"].as_str().unwrap_or("?"),
            format!(
                "{}{}",
                r["method"].as_str().unwrap_or("?"),
                if r["method"] == "qpbo" {
                    format!(
                        "/{} {:.1}%",
                        r["quadratize"].as_str().unwrap_or("?"),
                        100.0 * r["persistent_fraction_first_qpbo"].as_f64().unwrap_or(0.0)
                    )
                } else {
                    String::new()
                }
            ),
            r["ground_atoms"].as_u64().unwrap_or(0),
            r["ground_factors"].as_u64().unwrap_or(0),
            r["higher_order_factors"].as_u64().unwrap_or(0),
            100.0 * f(&r["persistent_fraction"]).unwrap_or(0.0),
            fmt_opt(f(&r["persistent_fraction_probe"]).map(|p| 100.0 * p), 2),
            f(&r["cost"]).unwrap_or(f64::NAN),
            fmt_opt(f(&r["reference"]["cost"]), 2),
            fmt_opt(f(&r["cost_minus_reference"]), 2),
            fmt_opt(f(&r["lower_bound"]), 2),
            f(&secs["ground"]).unwrap_or(f64::NAN),
            f(&secs["total"]).unwrap_or(f64::NAN),
            f(&r["target_seconds"]).unwrap_or(f64::NAN),
            f(&r["seconds_over_target"]).unwrap_or(f64::NAN),
            fmt_opt(f(&r["tuffy_logged_seconds"]), 1),
        );
    }
    println!(
        "cost = −Σ w·[ground formula true] over soft groundings with unknown atoms (lower is \
         better); Tuffy cost = Tuffy's shipped MAP answer scored by the same evaluator; diff = \
         ours − Tuffy (< 0: ours better); bound = QPBO/QSSR lower bound (= cost: proven optimal); \
         1st QPBO % = atoms labelled by the first QPBO round, pers % = after all QSSR rounds, probe % = after QSSR with probing (--probe; Table 3.4's steps 1-3); seconds are the fastest of the runs, parse + ground + solve; target = thesis Table 3.5 \
         time / 10; Tuffy s = Tuffy's logged run time on its authors' machine (PostgreSQL \
         grounding included), not measured here."
    );
    Ok(())
}

/// Wall and process CPU seconds of `f` (CPU summed over threads; `NaN` off Linux).
fn wall_and_cpu<R>(f: impl FnOnce() -> R) -> (R, f64, f64) {
    let (r, wall, cpu) = timed_on(Clock::Process, f);
    (r, wall, cpu.unwrap_or(f64::NAN))
}

/// One set of `bench mln --marginal`: MAP as `mln infer` and MC-SAT as `mln infer
/// --marginal`, each parse + ground + infer, the fastest of `--repeat` runs.
fn marginal_row(name: &str, files: &ProblemFiles, args: &MlnBenchArgs) -> anyhow::Result<Value> {
    use mln::infer::{map_inference, InferOptions};
    use mln::marginal::{mc_sat, McSatOptions};
    let mut map_options = InferOptions::default();
    map_options.walksat.seed = args.seed;
    let mc_options = McSatOptions {
        samples: args.samples.max(1),
        burn_in: args.burn_in,
        chains: args.chains.max(1),
        seed: args.seed,
        ..McSatOptions::default()
    };
    let (mut map_wall, mut map_cpu) = (f64::INFINITY, f64::INFINITY);
    let (mut mc_wall, mut mc_cpu) = (f64::INFINITY, f64::INFINITY);
    let mut last = None;
    for _ in 0..args.repeat.max(1) {
        let (r, wall, cpu) = wall_and_cpu(|| -> anyhow::Result<f64> {
            let loaded = load_and_ground(files, &GroundOptions::map())?;
            Ok(map_inference(&loaded.problem, &map_options).scores.cost)
        });
        r.with_context(|| format!("MAP on set {name}"))?;
        map_wall = map_wall.min(wall);
        map_cpu = map_cpu.min(cpu);
        let (r, wall, cpu) = wall_and_cpu(|| -> anyhow::Result<_> {
            let loaded = load_and_ground(files, &GroundOptions::default())?;
            let m = mc_sat(&loaded.problem, &mc_options)?;
            Ok((loaded.problem.atoms.len(), loaded.problem.factors.len(), m))
        });
        let r = r.with_context(|| format!("MC-SAT on set {name}"))?;
        mc_wall = mc_wall.min(wall);
        mc_cpu = mc_cpu.min(cpu);
        last = Some(r);
    }
    let Some((atoms, factors, m)) = last else {
        bail!("no run of set {name}");
    };
    Ok(serde_json::json!({
        "set": name,
        "ground_atoms": atoms,
        "ground_factors": factors,
        "slice_formulas": m.slice_formulas,
        "independent_atoms": m.independent_atoms,
        "fixed_atoms": m.fixed_atoms,
        "chains": m.chains,
        "samples": m.samples,
        "burn_in": args.burn_in,
        "max_chain_spread": m.max_chain_spread,
        "mean_chain_spread": m.mean_chain_spread,
        "acceptance": m.acceptance,
        "map_seconds": map_wall,
        "map_cpu_seconds": map_cpu,
        "mc_sat_seconds": mc_wall,
        "mc_sat_cpu_seconds": mc_cpu,
        "ratio": mc_wall / map_wall,
        "cpu_ratio": mc_cpu / map_cpu,
    }))
}

/// Prints `bench mln --marginal`'s rows as JSON or a table.
fn print_marginal_rows(rows: Vec<Value>, args: &MlnBenchArgs) -> anyhow::Result<()> {
    if args.json {
        let out = serde_json::json!({
            "repeat": args.repeat.max(1),
            "seed": args.seed,
            "samples": args.samples,
            "chains": args.chains,
            "burn_in": args.burn_in,
            "sets": rows,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{:<7} {:>7} {:>8} {:>8} {:>8} | {:>7} {:>7} | {:>7} {:>7} | {:>6} {:>6} | {:>7} {:>7}",
        "set",
        "atoms",
        "factors",
        "sampled",
        "indep.",
        "MAP s",
        "MAP cpu",
        "MC s",
        "MC cpu",
        "ratio",
        "cpu",
        "spread",
        "mean"
    );
    for r in &rows {
        let f = |k: &str| r[k].as_f64().unwrap_or(f64::NAN);
        let u = |k: &str| r[k].as_u64().unwrap_or(0);
        println!(
            "{:<7} {:>7} {:>8} {:>8} {:>8} | {:>7.2} {:>7.2} | {:>7.2} {:>7.2} | {:>6.1} {:>6.1} | {:>7.3} {:>7.4}",
            r["set"].as_str().unwrap_or("?"),
            u("ground_atoms"),
            u("ground_factors"),
            u("slice_formulas"),
            u("independent_atoms"),
            f("map_seconds"),
            f("map_cpu_seconds"),
            f("mc_sat_seconds"),
            f("mc_sat_cpu_seconds"),
            f("ratio"),
            f("cpu_ratio"),
            f("max_chain_spread"),
            f("mean_chain_spread"),
        );
    }
    println!(
        "MC-SAT: {} chains × {} samples after {} of burn-in; seconds are parse + ground + infer, \
         the fastest of {} runs (cpu: summed over threads); ratio = MC-SAT / MAP (issue 20's \
         target: ≤ 10); sampled = distinct formulas over two or more unforced atoms, indep. = \
         atoms in none (exact, not sampled); spread = largest difference between two chains' \
         estimates of one atom, mean = its mean over atoms.",
        args.chains,
        args.samples,
        args.burn_in,
        args.repeat.max(1)
    );
    Ok(())
}

/// Generates a benchmark problem into `out` (prog.mln, evidence.db, query.db; KB3 also
/// training.db).
fn write_generated(
    kind: Benchmark,
    seed: u64,
    data: &std::path::Path,
    out: &std::path::Path,
) -> anyhow::Result<()> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let g = benchmark_problem(kind, None, seed, data)?;
    for (name, text) in g.named_files() {
        let path = out.join(name);
        geodata::fsio::write_atomic(&path, text)
            .with_context(|| format!("writing {}", path.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn tuffy_log_time_is_parsed() {
        let log = "*** Tuffy exited at 17:03:11 12/9/18 after running for [3 min, 50.630 sec]\n";
        assert_eq!(tuffy_logged_seconds(log), Some(230.63));
        assert_eq!(tuffy_logged_seconds("no time here"), None);
    }
}
