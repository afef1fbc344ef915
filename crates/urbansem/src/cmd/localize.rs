//! `urbansem localize …`: global localization of a scan on OSM building outlines (issue 6).
//!
//! - `urbansem localize --map MAP --scan SCAN [--cost dcm|forward|reverse|symmetric] [--top K] [--json] [--svg FILE]`
//! - `urbansem localize eval --dataset DIR [--map MAP] [--method …] [--json] [--figures DIR]`
//!   (DIR: a simulated `localization` dataset, or an MCD sequence folder with `--map`).
//! - `urbansem localize extract-eval --dataset DIR [--stride N] [--json]` (DIR: a labelled
//!   KITTI-360 or MCD sequence): wall-extraction precision, recall, segments per scan.
//! - `urbansem localize track --map MAP --scans DIR --odometry FILE [--window K] [--json]`:
//!   every scan of a folder with the window of K scans ending at it, tied by odometry.
//!
//! Every form takes `--sensor auto|terrestrial|hdl64|vlp16|os1-64|os1-128` and the extraction
//! knobs of [`ExtractArgs`] (issue 15).

use crate::report::Svg;
use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use geodata::osm::OsmMap;
use localize::distractors::{embed_among_distractors, DistractorOptions, DistractorSummary};
use localize::eval::{accurate_within, is_mcd, mcd_scans, Accuracy, EvalScan, SimDataset};
use localize::extract_eval::{evaluate, labelled_scans};
use localize::hashing::{CornerIndex, HashingOptions};
use localize::index::{is_index, PreparedMap};
use localize::pipeline::{Localization, LocalizeOptions, Localizer};
use localize::rank::{rank_order, CostKind, Costs};
use localize::sensor::{ExtractOverrides, SensorChoice, SensorKind};
use localize::{Pose2, Segment};
use serde_json::{json, Value};
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Arguments of `urbansem localize`.
#[derive(Args)]
#[command(args_conflicts_with_subcommands = true)]
pub struct LocalizeArgs {
    /// `eval`: accuracy and timings over a dataset.
    #[command(subcommand)]
    pub command: Option<LocalizeCommand>,
    /// Localize one scan.
    #[command(flatten)]
    pub run: RunArgs,
}

/// Subcommands of `urbansem localize`.
#[derive(Subcommand)]
pub enum LocalizeCommand {
    /// Localize every scan of a dataset and print N_accurate, per-scan errors and timings.
    Eval(EvalArgs),
    /// Wall-segment extraction quality on labelled real scans (KITTI-360, MCD): precision,
    /// recall, segments per scan.
    ExtractEval(ExtractEvalArgs),
    /// Localize every scan of a track: a window of scans tied by odometry, searched as one.
    Track(TrackArgs),
    /// Prepare a map once and save it as an index (`.uloc`) that every `localize` command
    /// accepts as `--map`.
    Index(IndexArgs),
}

/// Arguments of `urbansem localize index`.
#[derive(Args)]
pub struct IndexArgs {
    /// OSM map (.osm or .osm.pbf).
    #[arg(long)]
    pub map: PathBuf,
    /// The index file to write (`.uloc`).
    #[arg(long)]
    pub out: PathBuf,
    /// Grid of the distance-transform tensor, metres (searches with the index must use the same).
    #[arg(long, default_value_t = 0.5)]
    pub grid_m: f64,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
}

/// Arguments of `urbansem localize track`.
#[derive(Args)]
pub struct TrackArgs {
    /// OSM map (.osm or .osm.pbf), or its index (.uloc, from `localize index`).
    #[arg(long)]
    pub map: PathBuf,
    /// Folder of gravity-levelled scans (any supported cloud format), taken in
    /// lexicographic file-name order.
    #[arg(long)]
    pub scans: PathBuf,
    /// One line per scan, `x_m y_m yaw_rad` (optionally `scan x_m y_m yaw_rad`), in any
    /// local odometry frame; `#` starts a comment.
    #[arg(long)]
    pub odometry: PathBuf,
    /// Scans per window (the scan and the K−1 before it).
    #[arg(long, default_value_t = 5)]
    pub window: usize,
    /// Candidates printed per scan.
    #[arg(long, default_value_t = 5)]
    pub top: usize,
    /// Cost that ranks the candidates.
    #[arg(long, value_enum, default_value = "reverse")]
    pub cost: CostArg,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Grid of the distance-transform tensor, metres.
    #[arg(long, default_value_t = 0.5)]
    pub grid_m: f64,
    /// Yaw step of the search, degrees.
    #[arg(long, default_value_t = 0.5)]
    pub yaw_step_deg: f64,
    /// Sensor profile and extraction knobs.
    #[command(flatten)]
    pub extract: ExtractArgs,
}

/// Sensor names accepted by `--sensor`.
#[derive(Clone, Copy, ValueEnum, PartialEq, Eq, Debug, Default)]
pub enum SensorArg {
    /// Mount height, beam layout and vertical field of view estimated from each scan.
    #[default]
    Auto,
    /// Panoramic terrestrial or tilting scanner.
    Terrestrial,
    /// Velodyne HDL-64E on a car roof.
    Hdl64,
    /// Velodyne VLP-16.
    Vlp16,
    /// Ouster OS1-64.
    #[value(name = "os1-64")]
    Os1_64,
    /// Ouster OS1-128.
    #[value(name = "os1-128")]
    Os1_128,
}

impl SensorArg {
    fn kind(self) -> Option<SensorKind> {
        match self {
            SensorArg::Auto => None,
            SensorArg::Terrestrial => Some(SensorKind::Terrestrial),
            SensorArg::Hdl64 => Some(SensorKind::Hdl64),
            SensorArg::Vlp16 => Some(SensorKind::Vlp16),
            SensorArg::Os1_64 => Some(SensorKind::Os1_64),
            SensorArg::Os1_128 => Some(SensorKind::Os1_128),
        }
    }

    fn choice(self) -> SensorChoice {
        self.kind().map_or(SensorChoice::Auto, SensorChoice::Named)
    }
}

/// The sensor profile and every knob of the wall extraction (unset: the profile's value).
#[derive(Args, Clone, Default)]
pub struct ExtractArgs {
    /// Sensor profile; `auto` estimates mount height, beams and field of view from each scan.
    #[arg(long, value_enum, default_value = "auto")]
    pub sensor: SensorArg,
    /// Wall points must be this high above the local ground, metres (cars, people below).
    #[arg(long)]
    pub clearance_m: Option<f64>,
    /// Voxel edge of the surface extraction, metres.
    #[arg(long)]
    pub voxel_m: Option<f64>,
    /// Points farther than this (horizontally) are ignored, metres.
    #[arg(long)]
    pub max_range_m: Option<f64>,
    /// Points closer than this (horizontally) are ignored, metres.
    #[arg(long)]
    pub min_range_m: Option<f64>,
    /// Lowest point kept, metres relative to the sensor.
    #[arg(long, allow_negative_numbers = true)]
    pub min_z_m: Option<f64>,
    /// Highest point kept, metres relative to the sensor.
    #[arg(long)]
    pub max_z_m: Option<f64>,
    /// Cell of the local ground estimate, metres.
    #[arg(long)]
    pub ground_cell_m: Option<f64>,
    /// Radius of the column neighbourhood a wall normal is fitted to, metres.
    #[arg(long)]
    pub column_radius_m: Option<f64>,
    /// Largest ratio of the small to the large eigenvalue of a wall neighbourhood.
    #[arg(long)]
    pub max_flatness: Option<f64>,
    /// Fewest columns in a neighbourhood for a normal.
    #[arg(long)]
    pub min_columns: Option<usize>,
    /// Largest share of a wall column's points with a return behind them (hedges, crowns; 1: off).
    #[arg(long)]
    pub max_see_through: Option<f64>,
    /// Fewest surface cells in a segment-histogram pixel.
    #[arg(long)]
    pub min_cell_count: Option<u32>,
    /// Shortest segment kept, metres.
    #[arg(long)]
    pub min_segment_m: Option<f64>,
}

impl ExtractArgs {
    fn overrides(&self) -> anyhow::Result<ExtractOverrides> {
        let positive = [
            ("--voxel-m", self.voxel_m),
            ("--max-range-m", self.max_range_m),
            ("--ground-cell-m", self.ground_cell_m),
            ("--column-radius-m", self.column_radius_m),
            ("--max-flatness", self.max_flatness),
            ("--max-see-through", self.max_see_through),
            ("--min-segment-m", self.min_segment_m),
        ];
        for (name, v) in positive {
            if let Some(v) = v {
                if !(v.is_finite() && v > 0.0) {
                    super::usage!("{name} {v}: expected a positive number");
                }
            }
        }
        for (name, v) in [
            ("--clearance-m", self.clearance_m),
            ("--min-range-m", self.min_range_m),
            ("--min-z-m", self.min_z_m),
            ("--max-z-m", self.max_z_m),
        ] {
            if let Some(v) = v {
                if !v.is_finite() {
                    super::usage!("{name} {v}: expected a finite number");
                }
            }
        }
        Ok(ExtractOverrides {
            voxel_m: self.voxel_m,
            max_range_m: self.max_range_m,
            min_range_m: self.min_range_m,
            min_z_m: self.min_z_m,
            max_z_m: self.max_z_m,
            clearance_m: self.clearance_m,
            ground_cell_m: self.ground_cell_m,
            column_radius_m: self.column_radius_m,
            max_flatness: self.max_flatness,
            min_columns: self.min_columns,
            max_see_through: self.max_see_through,
            min_cell_count: self.min_cell_count,
            min_segment_m: self.min_segment_m,
        })
    }
}

/// Arguments of `urbansem localize extract-eval`.
#[derive(Args)]
pub struct ExtractEvalArgs {
    /// A labelled real sequence folder (KITTI-360 or MCD layout).
    #[arg(long)]
    pub dataset: PathBuf,
    /// Use every N-th scan.
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Sensor profile and extraction knobs.
    #[command(flatten)]
    pub extract: ExtractArgs,
}

/// The cost that ranks candidates.
#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum CostArg {
    /// d_DCM of the search (eq. 5.3).
    Dcm,
    /// Forward d_f (eq. 5.4).
    Forward,
    /// Reverse d_r (eq. 5.5).
    Reverse,
    /// Symmetric d_s.
    Symmetric,
}

impl CostArg {
    fn kind(self) -> CostKind {
        match self {
            CostArg::Dcm => CostKind::Dcm,
            CostArg::Forward => CostKind::Forward,
            CostArg::Reverse => CostKind::Reverse,
            CostArg::Symmetric => CostKind::Symmetric,
        }
    }
}

/// Arguments of one localization.
#[derive(Args)]
pub struct RunArgs {
    /// OSM map (.osm or .osm.pbf), or its index (.uloc, from `localize index`).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Gravity-levelled scan in the sensor frame (PLY, PCD, LAS/LAZ, KITTI .bin).
    #[arg(long)]
    pub scan: Option<PathBuf>,
    /// Cost that ranks the candidates.
    #[arg(long, value_enum, default_value = "reverse")]
    pub cost: CostArg,
    /// Number of candidates printed.
    #[arg(long, default_value_t = 10)]
    pub top: usize,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write a figure (extracted segments over the map at the chosen pose, candidates).
    #[arg(long)]
    pub svg: Option<PathBuf>,
    /// Grid of the distance-transform tensor, metres.
    #[arg(long, default_value_t = 0.5)]
    pub grid_m: f64,
    /// Yaw step of the search, degrees (1 is about twice as fast, with fewer accurate
    /// candidates on maps with errors).
    #[arg(long, default_value_t = 0.5)]
    pub yaw_step_deg: f64,
    /// Sensor profile and extraction knobs.
    #[command(flatten)]
    pub extract: ExtractArgs,
}

/// Methods of `localize eval`.
#[derive(Clone, Copy, ValueEnum, PartialEq, Eq)]
pub enum Method {
    /// d_DCM, d_f, d_r, d_s and the hashing baseline.
    All,
    /// d_DCM.
    Dcm,
    /// d_f.
    Forward,
    /// d_r.
    Reverse,
    /// d_s.
    Symmetric,
    /// Geometric hashing (Cham et al. 2010).
    Hashing,
}

/// Arguments of `urbansem localize eval`.
#[derive(Args)]
pub struct EvalArgs {
    /// A `localization` dataset folder, or an MCD sequence folder (needs --map).
    #[arg(long)]
    pub dataset: PathBuf,
    /// OSM map, or its index (.uloc); default: the dataset's `map`.
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// Methods to evaluate (repeatable).
    #[arg(long, value_enum, default_values_t = [Method::All])]
    pub method: Vec<Method>,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write one SVG per scan and `curves.svg` (N_accurate against w, Figs. 5.5/5.6) into
    /// this folder.
    #[arg(long)]
    pub figures: Option<PathBuf>,
    /// Evaluate at most this many scans.
    #[arg(long)]
    pub limit: Option<usize>,
    /// Grid of the distance-transform tensor, metres.
    #[arg(long, default_value_t = 0.5)]
    pub grid_m: f64,
    /// Yaw step of the search, degrees (1 is about twice as fast, with fewer accurate
    /// candidates on maps with errors).
    #[arg(long, default_value_t = 0.5)]
    pub yaw_step_deg: f64,
    /// Embed the map among distractor buildings and streets cut from this other real OSM map
    /// (rotated tiles in a ring around the map's buildings; see `localize::distractors`).
    #[arg(long)]
    pub distractors: Option<PathBuf>,
    /// Seed of the distractor tiles' rotations and source centres.
    #[arg(long, default_value_t = 1)]
    pub distractor_seed: u64,
    /// Width of the distractor ring around the map's building bounding box, metres.
    #[arg(long, default_value_t = 400.0)]
    pub distractor_ring_m: f64,
    /// Track mode: localize each scan with the window of K scans ending at it, tied by
    /// odometry made from the true poses with drift (scans in file-name order).
    #[arg(long)]
    pub track: Option<usize>,
    /// Track mode: odometry scale error (0.02: 2 % of the distance travelled).
    #[arg(long, default_value_t = localize::track::ODOMETRY_SCALE_DRIFT)]
    pub odometry_drift: f64,
    /// Track mode: odometry heading drift, degrees per 50 m travelled.
    #[arg(long, default_value_t = localize::track::ODOMETRY_YAW_DRIFT_DEG_PER_50M)]
    pub odometry_yaw_drift_deg: f64,
    /// Sensor profile and extraction knobs.
    #[command(flatten)]
    pub extract: ExtractArgs,
}

/// Runs `urbansem localize`.
pub fn run(args: LocalizeArgs) -> anyhow::Result<()> {
    match args.command {
        Some(LocalizeCommand::Eval(e)) => eval(e),
        Some(LocalizeCommand::ExtractEval(e)) => extract_eval(e),
        Some(LocalizeCommand::Track(t)) => track(t),
        Some(LocalizeCommand::Index(i)) => index(i),
        None => run_one(args.run),
    }
}

fn options(
    cost: CostKind,
    grid_m: f64,
    yaw_step_deg: f64,
    extract: &ExtractArgs,
) -> anyhow::Result<LocalizeOptions> {
    if !(yaw_step_deg > 0.0 && yaw_step_deg <= 90.0) {
        super::usage!("--yaw-step-deg {yaw_step_deg}: expected a step in (0, 90] degrees");
    }
    let mut o = LocalizeOptions {
        rank_by: cost,
        sensor: extract.sensor.choice(),
        overrides: extract.overrides()?,
        ..LocalizeOptions::default()
    };
    o.chamfer.grid_m = grid_m;
    o.search.yaw_step_deg = yaw_step_deg;
    Ok(o)
}

fn candidate_json(map: &OsmMap, rank: usize, c: &localize::pipeline::Candidate) -> Value {
    let xy = [c.pose.x, c.pose.y];
    let (lat, lon) = map.frame.to_wgs84(xy);
    let yaw_geo =
        (c.pose.yaw_rad + map.frame.convergence_rad(xy)).rem_euclid(std::f64::consts::TAU);
    json!({
        "rank": rank + 1,
        "x": c.pose.x,
        "y": c.pose.y,
        "lat": lat,
        "lon": lon,
        "yaw": yaw_geo,
        "yaw_grid": c.pose.yaw_rad,
        "dcm": c.costs.dcm,
        "forward": c.costs.forward,
        "reverse": c.costs.reverse,
        "symmetric": c.costs.symmetric,
        "refined": c.refined,
        "confidence": c.confidence,
    })
}

/// The map of `--map`: an OSM file, or an index (`.uloc`) with the map it was built from.
fn load_map_or_index(path: &Path) -> anyhow::Result<(OsmMap, Option<PreparedMap>)> {
    if is_index(path) {
        let (prepared, source) = PreparedMap::read(path)?;
        let map = source.load(path)?;
        return Ok((map, Some(prepared)));
    }
    let map = OsmMap::load(path).with_context(|| format!("loading the map {}", path.display()))?;
    Ok((map, None))
}

/// A localizer on the map, prepared now or taken from its index.
fn prepare<'m>(
    map: &'m OsmMap,
    prepared: Option<PreparedMap>,
    options: LocalizeOptions,
    path: &Path,
) -> anyhow::Result<Localizer<'m>> {
    match prepared {
        Some(p) => Localizer::with_prepared(map, options, p)
            .with_context(|| format!("using the map index {}", path.display())),
        None => Localizer::new(map, options)
            .with_context(|| format!("preparing the map {}", path.display())),
    }
}

fn index(args: IndexArgs) -> anyhow::Result<()> {
    if is_index(&args.map) {
        super::usage!(
            "--map {}: expected an OSM map, not an index",
            args.map.display()
        );
    }
    if !is_index(&args.out) {
        super::usage!(
            "--out {}: the index file name must end in .uloc",
            args.out.display()
        );
    }
    let t = Instant::now();
    let map = OsmMap::load(&args.map)
        .with_context(|| format!("loading the map {}", args.map.display()))?;
    let load_s = t.elapsed().as_secs_f64();
    let mut o = LocalizeOptions::default();
    o.chamfer.grid_m = args.grid_m;
    let prepared = PreparedMap::build(&map, &o.chamfer, &o.search)
        .with_context(|| format!("preparing the map {}", args.map.display()))?;
    let t = Instant::now();
    prepared.write(&args.out, &args.map)?;
    let write_s = t.elapsed().as_secs_f64();
    let bytes = std::fs::metadata(&args.out).map(|m| m.len()).unwrap_or(0);
    let t = Instant::now();
    let (_, source) = PreparedMap::read(&args.out)?;
    source.load(&args.out)?;
    let load_index_s = t.elapsed().as_secs_f64();
    let dt = &prepared.dt;
    if args.json {
        let v = json!({
            "index": args.out,
            "map": args.map,
            "bytes": bytes,
            "edges": prepared.edges.len(),
            "tensor": [dt.width, dt.height, dt.channels],
            "grid_m": dt.grid_m,
            "seconds": {
                "load_map": load_s,
                "prepare": prepared.seconds,
                "write": write_s,
                "load_index": load_index_s,
            },
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
    } else {
        let s = &prepared.seconds;
        println!(
            "{}: {:.1} MB ({} edges, tensor {}×{}×{} at {} m); prepared in {:.2} s (tensor {:.2}, pyramid {:.2}, feasible {:.2}), written in {:.2} s; loading it back (index and map) takes {:.3} s",
            args.out.display(),
            bytes as f64 / 1e6,
            prepared.edges.len(),
            dt.width,
            dt.height,
            dt.channels,
            dt.grid_m,
            s.edges + s.distance_transform + s.pyramid + s.feasible,
            s.distance_transform,
            s.pyramid,
            s.feasible,
            write_s,
            load_index_s
        );
    }
    Ok(())
}

fn run_one(args: RunArgs) -> anyhow::Result<()> {
    let (Some(map_path), Some(scan_path)) = (&args.map, &args.scan) else {
        super::usage!(
            "urbansem localize needs --map MAP and --scan SCAN (or the `eval` subcommand)"
        );
    };
    let t = Instant::now();
    let (map, prepared) = load_map_or_index(map_path)?;
    let load_map_s = t.elapsed().as_secs_f64();
    let localizer = prepare(
        &map,
        prepared,
        options(
            args.cost.kind(),
            args.grid_m,
            args.yaw_step_deg,
            &args.extract,
        )?,
        map_path,
    )?;
    let t = Instant::now();
    let cloud = geodata::cloud::read_cloud(scan_path)
        .with_context(|| format!("reading the scan {}", scan_path.display()))?;
    let read_scan_s = t.elapsed().as_secs_f64();
    let result = localizer
        .localize_points(&cloud.positions)
        .with_context(|| format!("localizing {}", scan_path.display()))?;
    if let Some(svg_path) = &args.svg {
        let svg = figure(&localizer, &result, None, 100.0);
        geodata::fsio::write_atomic(svg_path, svg)
            .with_context(|| format!("writing {}", svg_path.display()))?;
    }
    let top: Vec<Value> = result
        .candidates
        .iter()
        .take(args.top)
        .enumerate()
        .map(|(i, c)| candidate_json(&map, i, c))
        .collect();
    let s = &result.seconds;
    if args.json {
        let v = json!({
            "map": map_path.display().to_string(),
            "scan": scan_path.display().to_string(),
            "cost": result.rank_by.name(),
            "candidates": top,
            "candidate_count": result.candidates.len(),
            "confidence": result.confidence,
            "segments": result.segments.len(),
            "sensor": result.sensor,
            "clearance_m": result.clearance_m,
            "vertical_cells": result.vertical_cells,
            "raw_poses": result.raw_poses,
            "after_suppression": result.after_suppression,
            "filtered": result.filtered,
            "search": result.search,
            "message": result.message,
            "seconds": {
                "load_map": load_map_s,
                "map_edges": localizer.seconds.edges,
                "distance_transform": localizer.seconds.distance_transform,
                "pyramid": localizer.seconds.pyramid,
                "feasible_mask": localizer.seconds.feasible,
                "read_scan": read_scan_s,
                "surfaces": s.surfaces,
                "segments": s.segments,
                "templates": s.templates,
                "search": s.search,
                "filter": s.filter,
                "visibility_costs": s.visibility_costs,
                "refine": s.refine,
                "total": s.total,
            },
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "{}: {} points, {} vertical cells, {} segments; {} raw poses → {} after suppression → {} candidates (ranked by {})",
        scan_path.display(),
        cloud.len(),
        result.vertical_cells,
        result.segments.len(),
        result.raw_poses,
        result.after_suppression,
        result.candidates.len(),
        result.rank_by.name()
    );
    if let Some(r) = &result.sensor {
        println!(
            "sensor {} ({}): mount {:.2} m, vertical field of view {:.1}° … {:.1}°, {} beams; wall clearance {:.2} m",
            r.profile,
            if r.detected { "detected" } else { "named" },
            r.geometry.mount_height_m,
            r.geometry.vfov_deg[0],
            r.geometry.vfov_deg[1],
            r.geometry.beams,
            result.clearance_m
        );
    }
    if let Some(m) = &result.message {
        println!("note: {m}");
    }
    println!(
        "{:>4} {:>10} {:>10} {:>11} {:>11} {:>8} {:>7} {:>7} {:>7} {:>7}",
        "rank", "x", "y", "lat", "lon", "yaw°", "dcm", "fwd", "rev", "sym"
    );
    for v in &top {
        let f = |k: &str| v.get(k).and_then(Value::as_f64).unwrap_or(f64::NAN);
        println!(
            "{:>4} {:>10.2} {:>10.2} {:>11.6} {:>11.6} {:>8.2} {:>7.3} {:>7.3} {:>7.3} {:>7.3}",
            f("rank"),
            f("x"),
            f("y"),
            f("lat"),
            f("lon"),
            f("yaw").to_degrees(),
            f("dcm"),
            f("forward"),
            f("reverse"),
            f("symmetric")
        );
    }
    println!("confidence {:.3}", result.confidence);
    println!(
        "seconds: map load {load_map_s:.2}, edges {:.3}, DT tensor {:.3}, pyramid {:.3}, scan read {read_scan_s:.3}, surfaces {:.3}, segments {:.3}, templates {:.3}, search {:.3}, filter {:.3}, visibility+costs {:.3}, refine {:.3}, total {:.3}",
        localizer.seconds.edges,
        localizer.seconds.distance_transform,
        localizer.seconds.pyramid,
        s.surfaces,
        s.segments,
        s.templates,
        s.search,
        s.filter,
        s.visibility_costs,
        s.refine,
        s.total
    );
    Ok(())
}

fn track(args: TrackArgs) -> anyhow::Result<()> {
    if args.window == 0 {
        super::usage!("--window 0: expected at least 1 scan per window");
    }
    let (map, prepared) = load_map_or_index(&args.map)?;
    let localizer = prepare(
        &map,
        prepared,
        options(
            args.cost.kind(),
            args.grid_m,
            args.yaw_step_deg,
            &args.extract,
        )?,
        &args.map,
    )?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(&args.scans)
        .with_context(|| format!("listing {}", args.scans.display()))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| geodata::cloud::Format::from_path(p).is_ok())
        .collect();
    files.sort();
    if files.is_empty() {
        anyhow::bail!(
            "{}: no scan files (PLY, PCD, LAS/LAZ, KITTI .bin)",
            args.scans.display()
        );
    }
    let names: Vec<String> = files
        .iter()
        .map(|p| {
            p.file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned())
        })
        .collect();
    let odometry = localize::track::read_odometry(&args.odometry, &names)?;
    let t = Instant::now();
    let mut extracted = Vec::with_capacity(files.len());
    for f in &files {
        let cloud = geodata::cloud::read_cloud(f)
            .with_context(|| format!("reading the scan {}", f.display()))?;
        extracted.push(
            localizer
                .scan_segments(&cloud.positions)
                .with_context(|| format!("extracting walls from {}", f.display()))?,
        );
    }
    let track_options = localize::track::TrackOptions {
        window: args.window,
        ..Default::default()
    };
    let results = localizer.localize_track(&extracted, &odometry, &track_options)?;
    let seconds = t.elapsed().as_secs_f64();
    let rows: Vec<Value> = names
        .iter()
        .zip(&results)
        .zip(&extracted)
        .map(|((name, r), e)| {
            let best = r.candidates.first().map(|c| candidate_json(&map, 0, c));
            let f = |k: &str| best.as_ref().and_then(|b| b.get(k).cloned()).unwrap_or(Value::Null);
            json!({
                "scan": name,
                "lat": f("lat"),
                "lon": f("lon"),
                "yaw": f("yaw"),
                "x": f("x"),
                "y": f("y"),
                "confidence": r.confidence,
                "candidates": r.candidates.iter().take(args.top).enumerate().map(|(i, c)| candidate_json(&map, i, c)).collect::<Vec<_>>(),
                "segments": e.segments.len(),
                "sensor": e.sensor,
                "message": r.message,
            })
        })
        .collect();
    if args.json {
        let v = json!({
            "map": args.map.display().to_string(),
            "scans_dir": args.scans.display().to_string(),
            "odometry": args.odometry.display().to_string(),
            "window": args.window,
            "cost": results.first().map_or("reverse", |r| r.rank_by.name()),
            "scans": rows,
            "seconds": {"total": seconds, "per_scan": seconds / files.len() as f64},
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "{}: {} scans, window {}, {:.2} s per scan",
        args.scans.display(),
        files.len(),
        args.window,
        seconds / files.len() as f64
    );
    println!(
        "{:>24} {:>5} {:>11} {:>11} {:>8} {:>6}",
        "scan", "segs", "lat", "lon", "yaw°", "conf"
    );
    for row in &rows {
        let g = |k: &str| row.get(k).and_then(Value::as_f64).unwrap_or(f64::NAN);
        println!(
            "{:>24} {:>5} {:>11.6} {:>11.6} {:>8.2} {:>6.3}",
            row["scan"].as_str().unwrap_or(""),
            row["segments"].as_u64().unwrap_or(0),
            g("lat"),
            g("lon"),
            g("yaw").to_degrees(),
            g("confidence")
        );
    }
    Ok(())
}

fn extract_eval(args: ExtractEvalArgs) -> anyhow::Result<()> {
    if args.stride == 0 {
        super::usage!("--stride 0: expected a stride of at least 1");
    }
    let overrides = args.extract.overrides()?;
    let t = Instant::now();
    let (kind, scans) = labelled_scans(&args.dataset, args.stride)
        .with_context(|| format!("reading {}", args.dataset.display()))?;
    if scans.is_empty() {
        anyhow::bail!("{}: no scans", args.dataset.display());
    }
    let read_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let result = evaluate(kind, &scans, args.extract.sensor.kind(), &|s, seg| {
        overrides.apply(s, seg)
    })?;
    let eval_s = t.elapsed().as_secs_f64();
    if args.json {
        let mut v = serde_json::to_value(&result)?;
        v["dataset"] = json!(args.dataset.display().to_string());
        v["sensor"] = json!(args.extract.sensor.kind().map_or("auto", SensorKind::name));
        v["seconds"] = json!({"read": read_s, "extract_and_score": eval_s});
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!(
        "{} ({}, {} scans): precision {:.3} ({:.3} counting the {:.0} % amid unlabelled points as wrong), recall {:.3}, {:.1} segments per scan",
        args.dataset.display(),
        result.kind,
        result.scans,
        result.precision,
        result.precision_all,
        100.0 * result.unjudged,
        result.recall,
        result.segments_per_scan
    );
    let profiles: Vec<String> = result
        .profiles
        .iter()
        .map(|(p, n)| format!("{p} ×{n}"))
        .collect();
    println!("sensor: {}", profiles.join(", "));
    let off: Vec<String> = result
        .off_building_m
        .iter()
        .map(|(c, m)| format!("{c} {m:.0} m"))
        .collect();
    println!(
        "segment length off buildings, by the class around it: {}",
        off.join(", ")
    );
    println!(
        "{:>12} {:>9} {:>7} {:>6} {:>7} {:>5} {:>9} {:>9} {:>6} {:>6}",
        "scan", "profile", "mount", "top°", "clear", "segs", "seg m", "on bldg", "facade", "cover"
    );
    for s in &result.per_scan {
        println!(
            "{:>12} {:>9} {:>7.2} {:>6.1} {:>7.2} {:>5} {:>9.1} {:>9.1} {:>6} {:>6}",
            s.scan,
            s.sensor.profile,
            s.sensor.geometry.mount_height_m,
            s.sensor.geometry.vfov_deg[1],
            s.clearance_m,
            s.segments,
            s.segment_m,
            s.on_building_m,
            s.facade_cells,
            s.covered_cells
        );
    }
    println!("seconds: read {read_s:.2}, extract and score {eval_s:.2}");
    Ok(())
}

/// A figure of one result: map outlines (grey), edges visible from the chosen pose (black),
/// scan segments at the chosen pose (red), candidates (blue; the best larger), truth (green).
fn figure(
    localizer: &Localizer<'_>,
    result: &Localization,
    truth: Option<Pose2>,
    half_m: f64,
) -> String {
    let centre = result
        .candidates
        .first()
        .map(|c| [c.pose.x, c.pose.y])
        .or(truth.map(|t| [t.x, t.y]))
        .unwrap_or([0.0, 0.0]);
    let (min, max) = (
        [centre[0] - half_m, centre[1] - half_m],
        [centre[0] + half_m, centre[1] + half_m],
    );
    let mut svg = Svg::new(600.0, min, max);
    for b in &localizer.map.buildings {
        if b.outer
            .iter()
            .any(|p| p[0] > min[0] && p[0] < max[0] && p[1] > min[1] && p[1] < max[1])
        {
            svg.polygon(&b.outer, "fill:#e6e0d4;stroke:#9a9a9a;stroke-width:1");
        }
    }
    for s in &localizer.map.streets.segments {
        svg.polyline(&[s.a, s.b], "stroke:#ffffff;stroke-width:2");
    }
    if let Some(best) = result.candidates.first() {
        for v in localizer.visible_from([best.pose.x, best.pose.y]) {
            svg.polyline(&[v.a, v.b], "stroke:#222;stroke-width:2");
        }
        for s in &result.segments {
            let m: Segment = s.transformed(&best.pose);
            svg.polyline(
                &[m.a, m.b],
                "stroke:#d62728;stroke-width:2.5;stroke-opacity:0.85",
            );
        }
    }
    for c in result.candidates.iter().skip(1).take(200) {
        svg.circle([c.pose.x, c.pose.y], 3.0, "fill:#6baed6;fill-opacity:0.7");
    }
    if let Some(t) = truth {
        svg.circle([t.x, t.y], 6.0, "fill:none;stroke:#2ca02c;stroke-width:2.5");
    }
    if let Some(best) = result.candidates.first() {
        svg.circle([best.pose.x, best.pose.y], 5.0, "fill:#1f4e9c");
        let tip = best.pose.apply([8.0, 0.0]);
        svg.polyline(
            &[[best.pose.x, best.pose.y], tip],
            "stroke:#1f4e9c;stroke-width:2",
        );
    }
    svg.scale_bar(20.0);
    svg.finish()
}

/// Per-scan evaluation record.
struct ScanRecord {
    name: String,
    truth: Pose2,
    /// Candidate poses ranked by each cost (dcm, forward, reverse, symmetric).
    ranked: [Vec<Pose2>; 4],
    /// Best costs of the top candidate by reverse.
    top_costs: Option<Costs>,
    hashing: Vec<Pose2>,
    result: Localization,
    hashing_s: f64,
}

const RADII: [f64; 6] = [50.0, 100.0, 200.0, 500.0, 1000.0, f64::INFINITY];
const KS: [usize; 3] = [1, 5, 10];

fn radius_name(w: f64) -> String {
    if w.is_finite() {
        format!("{w:.0}")
    } else {
        "map".into()
    }
}

fn eval(args: EvalArgs) -> anyhow::Result<()> {
    let methods: Vec<Method> = if args.method.contains(&Method::All) || args.method.is_empty() {
        vec![
            Method::Dcm,
            Method::Forward,
            Method::Reverse,
            Method::Symmetric,
            Method::Hashing,
        ]
    } else {
        args.method.clone()
    };
    let mcd = is_mcd(&args.dataset);
    let (map_path, sim) = if mcd {
        let Some(m) = args.map.clone() else {
            super::usage!(
                "{} is an MCD sequence; give the map with --map (e.g. ../shared/data/osm/kth_campus_stockholm.osm)",
                args.dataset.display()
            );
        };
        (m, None)
    } else {
        let d = SimDataset::open(&args.dataset)
            .with_context(|| format!("opening the dataset {}", args.dataset.display()))?;
        (
            args.map.clone().unwrap_or_else(|| d.map_path.clone()),
            Some(d),
        )
    };
    let t = Instant::now();
    let (map, prepared) = load_map_or_index(&map_path)?;
    if prepared.is_some() && args.distractors.is_some() {
        super::usage!(
            "--distractors changes the map, so it needs the OSM map, not the index {}",
            map_path.display()
        );
    }
    let (map, distractors) = match &args.distractors {
        Some(other_path) => {
            let other = OsmMap::load(other_path)
                .with_context(|| format!("loading the distractor map {}", other_path.display()))?;
            let options = DistractorOptions {
                ring_m: args.distractor_ring_m,
                seed: args.distractor_seed,
                ..DistractorOptions::default()
            };
            let (composed, summary) = embed_among_distractors(&map, &other, &options)
                .with_context(|| {
                    format!(
                        "embedding {} among distractors from {}",
                        map_path.display(),
                        other_path.display()
                    )
                })?;
            (composed, Some((other_path.clone(), options, summary)))
        }
        None => (map, None),
    };
    let load_map_s = t.elapsed().as_secs_f64();
    let localizer = prepare(
        &map,
        prepared,
        options(
            CostKind::Reverse,
            args.grid_m,
            args.yaw_step_deg,
            &args.extract,
        )?,
        &map_path,
    )?;
    let t = Instant::now();
    let hashing_index = CornerIndex::new(&map, &HashingOptions::default());
    let hashing_index_s = t.elapsed().as_secs_f64();
    let mut scans: Vec<EvalScan> = Vec::new();
    let count = match &sim {
        Some(d) => d.truth.len(),
        None => {
            scans = mcd_scans(&args.dataset, &map, 1)
                .with_context(|| format!("reading the MCD scans in {}", args.dataset.display()))?;
            scans.len()
        }
    };
    let count = args.limit.map_or(count, |l| l.min(count));
    if let Some(dir) = &args.figures {
        std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    }
    let load = |i: usize| -> anyhow::Result<EvalScan> {
        Ok(match &sim {
            Some(d) => d
                .load(i)
                .with_context(|| format!("loading scan {i} of {}", args.dataset.display()))?,
            None => scans
                .get(i)
                .cloned()
                .with_context(|| format!("MCD scan {i} missing"))?,
        })
    };
    // Track mode: every scan's walls first, then each window searched as one.
    let track_results: Option<Vec<Localization>> = match args.track {
        Some(0) => super::usage!("--track 0: expected a window of at least 1 scan"),
        Some(k) => {
            let mut truths = Vec::with_capacity(count);
            let mut extracted = Vec::with_capacity(count);
            for i in 0..count {
                let scan = load(i)?;
                truths.push(scan.truth);
                extracted.push(
                    localizer
                        .scan_segments(&scan.points)
                        .with_context(|| format!("extracting walls from {}", scan.name))?,
                );
            }
            let odometry = localize::track::drifted_odometry(
                &truths,
                args.odometry_drift,
                args.odometry_yaw_drift_deg.to_radians() / 50.0,
            );
            let track_options = localize::track::TrackOptions {
                window: k,
                ..Default::default()
            };
            Some(localizer.localize_track(&extracted, &odometry, &track_options)?)
        }
        None => None,
    };
    let mut records: Vec<ScanRecord> = Vec::new();
    for i in 0..count {
        let scan = match &sim {
            Some(d) => d
                .load(i)
                .with_context(|| format!("loading scan {i} of {}", args.dataset.display()))?,
            None => scans
                .get(i)
                .cloned()
                .with_context(|| format!("MCD scan {i} missing"))?,
        };
        let result = match &track_results {
            Some(results) => results[i].clone(),
            None => localizer
                .localize_points(&scan.points)
                .with_context(|| format!("localizing {}", scan.name))?,
        };
        let costs: Vec<Costs> = result.candidates.iter().map(|c| c.costs).collect();
        let poses: Vec<Pose2> = result.candidates.iter().map(|c| c.pose).collect();
        let ranked = CostKind::ALL.map(|k| {
            rank_order(&costs, &poses, k)
                .into_iter()
                .map(|j| poses[j])
                .collect()
        });
        let t = Instant::now();
        let hashing: Vec<Pose2> = if methods.contains(&Method::Hashing) {
            hashing_index
                .localize(&result.segments)
                .into_iter()
                .map(|(p, _)| p)
                .collect()
        } else {
            Vec::new()
        };
        let hashing_s = t.elapsed().as_secs_f64();
        if let Some(dir) = &args.figures {
            let path = dir.join(format!("{}.svg", scan.name.trim_end_matches(".ply")));
            geodata::fsio::write_atomic(&path, figure(&localizer, &result, Some(scan.truth), 90.0))
                .with_context(|| format!("writing {}", path.display()))?;
        }
        let rec = ScanRecord {
            name: scan.name.clone(),
            truth: scan.truth,
            ranked,
            top_costs: result.candidates.first().map(|c| c.costs),
            hashing,
            result,
            hashing_s,
        };
        if !args.json {
            print_scan_line(&rec);
        }
        records.push(rec);
    }
    summarize(
        &args,
        &methods,
        &map_path,
        load_map_s,
        hashing_index_s,
        &localizer,
        &records,
        mcd,
        distractors.as_ref(),
    )
}

/// The distractor map, its options and what was built.
type Distractors = (PathBuf, DistractorOptions, DistractorSummary);

fn top1_error(ranked: &[Pose2], truth: &Pose2) -> (f64, f64) {
    ranked.first().map_or((f64::NAN, f64::NAN), |p| {
        (p.distance_to(truth), p.yaw_error_to(truth).to_degrees())
    })
}

fn print_scan_line(r: &ScanRecord) {
    let mut line = format!(
        "{:<14} segs {:>3} cands {:>5}",
        r.name,
        r.result.segments.len(),
        r.result.candidates.len()
    );
    for (k, name) in ["dcm", "fwd", "rev", "sym"].iter().enumerate() {
        let (m, d) = top1_error(&r.ranked[k], &r.truth);
        line += &format!(" | {name} {m:>7.2} m {d:>6.2}°");
    }
    let (m, d) = top1_error(&r.hashing, &r.truth);
    line += &format!(" | hash {m:>7.2} m {d:>6.2}°");
    line += &format!(
        " | conf {:.2} | {:.2} s",
        r.result.confidence, r.result.seconds.total
    );
    if let Some(msg) = &r.result.message {
        line += &format!(" | {msg}");
    }
    println!("{line}");
}

fn median(mut v: Vec<f64>) -> f64 {
    v.retain(|x| x.is_finite());
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

#[allow(clippy::too_many_arguments)]
fn summarize(
    args: &EvalArgs,
    methods: &[Method],
    map_path: &Path,
    load_map_s: f64,
    hashing_index_s: f64,
    localizer: &Localizer<'_>,
    records: &[ScanRecord],
    mcd: bool,
    distractors: Option<&Distractors>,
) -> anyhow::Result<()> {
    let n = records.len();
    let method_rows: Vec<(&str, Method)> = methods
        .iter()
        .filter_map(|m| match m {
            Method::Dcm => Some(("dcm", *m)),
            Method::Forward => Some(("forward", *m)),
            Method::Reverse => Some(("reverse", *m)),
            Method::Symmetric => Some(("symmetric", *m)),
            Method::Hashing => Some(("hashing", *m)),
            Method::All => None,
        })
        .collect();
    let ranked_for = |r: &ScanRecord, m: Method| -> Vec<Pose2> {
        match m {
            Method::Dcm => r.ranked[0].clone(),
            Method::Forward => r.ranked[1].clone(),
            Method::Reverse => r.ranked[2].clone(),
            Method::Symmetric => r.ranked[3].clone(),
            Method::Hashing => r.hashing.clone(),
            Method::All => Vec::new(),
        }
    };
    let mut table = serde_json::Map::new();
    for (name, m) in &method_rows {
        let acc = if *m == Method::Hashing {
            Accuracy::HASHING
        } else {
            Accuracy::THESIS
        };
        let mut per_k = serde_json::Map::new();
        for k in KS {
            let mut per_w = serde_json::Map::new();
            for w in RADII {
                let c = records
                    .iter()
                    .filter(|r| accurate_within(&ranked_for(r, *m), &r.truth, k, w, acc))
                    .count();
                per_w.insert(radius_name(w), json!(c));
            }
            per_k.insert(k.to_string(), Value::Object(per_w));
        }
        table.insert(name.to_string(), Value::Object(per_k));
    }
    let in_set = records
        .iter()
        .filter(|r| {
            accurate_within(
                &r.ranked[2],
                &r.truth,
                usize::MAX,
                f64::INFINITY,
                Accuracy::THESIS,
            )
        })
        .count();
    let strict = Accuracy::STRICT;
    let strict_top1: Vec<usize> = (0..4)
        .map(|k| {
            records
                .iter()
                .filter(|r| {
                    r.ranked[k]
                        .first()
                        .is_some_and(|p| strict.accepts(p, &r.truth))
                })
                .count()
        })
        .collect();
    // Top 10 by d_r within 2 m / 3° (issue 15's car-mounted target), and the sensors seen.
    let strict_top10 = records
        .iter()
        .filter(|r| {
            r.ranked[2]
                .iter()
                .take(10)
                .any(|p| strict.accepts(p, &r.truth))
        })
        .count();
    // Track mode: the scans after the first window.
    // Track mode ranks by the chains of its window: judged in the localizer's own order.
    let track_summary = args.track.map(|k| {
        let after: Vec<&ScanRecord> = records.iter().skip(k.saturating_sub(1)).collect();
        let within = |r: &ScanRecord, n: usize| {
            r.result
                .candidates
                .iter()
                .take(n)
                .any(|c| strict.accepts(&c.pose, &r.truth))
        };
        let top1 = after.iter().filter(|r| within(r, 1)).count();
        let top10 = after.iter().filter(|r| within(r, 10)).count();
        (k, after.len(), top1, top10)
    });
    let mut sensors: Vec<(&str, usize)> = Vec::new();
    for r in records.iter() {
        let name = r.result.sensor.map_or("manual", |s| s.profile);
        match sensors.iter_mut().find(|(p, _)| *p == name) {
            Some(e) => e.1 += 1,
            None => sensors.push((name, 1)),
        }
    }
    let accurate_top1_err: Vec<f64> = records
        .iter()
        .filter_map(|r| {
            r.ranked[2]
                .first()
                .filter(|p| Accuracy::THESIS.accepts(p, &r.truth))
                .map(|p| p.distance_to(&r.truth))
        })
        .collect();
    let median_err = median(accurate_top1_err);
    let stage = |f: &dyn Fn(&ScanRecord) -> f64| -> (f64, f64, f64) {
        let v: Vec<f64> = records.iter().map(f).collect();
        let mean = if v.is_empty() {
            0.0
        } else {
            v.iter().sum::<f64>() / v.len() as f64
        };
        let max = v.iter().copied().fold(0.0, f64::max);
        (mean, median(v), max)
    };
    type StageFn = fn(&ScanRecord) -> f64;
    let stages: [(&str, StageFn); 9] = [
        ("surfaces", |r| r.result.seconds.surfaces),
        ("segments", |r| r.result.seconds.segments),
        ("templates", |r| r.result.seconds.templates),
        ("search", |r| r.result.seconds.search),
        ("filter", |r| r.result.seconds.filter),
        ("visibility_costs", |r| r.result.seconds.visibility_costs),
        ("refine", |r| r.result.seconds.refine),
        ("total", |r| r.result.seconds.total),
        ("hashing", |r| r.hashing_s),
    ];
    let timing: Vec<(&str, (f64, f64, f64))> = stages.iter().map(|(n, f)| (*n, stage(f))).collect();
    let threads = rayon::current_num_threads();
    let grid_m = localizer.dt.grid_m;
    let search_area_km2 = localizer.domain.cells() as f64 * grid_m * grid_m / 1e6;
    let distractors_json = distractors.map(|(path, o, s)| {
        json!({
            "map": path.display().to_string(),
            "seed": o.seed,
            "ring_m": o.ring_m,
            "gap_m": o.gap_m,
            "tile_m": o.tile_m,
            "summary": s,
        })
    });
    if let Some(dir) = &args.figures {
        let path = dir.join("curves.svg");
        let names: Vec<&str> = method_rows.iter().map(|(n, _)| *n).collect();
        geodata::fsio::write_atomic(&path, curves_svg(&table, &names, n))
            .with_context(|| format!("writing {}", path.display()))?;
    }
    if args.json {
        let scans: Vec<Value> = records
            .iter()
            .map(|r| {
                let errs: serde_json::Map<String, Value> =
                    ["dcm", "forward", "reverse", "symmetric"]
                        .iter()
                        .enumerate()
                        .map(|(k, name)| {
                            let (m, d) = top1_error(&r.ranked[k], &r.truth);
                            (name.to_string(), json!({"error_m": m, "error_deg": d}))
                        })
                        .chain(std::iter::once({
                            let (m, d) = top1_error(&r.hashing, &r.truth);
                            ("hashing".to_string(), json!({"error_m": m, "error_deg": d}))
                        }))
                        .collect();
                json!({
                    "scan": r.name,
                    "truth": {"x": r.truth.x, "y": r.truth.y, "yaw_grid": r.truth.yaw_rad},
                    "segments": r.result.segments.len(),
                    "sensor": r.result.sensor,
                    "clearance_m": r.result.clearance_m,
                    "raw_poses": r.result.raw_poses,
                    "search": r.result.search,
                    "candidates": r.result.candidates.len(),
                    "confidence": r.result.confidence,
                    "top1": errs,
                    "top_costs": r.top_costs,
                    "message": r.result.message,
                    "seconds": r.result.seconds,
                    "hashing_seconds": r.hashing_s,
                })
            })
            .collect();
        let v = json!({
            "dataset": args.dataset.display().to_string(),
            "map": map_path.display().to_string(),
            "scans": n,
            "thresholds": {"chamfer": {"m": 4.0, "rad": 0.2}, "hashing": {"m": 5.0, "rad": std::f64::consts::FRAC_PI_6}},
            "distractors": distractors_json,
            "search_area_km2": search_area_km2,
            "n_accurate": table,
            "accurate_in_candidate_set": in_set,
            "top1_within_2m_3deg": {"dcm": strict_top1[0], "forward": strict_top1[1], "reverse": strict_top1[2], "symmetric": strict_top1[3]},
            "top10_within_2m_3deg_reverse": strict_top10,
            "track": track_summary.map(|(k, n, t1, t10)| json!({
                "window": k,
                "odometry_drift": args.odometry_drift,
                "odometry_yaw_drift_deg_per_50m": args.odometry_yaw_drift_deg,
                "scans_after_first_window": n,
                "top1_within_2m_3deg": t1,
                "top10_within_2m_3deg": t10,
            })),
            "sensors": sensors.iter().map(|(p, n)| (p.to_string(), json!(n))).collect::<serde_json::Map<String, Value>>(),
            "median_error_accurate_top1_reverse_m": median_err,
            "map_seconds": {
                "load_map": load_map_s,
                "map_edges": localizer.seconds.edges,
                "distance_transform": localizer.seconds.distance_transform,
                "pyramid": localizer.seconds.pyramid,
                "feasible_mask": localizer.seconds.feasible,
                "hashing_index": hashing_index_s,
            },
            "tensor": {"width": localizer.dt.width, "height": localizer.dt.height, "channels": localizer.dt.channels, "grid_m": localizer.dt.grid_m, "bytes": localizer.dt.bytes()},
            "stage_seconds": timing.iter().map(|(n, (mean, med, max))| (n.to_string(), json!({"mean": mean, "median": med, "max": max}))).collect::<serde_json::Map<String, Value>>(),
            "threads": threads,
            "per_scan": scans,
        });
        println!("{}", serde_json::to_string_pretty(&v)?);
        return Ok(());
    }
    println!();
    println!(
        "{} scans of {} on {} ({})",
        n,
        args.dataset.display(),
        map_path.display(),
        if mcd { "real MCD scans" } else { "simulated" }
    );
    if let Some((path, o, s)) = distractors {
        println!(
            "embedded among distractors from {} (seed {}, ring {} m, gap {} m, tiles {} m): {} target buildings, {} distractor buildings ({} dropped at tile seams), {} distractor street segments in {} tiles; building box {:.2} km² → {:.2} km²",
            path.display(),
            o.seed,
            o.ring_m,
            o.gap_m,
            o.tile_m,
            s.target_buildings,
            s.distractor_buildings,
            s.dropped_overlapping,
            s.distractor_street_segments,
            s.tiles.len(),
            s.target_area_km2,
            s.outer_area_km2
        );
    }
    println!(
        "search area {search_area_km2:.2} km² ({} cells × {} yaws)",
        localizer.domain.cells(),
        records.first().map_or(0, |r| r.result.search.space
            / localizer.domain.cells().max(1))
    );
    println!("N_accurate (thresholds 4 m / 0.2 rad; hashing 5 m / π/6), k best candidates within radius w (m) of the truth:");
    let mut header = format!("{:<10} {:>3}", "method", "k");
    for w in RADII {
        header += &format!(" {:>6}", radius_name(w));
    }
    println!("{header}");
    for (name, _) in &method_rows {
        for k in KS {
            let mut line = format!("{name:<10} {k:>3}");
            for w in RADII {
                let c = table
                    .get(*name)
                    .and_then(|v| v.get(k.to_string()))
                    .and_then(|v| v.get(radius_name(w)))
                    .and_then(Value::as_u64)
                    .unwrap_or(0);
                line += &format!(" {c:>6}");
            }
            println!("{line}");
        }
    }
    println!(
        "accurate candidate in the candidate set: {in_set}/{n}; top-1 within 2 m and 3°: dcm {}, forward {}, reverse {}, symmetric {} of {n}; top 10 (reverse) within 2 m and 3°: {strict_top10}/{n}; median error of accurate top-1 (reverse, refined) {median_err:.2} m",
        strict_top1[0], strict_top1[1], strict_top1[2], strict_top1[3]
    );
    let sensor_counts: Vec<String> = sensors.iter().map(|(p, c)| format!("{p} ×{c}")).collect();
    println!("sensor profiles: {}", sensor_counts.join(", "));
    if let Some((k, after, t1, t10)) = track_summary {
        println!(
            "track mode (window {k}, odometry drift {:.1} % and {:.1}°/50 m): after the first window, top-1 (reverse) within 2 m and 3° for {t1}/{after} scans, top 10 for {t10}/{after}",
            100.0 * args.odometry_drift,
            args.odometry_yaw_drift_deg
        );
    }
    println!(
        "map: load {load_map_s:.2} s, edges {:.3} s, DT tensor {}×{}×{} at {} m {:.3} s, pyramid {:.3} s, feasible-pose mask {:.3} s ({} of {} cells), hashing index {hashing_index_s:.3} s ({threads} threads)",
        localizer.seconds.edges,
        localizer.dt.width,
        localizer.dt.height,
        localizer.dt.channels,
        localizer.dt.grid_m,
        localizer.seconds.distance_transform,
        localizer.seconds.pyramid,
        localizer.seconds.feasible,
        localizer.feasible.as_ref().map_or(localizer.domain.cells(), |m| m.feasible_cells),
        localizer.domain.cells()
    );
    println!(
        "{:<18} {:>9} {:>9} {:>9}",
        "stage (s/scan)", "mean", "median", "max"
    );
    for (name, (mean, med, max)) in &timing {
        println!("{name:<18} {mean:>9.4} {med:>9.4} {max:>9.4}");
    }
    Ok(())
}

/// The curves of thesis Figs. 5.5/5.6: N_accurate against the search radius w, one panel per
/// k, one line per method (`table[method][k][w]` as built by `summarize`).
fn curves_svg(table: &serde_json::Map<String, Value>, methods: &[&str], scans: usize) -> String {
    use std::fmt::Write as _;
    let (pw, ph, left, top, gap) = (260.0, 220.0, 48.0, 30.0, 30.0);
    let width = left + KS.len() as f64 * (pw + gap) + 110.0;
    let height = top + ph + 50.0;
    let colour = |m: &str| match m {
        "dcm" => "#7f7f7f",
        "forward" => "#1f77b4",
        "reverse" => "#d62728",
        "symmetric" => "#2ca02c",
        _ => "#9467bd",
    };
    let mut out = format!(
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="{width:.0}" height="{height:.0}" viewBox="0 0 {width:.0} {height:.0}" font-family="sans-serif" font-size="11"><rect width="100%" height="100%" fill="white"/>"#
    );
    let ymax = scans.max(1) as f64;
    for (p, k) in KS.iter().enumerate() {
        let x0 = left + p as f64 * (pw + gap);
        let px = |i: usize| x0 + pw * i as f64 / (RADII.len() - 1) as f64;
        let py = |v: f64| top + ph * (1.0 - v / ymax);
        let _ = write!(
            out,
            r#"<rect x="{x0:.1}" y="{top:.1}" width="{pw:.1}" height="{ph:.1}" fill="none" stroke="dimgray"/><text x="{:.1}" y="{:.1}" text-anchor="middle">k = {k}</text>"#,
            x0 + pw / 2.0,
            top - 8.0
        );
        for (i, w) in RADII.iter().enumerate() {
            let _ = write!(
                out,
                r#"<line x1="{x:.1}" y1="{y0:.1}" x2="{x:.1}" y2="{y1:.1}" stroke="gainsboro"/><text x="{x:.1}" y="{ty:.1}" text-anchor="middle">{}</text>"#,
                radius_name(*w),
                x = px(i),
                y0 = top,
                y1 = top + ph,
                ty = top + ph + 14.0
            );
        }
        for q in 0..=4 {
            let v = ymax * q as f64 / 4.0;
            let _ = write!(
                out,
                r#"<text x="{:.1}" y="{:.1}" text-anchor="end">{v:.0}</text>"#,
                x0 - 4.0,
                py(v) + 4.0
            );
        }
        let _ = write!(
            out,
            r#"<text x="{:.1}" y="{:.1}" text-anchor="middle">search radius w (m)</text>"#,
            x0 + pw / 2.0,
            top + ph + 32.0
        );
        for m in methods {
            let pts: Vec<String> = RADII
                .iter()
                .enumerate()
                .map(|(i, w)| {
                    let c = table
                        .get(*m)
                        .and_then(|v| v.get(k.to_string()))
                        .and_then(|v| v.get(radius_name(*w)))
                        .and_then(Value::as_u64)
                        .unwrap_or(0);
                    format!("{:.1},{:.1}", px(i), py(c as f64))
                })
                .collect();
            let _ = write!(
                out,
                r#"<polyline points="{}" fill="none" stroke="{}" stroke-width="2"/>"#,
                pts.join(" "),
                colour(m)
            );
        }
    }
    let _ = write!(
        out,
        r#"<text x="12" y="{:.1}" transform="rotate(-90 12 {:.1})" text-anchor="middle">N_accurate of {scans}</text>"#,
        top + ph / 2.0,
        top + ph / 2.0
    );
    let lx = left + KS.len() as f64 * (pw + gap);
    for (i, m) in methods.iter().enumerate() {
        let y = top + 14.0 + 18.0 * i as f64;
        let _ = write!(
            out,
            r#"<line x1="{lx:.1}" y1="{y:.1}" x2="{:.1}" y2="{y:.1}" stroke="{}" stroke-width="2"/><text x="{:.1}" y="{:.1}">{m}</text>"#,
            lx + 22.0,
            colour(m),
            lx + 28.0,
            y + 4.0
        );
    }
    out.push_str("</svg>");
    out
}

/// An HTML table of JSON rows: one column per (header, key, decimals).
fn rows_table(rows: &[Value], columns: &[(&str, &str, usize)]) -> String {
    let cells: Vec<Vec<String>> = rows
        .iter()
        .map(|r| {
            columns
                .iter()
                .map(|&(_, key, decimals)| {
                    let v = r.get(key).and_then(Value::as_f64).unwrap_or(f64::NAN);
                    format!("{v:.decimals$}")
                })
                .collect()
        })
        .collect();
    let headers: Vec<&str> = columns.iter().map(|c| c.0).collect();
    crate::report::Html::table(&headers, &cells)
}

/// The demo stage: simulated scans of the embedded default city (with the OSM map-error
/// model) localized on its map without a prior.
pub(crate) fn demo_stage(
    args: &crate::cmd::demo::DemoArgs,
) -> anyhow::Result<crate::cmd::demo::StageOutput> {
    use geodata::sim::scene::{MapErrorOptions, Scene, SceneOptions};
    use geodata::sim::sensor::{scan_with, ScanFrame, SensorOptions};

    let map = geodata::city::default_city_map().context("generating the embedded default city")?;
    let scene = Scene::build(
        &map,
        &SceneOptions {
            map_error: MapErrorOptions::osm_like(),
            ..SceneOptions::default()
        },
        args.seed,
    )
    .context("building the simulated world")?;
    let poses = scene
        .sample_poses_with_height(2, 1.8, args.seed)
        .context("placing scanner poses")?;
    // A coarser scanner than the datasets' (0.8° × 1°) keeps the stage at a few seconds.
    let sensor = SensorOptions {
        h_step_deg: 0.8,
        v_step_deg: 1.0,
        ..SensorOptions::default()
    };
    let mut options = LocalizeOptions::default();
    options.visibility.scanner_step_deg = sensor.h_step_deg;
    let localizer = Localizer::new(&map, options).context("preparing the map")?;
    let mut rows = Vec::new();
    let mut figures = Vec::new();
    let mut files = Vec::new();
    let mut accurate = 0;
    for (i, pose) in poses.iter().enumerate() {
        let (cloud, _) = scan_with(
            &scene,
            pose,
            &sensor,
            args.seed + i as u64,
            ScanFrame::Sensor,
        )
        .context("scanning")?;
        // The truth in the map's frame, as the datasets' truth.json.
        let field = &scene.map_error.field;
        let world_xy = [pose.position[0], pose.position[1]];
        let map_xy = field.map_from_world(world_xy);
        let truth = Pose2 {
            x: map_xy[0],
            y: map_xy[1],
            yaw_rad: pose.yaw_rad + field.rotation_rad(world_xy),
        };
        let result = localizer
            .localize_points(&cloud.positions)
            .context("localizing")?;
        let (e_m, e_deg) = result.candidates.first().map_or((f64::NAN, f64::NAN), |c| {
            (
                c.pose.distance_to(&truth),
                c.pose.yaw_error_to(&truth).to_degrees(),
            )
        });
        if result
            .candidates
            .first()
            .is_some_and(|c| Accuracy::THESIS.accepts(&c.pose, &truth))
        {
            accurate += 1;
        }
        rows.push(json!({
            "scan": i,
            "points": cloud.len(),
            "segments": result.segments.len(),
            "candidates": result.candidates.len(),
            "error_m": e_m,
            "error_deg": e_deg,
            "confidence": result.confidence,
            "seconds": result.seconds.total,
        }));
        if i == 0 {
            let svg = figure(&localizer, &result, Some(truth), 90.0);
            files.push(("localize.svg", svg.clone().into_bytes()));
            figures.push(svg);
        }
    }
    let table = rows_table(
        &rows,
        &[
            ("scan", "scan", 0),
            ("segments", "segments", 0),
            ("candidates", "candidates", 0),
            ("top-1 error m", "error_m", 2),
            ("top-1 error °", "error_deg", 2),
            ("confidence", "confidence", 2),
            ("s", "seconds", 2),
        ],
    );
    Ok(crate::cmd::demo::StageOutput {
        key: "localize",
        summary: json!({
            "scans": rows.len(),
            "top1_accurate_4m_0.2rad": accurate,
            "tensor_seconds": localizer.seconds.distance_transform,
            "per_scan": rows,
        }),
        title: "localize: global localization on building outlines (FDCM + visibility-aware reverse cost)",
        text_html: format!(
            "{} simulated scans of the default city (OSM map-error model on) localized on the whole map without a prior; \
             {accurate} of them have an accurate top-1 pose (4 m, 0.2 rad). Figure: map outlines (grey), edges visible from \
             the chosen pose (black), scan segments at the chosen pose (red), other candidates (light blue), truth (green ring).{table}",
            rows.len()
        ),
        figures,
        files,
    })
}

/// The demo's car-LiDAR stage: a simulated HDL-64 drive through the embedded default city
/// (OSM map-error model on), localized in track mode with odometry that drifts 2 % and
/// 1° per 50 m, drawn over the map with the truth.
pub(crate) fn demo_track_stage(
    args: &crate::cmd::demo::DemoArgs,
) -> anyhow::Result<crate::cmd::demo::StageOutput> {
    use geodata::sim::dataset::{write_localization, LocalizationOptions};

    const SCANS: usize = 12;
    const WINDOW: usize = 5;
    let strict = Accuracy::STRICT;
    let map = geodata::city::default_city_map().context("generating the embedded default city")?;
    // The scans are written as a dataset (as `sim dataset --sensor hdl64` writes them), read
    // back, and removed: the demo's folder keeps only the figure and the summary.
    let dir = args.out.join(".track-hdl64");
    let options = LocalizationOptions {
        scans: SCANS,
        ..LocalizationOptions::for_sensor(geodata::sensors::SensorKind::Hdl64)
    };
    let started = Instant::now();
    write_localization(
        &map,
        "embedded default city",
        &dir,
        &options,
        args.seed,
        &|_, _| {},
    )
    .context("simulating the HDL-64 drive")?;
    let simulate_s = started.elapsed().as_secs_f64();
    let dataset = SimDataset::open(&dir)?;
    let localizer =
        Localizer::new(&map, LocalizeOptions::default()).context("preparing the map")?;
    let started = Instant::now();
    let mut truths = Vec::with_capacity(SCANS);
    let mut extracted = Vec::with_capacity(SCANS);
    for i in 0..dataset.truth.len() {
        let scan = dataset.load(i)?;
        truths.push(scan.truth);
        extracted.push(
            localizer
                .scan_segments(&scan.points)
                .with_context(|| format!("extracting walls from {}", scan.name))?,
        );
    }
    std::fs::remove_dir_all(&dir).with_context(|| format!("removing {}", dir.display()))?;
    let odometry = localize::track::drifted_odometry(
        &truths,
        localize::track::ODOMETRY_SCALE_DRIFT,
        localize::track::ODOMETRY_YAW_DRIFT_DEG_PER_50M.to_radians() / 50.0,
    );
    let results = localizer.localize_track(
        &extracted,
        &odometry,
        &localize::track::TrackOptions {
            window: WINDOW,
            ..Default::default()
        },
    )?;
    let track_s = started.elapsed().as_secs_f64();
    let after_window = truths.len().saturating_sub(WINDOW - 1);
    let mut top1 = 0;
    let mut top10 = 0;
    let mut rows = Vec::new();
    for (i, (r, truth)) in results.iter().zip(&truths).enumerate() {
        let ok1 = r
            .candidates
            .first()
            .is_some_and(|c| strict.accepts(&c.pose, truth));
        let ok10 = r
            .candidates
            .iter()
            .take(10)
            .any(|c| strict.accepts(&c.pose, truth));
        if i + 1 >= WINDOW {
            top1 += usize::from(ok1);
            top10 += usize::from(ok10);
        }
        let (e_m, e_deg) = r.candidates.first().map_or((f64::NAN, f64::NAN), |c| {
            (
                c.pose.distance_to(truth),
                c.pose.yaw_error_to(truth).to_degrees(),
            )
        });
        rows.push(json!({
            "scan": i,
            "segments": extracted[i].segments.len(),
            "candidates": r.candidates.len(),
            "error_m": e_m,
            "error_deg": e_deg,
            "confidence": r.confidence,
            "top1_within_2m_3deg": ok1,
        }));
    }
    let svg = track_figure(&map, &truths, &results, &strict, WINDOW);
    let table = rows_table(
        &rows,
        &[
            ("scan", "scan", 0),
            ("segments", "segments", 0),
            ("top-1 error m", "error_m", 2),
            ("top-1 error °", "error_deg", 2),
            ("confidence", "confidence", 2),
        ],
    );
    Ok(crate::cmd::demo::StageOutput {
        key: "localize_track",
        summary: json!({
            "sensor": "hdl64",
            "scans": truths.len(),
            "window": WINDOW,
            "scans_after_first_window": after_window,
            "top1_within_2m_3deg": top1,
            "top10_within_2m_3deg": top10,
            "per_scan": rows,
            "simulate_seconds": simulate_s,
            "track_seconds": track_s,
        }),
        title: "localize track: a car-mounted HDL-64 drive localized along its track",
        text_html: format!(
            "{} simulated HDL-64 scans (1.73 m above the road, heading along it) of a drive through the default city, \
             OSM map-error model on, localized on the whole map in track mode (window {WINDOW}, odometry drifting 2 % \
             and 1° per 50 m). After the first window, {top1} of {after_window} scans have an accurate top-1 pose \
             (2 m, 3°) and {top10} an accurate pose among the top 10. Figure: true track (green), each scan's next 9 \
             candidates where the track keeps any (light blue), its chosen pose (dark blue when accurate, red when not; the first window's \
             scans ringed), a thin line from the chosen pose to the truth.{table}",
            truths.len()
        ),
        figures: vec![svg.clone()],
        files: vec![("localize_track.svg", svg.into_bytes())],
    })
}

/// The track figure: the map around the drive, the true track, every scan's candidates and
/// chosen pose.
fn track_figure(
    map: &OsmMap,
    truths: &[Pose2],
    results: &[Localization],
    accuracy: &Accuracy,
    window: usize,
) -> String {
    let mut min = [f64::INFINITY; 2];
    let mut max = [f64::NEG_INFINITY; 2];
    for t in truths {
        for k in 0..2 {
            let v = [t.x, t.y][k];
            min[k] = min[k].min(v);
            max[k] = max[k].max(v);
        }
    }
    let half = ((max[0] - min[0]).max(max[1] - min[1]) / 2.0 + 60.0).max(80.0);
    let centre = [(min[0] + max[0]) / 2.0, (min[1] + max[1]) / 2.0];
    let (min, max) = (
        [centre[0] - half, centre[1] - half],
        [centre[0] + half, centre[1] + half],
    );
    let inside = |p: &[f64; 2]| p[0] > min[0] && p[0] < max[0] && p[1] > min[1] && p[1] < max[1];
    let mut svg = Svg::new(640.0, min, max);
    for b in &map.buildings {
        if b.outer.iter().any(inside) {
            svg.polygon(&b.outer, "fill:#e6e0d4;stroke:#9a9a9a;stroke-width:1");
        }
    }
    for s in &map.streets.segments {
        if inside(&s.a) || inside(&s.b) {
            svg.polyline(&[s.a, s.b], "stroke:#bbbbbb;stroke-width:1.5");
        }
    }
    let track: Vec<[f64; 2]> = truths.iter().map(|t| [t.x, t.y]).collect();
    svg.polyline(
        &track,
        "fill:none;stroke:#2ca02c;stroke-width:3;stroke-opacity:0.8",
    );
    for r in results {
        for c in r.candidates.iter().skip(1).take(9) {
            svg.circle([c.pose.x, c.pose.y], 2.5, "fill:#6baed6;fill-opacity:0.7");
        }
    }
    for (i, (r, t)) in results.iter().zip(truths).enumerate() {
        let Some(best) = r.candidates.first() else {
            continue;
        };
        let p = [best.pose.x, best.pose.y];
        svg.polyline(&[p, [t.x, t.y]], "stroke:#555;stroke-width:0.8");
        let colour = if accuracy.accepts(&best.pose, t) {
            "#1f4e9c"
        } else {
            "#d62728"
        };
        svg.circle(p, 4.0, &format!("fill:{colour}"));
        svg.polyline(
            &[p, best.pose.apply([8.0, 0.0])],
            &format!("stroke:{colour};stroke-width:2"),
        );
        if i + 1 < window {
            svg.circle(p, 7.0, &format!("fill:none;stroke:{colour};stroke-width:1"));
        }
    }
    svg.scale_bar(50.0);
    svg.finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn demo_stage_localizes_simulated_scans() {
        use clap::{Args, FromArgMatches};
        let out = std::env::temp_dir().join("urbansem-localize-demo-test");
        let matches = crate::cmd::demo::DemoArgs::augment_args(clap::Command::new("demo"))
            .get_matches_from(["demo", "--out", &out.display().to_string()]);
        let args = crate::cmd::demo::DemoArgs::from_arg_matches(&matches).unwrap();
        let stage = demo_stage(&args).unwrap();
        assert_eq!(stage.key, "localize");
        assert_eq!(stage.summary["scans"], 2);
        assert_eq!(stage.files.len(), 1);
        assert!(stage.figures[0].starts_with("<svg"));
    }

    #[test]
    fn demo_track_stage_follows_a_simulated_hdl64_drive() {
        use clap::{Args, FromArgMatches};
        let out = tempfile::tempdir().unwrap();
        let matches = crate::cmd::demo::DemoArgs::augment_args(clap::Command::new("demo"))
            .get_matches_from(["demo", "--out", &out.path().display().to_string()]);
        let args = crate::cmd::demo::DemoArgs::from_arg_matches(&matches).unwrap();
        let stage = demo_track_stage(&args).unwrap();
        assert_eq!(stage.key, "localize_track");
        assert_eq!(stage.summary["scans_after_first_window"], 8);
        // The scans are removed again; the figure is the stage's one file.
        assert!(!out.path().join(".track-hdl64").exists());
        assert_eq!(stage.files.len(), 1);
        assert!(stage.figures[0].starts_with("<svg"));
        let top1 = stage.summary["top1_within_2m_3deg"].as_u64().unwrap();
        assert!(top1 >= 6, "{}", stage.summary);
    }

    #[test]
    fn localize_without_map_or_scan_is_a_clear_error() {
        let err = run_one(RunArgs {
            map: None,
            scan: None,
            cost: CostArg::Reverse,
            top: 10,
            json: false,
            svg: None,
            grid_m: 0.5,
            yaw_step_deg: 0.5,
            extract: ExtractArgs::default(),
        })
        .unwrap_err();
        assert!(err.to_string().contains("--map"), "{err}");
    }
}
