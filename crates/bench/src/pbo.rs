//! `urbansem bench pbo` generates the three seeded instances of issue 2 (`pbo::instances`),
//! writes them to `target/bench-data/`, times urbansem's QPBO and max-flow on them, runs
//! `scripts/bench_pbo_peers.py` (Kolmogorov's QPBO via `thinqpbo`, BK max-flow via
//! `PyMaxflow`, installed with pip if missing) on the same files, prints both timings with
//! the ratio urbansem/peer, and fails if energies, bounds or labelled counts differ. The
//! `--repeat` runs are interleaved rounds (urbansem, then the peers), so that a change of
//! load on a shared machine hits both sides; the solve's thread CPU time is reported too.

use crate::metrics::timed;
use anyhow::{bail, Context};
use clap::Args;
use pbo::instances::{denoising_grid, random_sparse, segmentation_3d, QuadraticInstance};
use pbo::maxflow::Segment;
use serde_json::Value;
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Instant;

/// Options of `urbansem bench pbo`.
#[derive(Args)]
pub struct PboBenchArgs {
    /// Smaller instances (256², 20 000 variables, 32³) for CI and the demo.
    #[arg(long)]
    quick: bool,
    /// Print one JSON object instead of the table (peer messages go to stderr).
    #[arg(long)]
    json: bool,
    /// Rounds (each runs urbansem, then the peers, once per solver and instance); the
    /// fastest run of each side is reported.
    #[arg(long, default_value_t = 3)]
    repeat: usize,
    /// Directory for the instance files and the peers' results.
    #[arg(long, default_value = "target/bench-data")]
    data_dir: PathBuf,
    /// Python interpreter for scripts/bench_pbo_peers.py.
    #[arg(long, default_value = "python3")]
    python: String,
    /// Time urbansem only (no peers, no exactness check).
    #[arg(long)]
    no_peers: bool,
}

/// What one solver returned on one instance, with its fastest times.
#[derive(Debug, Clone, Default)]
struct Outcome {
    total_s: f64,
    solve_s: f64,
    /// Thread CPU seconds of the solve (None where the platform does not tell).
    solve_cpu_s: Option<f64>,
    /// QPBO: energy of the labelling (unlabelled as 0); max-flow: the flow value.
    energy: i64,
    /// QPBO: labelled variables; max-flow: nodes on the sink side.
    count: i64,
    /// QPBO: twice the roof-dual bound; max-flow: unused (= 2 · flow).
    twice_bound: i64,
}

fn is_submodular(inst: &QuadraticInstance) -> bool {
    inst.pairs
        .iter()
        .all(|p| i64::from(p.e[0]) + i64::from(p.e[3]) <= i64::from(p.e[1]) + i64::from(p.e[2]))
}

impl Outcome {
    /// Keeps the fastest times of `self` and `run` and the answer of `run`.
    fn best_with(self, run: Outcome) -> Outcome {
        let cpu = match (self.solve_cpu_s, run.solve_cpu_s) {
            (Some(a), Some(b)) => Some(a.min(b)),
            (a, b) => a.or(b),
        };
        Outcome {
            total_s: self.total_s.min(run.total_s),
            solve_s: self.solve_s.min(run.solve_s),
            solve_cpu_s: cpu,
            ..run
        }
    }
}

/// urbansem's QPBO, one run: build + solve (and weak persistencies when submodular, which
/// is what Kolmogorov's `Solve` labels in that case: every node, free ones as 0).
fn time_qpbo(inst: &QuadraticInstance) -> Outcome {
    let submodular = is_submodular(inst);
    let t0 = Instant::now();
    let mut q = inst.to_qpbo::<i32>();
    q.prepare();
    let build_s = t0.elapsed().as_secs_f64();
    let ((), solve_s, solve_cpu_s) = timed(|| {
        q.solve();
        if submodular {
            q.compute_weak_persistencies();
        }
    });
    Outcome {
        total_s: build_s + solve_s,
        solve_s,
        solve_cpu_s,
        energy: inst.energy(&q.labelling_or_zero()),
        count: q.num_labelled() as i64,
        twice_bound: i64::from(q.twice_lower_bound()),
    }
}

/// urbansem's max-flow on the cut form of the energy, one run (build + solve).
fn time_maxflow(inst: &QuadraticInstance) -> Option<Outcome> {
    let t0 = Instant::now();
    let mut g = inst.to_graph::<i32>()?;
    g.prepare();
    let build_s = t0.elapsed().as_secs_f64();
    let (flow, solve_s, solve_cpu_s) = timed(|| g.maxflow(false));
    let energy = i64::from(flow);
    Some(Outcome {
        total_s: build_s + solve_s,
        solve_s,
        solve_cpu_s,
        energy,
        count: (0..inst.num_vars)
            .filter(|&i| g.segment(i) == Segment::Sink)
            .count() as i64,
        twice_bound: 2 * energy,
    })
}

/// `scripts/bench_pbo_peers.py`, from the working directory or the source tree.
pub(crate) fn script_path() -> PathBuf {
    let in_cwd = PathBuf::from("scripts/bench_pbo_peers.py");
    if in_cwd.exists() {
        return in_cwd;
    }
    PathBuf::from(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/../../scripts/bench_pbo_peers.py"
    ))
}

/// Runs the Python peers once on `files`; returns their JSON keyed by file path.
fn run_peers(args: &PboBenchArgs, files: &[PathBuf]) -> anyhow::Result<Value> {
    let script = script_path();
    let out = args.data_dir.join("peers.json");
    let mut cmd = Command::new(&args.python);
    cmd.arg(&script)
        .args(files)
        .arg("--repeat")
        .arg("1")
        .arg("--json-out")
        .arg(&out);
    if args.json {
        // Keep stdout one JSON object: the peers' messages go to stderr.
        cmd.stdout(Stdio::from(std::io::stderr()));
    }
    let status = cmd
        .status()
        .with_context(|| format!("running {} {}", args.python, script.display()))?;
    if !status.success() {
        bail!(
            "peer benchmark {} failed with {status} (needs python3 with numpy and pip)",
            script.display()
        );
    }
    let text =
        std::fs::read_to_string(&out).with_context(|| format!("reading {}", out.display()))?;
    serde_json::from_str(&text).with_context(|| format!("parsing {}", out.display()))
}

fn peer_outcome(v: &Value) -> Option<Outcome> {
    let f = |k: &str| v.get(k).and_then(Value::as_f64);
    let i = |k: &str| v.get(k).and_then(Value::as_i64);
    Some(Outcome {
        total_s: f("total_s")?,
        solve_s: f("solve_s")?,
        solve_cpu_s: f("solve_cpu_s"),
        energy: i("energy").or_else(|| i("flow"))?,
        count: i("labelled").or_else(|| i("sink_nodes"))?,
        twice_bound: i("twice_lower_bound").or_else(|| i("flow").map(|x| 2 * x))?,
    })
}

/// One row of the comparison table.
struct Row {
    instance: String,
    n: usize,
    m: usize,
    solver: &'static str,
    peer_name: &'static str,
    ours: Outcome,
    peer: Option<Outcome>,
}

impl Row {
    fn matches(&self) -> Option<bool> {
        self.peer.as_ref().map(|p| {
            p.energy == self.ours.energy
                && p.count == self.ours.count
                && p.twice_bound == self.ours.twice_bound
        })
    }
}

fn ratio(ours: f64, peer: Option<f64>) -> Option<f64> {
    peer.filter(|&p| p > 0.0).map(|p| ours / p)
}

/// `v` with `digits` decimals, or `-`.
pub(crate) fn fmt_opt(v: Option<f64>, digits: usize) -> String {
    v.map_or_else(|| "-".to_string(), |x| format!("{x:.digits$}"))
}

/// Runs `urbansem bench pbo`.
pub fn bench_pbo(args: &PboBenchArgs) -> anyhow::Result<()> {
    let say = |s: String| {
        if args.json {
            eprintln!("{s}");
        } else {
            println!("{s}");
        }
    };
    let t = Instant::now();
    let instances = if args.quick {
        vec![
            denoising_grid(256, 256, 1),
            random_sparse(20_000, 6, 2),
            segmentation_3d(32, 3),
        ]
    } else {
        vec![
            denoising_grid(1024, 1024, 1),
            random_sparse(200_000, 6, 2),
            segmentation_3d(128, 3),
        ]
    };
    let mut files = Vec::new();
    for inst in &instances {
        let path = inst
            .write_raw(&args.data_dir)
            .with_context(|| format!("writing instance {}", inst.name))?;
        files.push(path);
    }
    say(format!(
        "generated {} instances in {:.2} s under {}",
        instances.len(),
        t.elapsed().as_secs_f64(),
        args.data_dir.display()
    ));
    let mut rows: Vec<Row> = Vec::new();
    let rounds = args.repeat.max(1);
    for round in 1..=rounds {
        say(format!("round {round}/{rounds}"));
        let mut k = 0;
        for inst in &instances {
            let runs = [
                ("qpbo", "thinqpbo", Some(time_qpbo(inst))),
                ("maxflow", "PyMaxflow", time_maxflow(inst)),
            ];
            for (solver, peer_name, run) in runs {
                let Some(run) = run else { continue };
                say(format!(
                    "urbansem {solver:<7} {}: build+solve {:.3} s, solve {:.3} s (CPU {} s)",
                    inst.name,
                    run.total_s,
                    run.solve_s,
                    fmt_opt(run.solve_cpu_s, 3)
                ));
                if let Some(row) = rows.get_mut(k) {
                    row.ours = row.ours.clone().best_with(run);
                } else {
                    rows.push(Row {
                        instance: inst.name.clone(),
                        n: inst.num_vars,
                        m: inst.pairs.len(),
                        solver,
                        peer_name,
                        ours: run,
                        peer: None,
                    });
                }
                k += 1;
            }
        }
        if args.no_peers {
            continue;
        }
        let peers = run_peers(args, &files)?;
        for row in &mut rows {
            let file = instances
                .iter()
                .zip(&files)
                .find(|(inst, _)| inst.name == row.instance)
                .map(|(_, f)| f.display().to_string());
            let run = file
                .and_then(|f| peers.get(f.as_str()))
                .and_then(|e| e.get(row.solver))
                .and_then(peer_outcome);
            row.peer = match (row.peer.take(), run) {
                (Some(best), Some(run)) => Some(best.best_with(run)),
                (best, run) => run.or(best),
            };
        }
    }
    let all_match = rows.iter().all(|r| r.matches() != Some(false));
    if args.json {
        let list: Vec<Value> = rows
            .iter()
            .map(|r| {
                serde_json::json!({
                    "instance": r.instance,
                    "n": r.n,
                    "m": r.m,
                    "solver": r.solver,
                    "peer": r.peer_name,
                    "urbansem_total_s": r.ours.total_s,
                    "urbansem_solve_s": r.ours.solve_s,
                    "peer_total_s": r.peer.as_ref().map(|p| p.total_s),
                    "peer_solve_s": r.peer.as_ref().map(|p| p.solve_s),
                    "urbansem_solve_cpu_s": r.ours.solve_cpu_s,
                    "peer_solve_cpu_s": r.peer.as_ref().and_then(|p| p.solve_cpu_s),
                    "ratio_solve_cpu": r.ours.solve_cpu_s.and_then(|c| ratio(c, r.peer.as_ref().and_then(|p| p.solve_cpu_s))),
                    "ratio_total": ratio(r.ours.total_s, r.peer.as_ref().map(|p| p.total_s)),
                    "ratio_solve": ratio(r.ours.solve_s, r.peer.as_ref().map(|p| p.solve_s)),
                    "energy": r.ours.energy,
                    "peer_energy": r.peer.as_ref().map(|p| p.energy),
                    "count": r.ours.count,
                    "peer_count": r.peer.as_ref().map(|p| p.count),
                    "twice_lower_bound": r.ours.twice_bound,
                    "peer_twice_lower_bound": r.peer.as_ref().map(|p| p.twice_bound),
                    "match": r.matches(),
                })
            })
            .collect();
        let value = serde_json::json!({
            "quick": args.quick,
            "repeat": args.repeat,
            "rows": list,
            "all_match": all_match,
        });
        println!("{}", serde_json::to_string_pretty(&value)?);
    } else {
        print_table(&rows);
    }
    if !all_match {
        for r in rows.iter().filter(|r| r.matches() == Some(false)) {
            if let Some(p) = &r.peer {
                eprintln!(
                    "MISMATCH {} {} vs {}: energy {} vs {}, count {} vs {}, 2·bound {} vs {}",
                    r.instance,
                    r.solver,
                    r.peer_name,
                    r.ours.energy,
                    p.energy,
                    r.ours.count,
                    p.count,
                    r.ours.twice_bound,
                    p.twice_bound
                );
            }
        }
        bail!("urbansem and its peers disagree (see MISMATCH lines above)");
    }
    Ok(())
}

fn print_table(rows: &[Row]) {
    println!();
    println!(
        "{:<22} {:>9} {:>9} {:<8} {:<10} | {:>9} {:>9} {:>6} | {:>9} {:>9} {:>6} {:>6} | {:>12} {:>9} {:<5}",
        "instance",
        "n",
        "m",
        "solver",
        "peer",
        "ours tot",
        "peer tot",
        "ratio",
        "ours slv",
        "peer slv",
        "ratio",
        "cpu",
        "energy",
        "count",
        "check"
    );
    for r in rows {
        let pt = r.peer.as_ref().map(|p| p.total_s);
        let ps = r.peer.as_ref().map(|p| p.solve_s);
        let pc = r.peer.as_ref().and_then(|p| p.solve_cpu_s);
        let check = match r.matches() {
            Some(true) => "ok",
            Some(false) => "DIFF",
            None => "-",
        };
        println!(
            "{:<22} {:>9} {:>9} {:<8} {:<10} | {:>9.3} {:>9} {:>6} | {:>9.3} {:>9} {:>6} {:>6} | {:>12} {:>9} {:<5}",
            r.instance,
            r.n,
            r.m,
            r.solver,
            r.peer_name,
            r.ours.total_s,
            fmt_opt(pt, 3),
            fmt_opt(ratio(r.ours.total_s, pt), 2),
            r.ours.solve_s,
            fmt_opt(ps, 3),
            fmt_opt(ratio(r.ours.solve_s, ps), 2),
            fmt_opt(r.ours.solve_cpu_s.and_then(|c| ratio(c, pc)), 2),
            r.ours.energy,
            r.ours.count,
            check
        );
    }
    println!(
        "times in seconds, fastest of the interleaved rounds; 'tot' = build + solve, 'slv' = \
         solve with the graph already built (urbansem: arc array built by prepare(), as the \
         peers build theirs while terms are added); ratio = urbansem / peer (< 1: urbansem \
         faster); 'cpu' = the same ratio of the solve's thread CPU time (robust to a loaded \
         machine). energy: QPBO \
         labelling with unlabelled as 0, or the flow; count: labelled variables, or sink-side \
         nodes. The peers' build runs a Python loop (thinqpbo has no array API), so 'tot' \
         favours urbansem there; 'slv' is the like-for-like number."
    );
}
