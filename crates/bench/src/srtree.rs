//! `urbansem bench srtree`: all real scans registered into one cloud, inserted scan by scan
//! (with and without free-space ray casting), then box queries; the peers (OctoMap,
//! libspatialindex) run in `scripts/bench_srtree_octomap.py` on the exported files.

use crate::metrics::{cpu_seconds, rss_bytes, Clock};
use anyhow::Context;
use serde_json::{json, Value};
use srtree::map::{MapOptions, SrMap};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Options of `urbansem bench srtree`.
#[derive(clap::Args)]
pub struct SrtreeBenchArgs {
    /// The folder holding `kitti360_2013_05_28_drive_0009/` and `mcd_kth_day_06/`.
    #[arg(long, default_value = "../shared/data/lidar")]
    data: PathBuf,
    /// Cell size, metres.
    #[arg(long, default_value_t = 0.1)]
    resolution: f64,
    /// Number of query boxes.
    #[arg(long, default_value_t = 2000)]
    boxes: usize,
    /// Seed of the query boxes.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Runs of all the queries; the median run time is reported (and the fastest).
    #[arg(long, default_value_t = 9)]
    repeat: usize,
    /// Builds of the map without ray casting; the median time is reported (with ray
    /// casting: one build).
    #[arg(long, default_value_t = 3)]
    insert_repeat: usize,
    /// Use at most this many scans per sequence.
    #[arg(long)]
    max_scans: Option<usize>,
    /// Write the registered cloud, scan origins, cell centres and boxes here for the peers.
    #[arg(long)]
    export: Option<PathBuf>,
    /// Skip the run with free-space ray casting.
    #[arg(long)]
    no_ray_casting: bool,
    /// Print one JSON object.
    #[arg(long)]
    json: bool,
}

fn write_f64s(path: &Path, values: impl Iterator<Item = f64>) -> anyhow::Result<()> {
    let bytes: Vec<u8> = values.flat_map(f64::to_le_bytes).collect();
    geodata::fsio::write_atomic(path, bytes).with_context(|| format!("writing {}", path.display()))
}

/// `urbansem bench srtree`: inserts all real scans, registered into one cloud, scan by scan
/// (with and without free-space ray casting), then times box queries.
pub fn bench_srtree(args: &SrtreeBenchArgs) -> anyhow::Result<()> {
    use rand::{Rng, SeedableRng};
    let sequences = srtree::scans::load_sequences(&args.data, args.max_scans)
        .with_context(|| format!("reading the labelled scans under {}", args.data.display()))?;
    let (cloud, ranges) = srtree::scans::combined_cloud(&sequences);
    let scans: Vec<(geodata::cloud::PointCloud, [f64; 3])> = ranges
        .iter()
        .map(|&(origin, start, end)| (cloud.filter(|i| i >= start && i < end), origin))
        .collect();
    let points = cloud.len();
    let mut runs = Vec::new();
    let mut plain_map = None;
    let modes: &[bool] = if args.no_ray_casting {
        &[false]
    } else {
        &[false, true]
    };
    let batch: Vec<(&geodata::cloud::PointCloud, Option<[f64; 3]>)> =
        scans.iter().map(|(c, o)| (c, Some(*o))).collect();
    for &ray_casting in modes {
        let builds = if ray_casting {
            1
        } else {
            args.insert_repeat.max(1)
        };
        let (mut walls, mut cpus) = (Vec::new(), Vec::new());
        let mut last = None;
        let mut rss = None;
        for _ in 0..builds {
            drop(last.take());
            let rss0 = rss_bytes().unwrap_or(0);
            let mut map = SrMap::new(MapOptions {
                resolution_m: args.resolution,
                ray_casting,
                ..MapOptions::default()
            })?;
            let (t, cpu0) = (Instant::now(), cpu_seconds(Clock::Process).unwrap_or(0.0));
            let stats = map.insert_scans(&batch)?;
            walls.push(t.elapsed().as_secs_f64());
            cpus.push(cpu_seconds(Clock::Process).unwrap_or(0.0) - cpu0);
            // RSS growth of the first build (later ones reuse freed pages).
            rss.get_or_insert(rss_bytes().unwrap_or(0).saturating_sub(rss0));
            last = Some((map, stats));
        }
        let (map, stats) = last.context("no map built")?;
        let rss = rss.unwrap_or(0);
        walls.sort_by(f64::total_cmp);
        cpus.sort_by(f64::total_cmp);
        let (seconds, cpu) = (walls[walls.len() / 2], cpus[cpus.len() / 2]);
        let (rays, misses) = (stats.rays, stats.misses);
        let mem = map.memory();
        let occupied = map.cells().iter().filter(|c| c.occupied()).count();
        runs.push(json!({
            "ray_casting": ray_casting,
            "seconds": seconds,
            "points_per_second": points as f64 / seconds.max(1e-9),
            "cpu_seconds": cpu,
            "points_per_cpu_second": points as f64 / cpu.max(1e-9),
            "builds": builds,
            "cells": map.len(),
            "occupied_cells": occupied,
            "rays": rays,
            "misses": misses,
            "memory": mem,
            "rss_growth_bytes": rss,
        }));
        if !ray_casting {
            plain_map = Some(map);
        }
    }
    let map = plain_map.context("no map built")?;
    // Boxes: centred on random cells, 1–20 m wide per axis.
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(args.seed);
    let boxes: Vec<[f64; 6]> = (0..args.boxes)
        .map(|_| {
            let c = map.centre(map.cells()[rng.gen_range(0..map.len())].key);
            let h: [f64; 3] = std::array::from_fn(|_| rng.gen_range(0.5..10.0));
            [
                c[0] - h[0],
                c[1] - h[1],
                c[2] - h[2],
                c[0] + h[0],
                c[1] + h[1],
                c[2] + h[2],
            ]
        })
        .collect();
    let mut times = Vec::new();
    let mut cpu_times = Vec::new();
    let mut found = 0usize;
    for _ in 0..args.repeat.max(1) {
        let (t, cpu0) = (Instant::now(), cpu_seconds(Clock::Thread).unwrap_or(0.0));
        found = boxes
            .iter()
            .map(|b| {
                map.cells_in_box([b[0], b[1], b[2]], [b[3], b[4], b[5]])
                    .len()
            })
            .sum();
        times.push(t.elapsed().as_secs_f64());
        cpu_times.push(cpu_seconds(Clock::Thread).unwrap_or(0.0) - cpu0);
    }
    times.sort_by(f64::total_cmp);
    cpu_times.sort_by(f64::total_cmp);
    let cpu_median = cpu_times[cpu_times.len() / 2];
    let best = times[times.len() / 2];
    let fastest = times[0];
    if let Some(dir) = &args.export {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
        write_f64s(
            &dir.join("points.f64"),
            cloud.positions.iter().flatten().copied(),
        )?;
        let centres = map
            .cells()
            .iter()
            .filter(|c| c.occupied())
            .flat_map(|c| map.centre(c.key));
        write_f64s(&dir.join("cells.f64"), centres)?;
        write_f64s(&dir.join("boxes.f64"), boxes.iter().flatten().copied())?;
        let scans_json: Vec<Value> = ranges
            .iter()
            .map(|(o, s, e)| json!({"origin": o, "start": s, "end": e}))
            .collect();
        let meta = json!({"resolution_m": args.resolution, "points": points, "scans": scans_json,
            "max_ray_m": MapOptions::default().max_ray_m});
        let p = dir.join("meta.json");
        geodata::fsio::write_atomic(&p, serde_json::to_string_pretty(&meta)?)
            .with_context(|| format!("writing {}", p.display()))?;
    }
    let out = json!({
        "points": points,
        "scans": ranges.len(),
        "resolution_m": args.resolution,
        "insert": runs,
        "queries": {
            "boxes": boxes.len(),
            "cells_found": found,
            "seconds": best,
            "seconds_fastest": fastest,
            "cpu_seconds": cpu_median,
            "repeat": times.len(),
            "microseconds_per_query": best * 1e6 / boxes.len().max(1) as f64,
        },
        "export": args.export.as_ref().map(|p| p.display().to_string()),
    });
    if args.json {
        println!("{}", serde_json::to_string_pretty(&out)?);
        return Ok(());
    }
    println!(
        "{points} points in {} scans, {} m cells",
        ranges.len(),
        args.resolution
    );
    for r in &runs {
        println!(
            "insert (ray casting {}): {:.2} s ({:.2} s CPU), {:.2} M points/s, {} cells, {:.0} bytes/cell ({:.1} MB), RSS +{:.1} MB",
            r["ray_casting"],
            r["seconds"].as_f64().unwrap_or(0.0),
            r["cpu_seconds"].as_f64().unwrap_or(0.0),
            r["points_per_second"].as_f64().unwrap_or(0.0) / 1e6,
            r["cells"],
            r["memory"]["bytes_per_cell"].as_f64().unwrap_or(0.0),
            r["memory"]["total_bytes"].as_f64().unwrap_or(0.0) / 1e6,
            r["rss_growth_bytes"].as_f64().unwrap_or(0.0) / 1e6
        );
    }
    println!(
        "box queries: {} boxes, {} cells found, median of {} runs {:.3} s ({:.3} s CPU, {:.1} µs per box)",
        boxes.len(),
        found,
        times.len(),
        best,
        cpu_median,
        best * 1e6 / boxes.len().max(1) as f64
    );
    Ok(())
}
