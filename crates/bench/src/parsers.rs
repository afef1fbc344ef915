//! `urbansem bench parsers`: every reader on generated inputs of three sizes (linear growth),
//! and the 512² OPB grid end to end (`urbansem pbo solve` as a user runs it) beside
//! Kolmogorov's QPBO (`thinqpbo`) on the same grid (issue 16). Its timings assume the
//! allocator keeps freed memory, which the `urbansem` binary sets for every command
//! (`keep_freed_memory` in `crates/urbansem/src/main.rs`), so that no size is timed on pages
//! faulted in afresh.

use anyhow::Context;
use clap::Args;
use fuzzing::scale::{formats, measure, Measurement};
use pbo::instances::denoising_grid;
use serde_json::{json, Value};
use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Instant;

/// Options of `urbansem bench parsers`.
#[derive(Args)]
pub struct ParsersBenchArgs {
    /// Input sizes in MB (10⁶ bytes), smallest first.
    #[arg(long, value_delimiter = ',', default_value = "2,16,128")]
    sizes_mb: Vec<f64>,
    /// Formats to run (comma-separated; default all): opb, mln-program, mln-evidence,
    /// osm-xml, ply-ascii, ply-binary, pcd-ascii, pcd-binary, pcd-compressed, las, laz,
    /// kitti-bin, srt.
    #[arg(long, value_delimiter = ',')]
    formats: Vec<String>,
    /// Reads per input; the fastest is reported.
    #[arg(long, default_value_t = 2)]
    repeat: usize,
    /// Folder for the generated inputs (each is removed after it was read).
    #[arg(long, default_value = "target/bench-parsers")]
    dir: PathBuf,
    /// Side of the OPB denoising grid solved end to end (0: skip).
    #[arg(long, default_value_t = 512)]
    grid: usize,
    /// Python interpreter for scripts/bench_pbo_peers.py (thinqpbo).
    #[arg(long, default_value = "python3")]
    python: String,
    /// Skip the peer (thinqpbo).
    #[arg(long)]
    no_peers: bool,
    /// Print one JSON object instead of the tables.
    #[arg(long)]
    json: bool,
}

/// Runs `urbansem bench parsers`.
pub fn run(args: &ParsersBenchArgs) -> anyhow::Result<()> {
    let all = formats();
    for f in &args.formats {
        if !all.iter().any(|g| g.name == f) {
            let names: Vec<&str> = all.iter().map(|g| g.name).collect();
            crate::usage!("unknown format {f:?}: expected one of {}", names.join(", "));
        }
    }
    if args.sizes_mb.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
        crate::usage!("--sizes-mb {:?}: expected positive sizes", args.sizes_mb);
    }
    let sizes: Vec<u64> = args.sizes_mb.iter().map(|s| (s * 1e6) as u64).collect();
    let mut rows: Vec<Measurement> = Vec::new();
    for format in all
        .iter()
        .filter(|f| args.formats.is_empty() || args.formats.iter().any(|n| n == f.name))
    {
        let m = measure(format, &sizes, &args.dir, args.repeat, |msg| {
            eprintln!("bench parsers: {msg}")
        })
        .map_err(|e| anyhow::anyhow!("{}: {e}", format.name))?;
        rows.extend(m);
    }
    let grid = if args.grid > 0 {
        Some(grid_end_to_end(args)?)
    } else {
        None
    };
    let worst = rows
        .iter()
        .filter_map(|r| r.growth.map(|g| (g, r.format)))
        .fold(None, |acc: Option<(f64, &str)>, (g, f)| match acc {
            Some((w, _)) if w >= g => acc,
            _ => Some((g, f)),
        });
    if args.json {
        let out = json!({
            "sizes_mb": args.sizes_mb,
            "readers": rows,
            "worst_growth": worst.map(|(g, f)| json!({"format": f, "growth": g})),
            "grid": grid,
        });
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{:<15} {:>10} {:>12} {:>9} {:>9} {:>7}",
        "reader", "MB", "items", "seconds", "MB/s", "growth"
    );
    for r in &rows {
        println!(
            "{:<15} {:>10.1} {:>12} {:>9.3} {:>9.1} {:>7}",
            r.format,
            r.bytes as f64 / 1e6,
            r.items,
            r.seconds,
            r.mb_per_s,
            r.growth.map_or("".to_owned(), |g| format!("{g:.2}"))
        );
    }
    if let Some((g, f)) = worst {
        println!(
            "worst growth ratio {g:.2} ({f}); 1.0 is linear, the size factor is quadratic; target ≤ 1.3"
        );
    }
    if let Some(g) = grid {
        println!("{}", g["text"].as_str().unwrap_or_default());
    }
    Ok(())
}

/// `urbansem pbo solve` on the grid file as a user runs it, and thinqpbo on the same grid.
fn grid_end_to_end(args: &ParsersBenchArgs) -> anyhow::Result<Value> {
    let side = args.grid;
    let inst = denoising_grid(side, side, 1);
    std::fs::create_dir_all(&args.dir)
        .with_context(|| format!("creating {}", args.dir.display()))?;
    let opb_path = args.dir.join(format!("grid{side}.opb"));
    geodata::fsio::write_atomic(&opb_path, pbo::opb::write_opb(&inst.to_opb()))
        .with_context(|| format!("writing {}", opb_path.display()))?;
    let bytes = std::fs::metadata(&opb_path)?.len();
    let exe = std::env::current_exe().context("locating the urbansem binary")?;
    let mut best = f64::INFINITY;
    let mut ours: Value = Value::Null;
    for _ in 0..args.repeat.max(1) {
        let t = Instant::now();
        let out = Command::new(&exe)
            .args(["pbo", "solve"])
            .arg(&opb_path)
            .arg("--json")
            .stderr(Stdio::inherit())
            .output()
            .context("running urbansem pbo solve")?;
        best = best.min(t.elapsed().as_secs_f64());
        anyhow::ensure!(out.status.success(), "urbansem pbo solve failed");
        ours = serde_json::from_slice(&out.stdout).context("parsing pbo solve --json")?;
    }
    let energy = ours["energy"].as_f64().unwrap_or(f64::NAN);
    // A failed peer is reported beside our numbers, not instead of them (the readers above
    // took minutes to measure).
    let (peer, peer_error) = if args.no_peers {
        (None, None)
    } else {
        match grid_peer(args, &inst) {
            Ok(p) => (p, None),
            Err(e) => {
                eprintln!("bench parsers: thinqpbo not run: {e:#}");
                (None, Some(format!("{e:#}")))
            }
        }
    };
    let text = format!(
        "OPB {side}² grid end to end ({:.1} MB, one objective line): urbansem pbo solve {best:.2} s \
         (process start, parse, solve, JSON out; target ≤ 2 s), energy {energy}{}",
        bytes as f64 / 1e6,
        match peer {
            Some((t, e)) => format!(
                "; thinqpbo build+solve {t:.3} s, energy {e} ({})",
                if e == energy { "equal" } else { "DIFFERENT" }
            ),
            None => match &peer_error {
                Some(e) => format!("; thinqpbo not run: {e}"),
                None => String::new(),
            },
        }
    );
    Ok(json!({
        "side": side,
        "bytes": bytes,
        "urbansem_seconds": best,
        "urbansem_energy": energy,
        "urbansem_seconds_parse_solve": ours["seconds"],
        "thinqpbo_seconds": peer.map(|p| p.0),
        "thinqpbo_energy": peer.map(|p| p.1),
        "thinqpbo_error": peer_error,
        "text": text,
    }))
}

/// Kolmogorov's QPBO (thinqpbo, through scripts/bench_pbo_peers.py) on the grid: (build and
/// solve seconds, energy), or `None` when the script reports none.
fn grid_peer(
    args: &ParsersBenchArgs,
    inst: &pbo::instances::QuadraticInstance,
) -> anyhow::Result<Option<(f64, f64)>> {
    let raw = inst
        .write_raw(&args.dir)
        .context("writing the raw grid for the peer")?;
    let json_out = args.dir.join("grid-peer.json");
    let script = crate::pbo::script_path();
    let status = Command::new(&args.python)
        .arg(&script)
        .arg(&raw)
        .args(["--repeat", "3", "--json-out"])
        .arg(&json_out)
        .stdout(Stdio::from(std::io::stderr()))
        .status()
        .with_context(|| format!("running {} {}", args.python, script.display()))?;
    anyhow::ensure!(
        status.success(),
        "the peer script failed (it needs numpy and thinqpbo: `pip install numpy thinqpbo`, or pass --python)"
    );
    let v: Value = serde_json::from_str(&std::fs::read_to_string(&json_out)?)?;
    let entry = v
        .get(raw.display().to_string())
        .and_then(|e| e.get("qpbo"))
        .cloned()
        .unwrap_or(Value::Null);
    Ok(
        match (entry["total_s"].as_f64(), entry["energy"].as_f64()) {
            (Some(t), Some(e)) => Some((t, e)),
            _ => None,
        },
    )
}
