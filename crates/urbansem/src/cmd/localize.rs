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

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use geodata::osm::OsmMap;
use localize::distractors::DistractorOptions;
use localize::eval::is_mcd;
use localize::eval::report::{RankMethod, TrackSetup};
use localize::eval::run::{run_eval, EvalJob};
use localize::extract_eval::{evaluate, labelled_scans};
use localize::index::{is_index, load_map_or_index, PreparedMap};
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::rank::CostKind;
use localize::report::{LocalizeReport, TrackReport, TrackRow, TrackSeconds};
use localize::sensor::{ExtractOverrides, SensorChoice, SensorKind};
use localize::LocalizeError;
use serde_json::json;
use std::path::PathBuf;
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
    let localizer = Localizer::prepared_or_new(
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
        let svg = localize::figure::result_svg(&localizer, &result, None, 100.0);
        geodata::fsio::write_atomic(svg_path, svg)
            .with_context(|| format!("writing {}", svg_path.display()))?;
    }
    let report = LocalizeReport::new(
        &localizer,
        &map_path.display().to_string(),
        &scan_path.display().to_string(),
        &result,
        args.top,
        load_map_s,
        read_scan_s,
    );
    if args.json {
        return super::print_json(&report);
    }
    let (s, stages) = (&report.seconds, &report.seconds.scan);
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
    for c in &report.candidates {
        println!(
            "{:>4} {:>10.2} {:>10.2} {:>11.6} {:>11.6} {:>8.2} {:>7.3} {:>7.3} {:>7.3} {:>7.3}",
            c.rank,
            c.x,
            c.y,
            c.lat,
            c.lon,
            c.yaw.to_degrees(),
            c.dcm,
            c.forward,
            c.reverse,
            c.symmetric
        );
    }
    println!("confidence {:.3}", result.confidence);
    println!(
        "seconds: map load {:.2}, edges {:.3}, DT tensor {:.3}, pyramid {:.3}, scan read {:.3}, surfaces {:.3}, segments {:.3}, templates {:.3}, search {:.3}, filter {:.3}, visibility+costs {:.3}, refine {:.3}, total {:.3}",
        s.load_map,
        s.map_edges,
        s.distance_transform,
        s.pyramid,
        s.read_scan,
        stages.surfaces,
        stages.segments,
        stages.templates,
        stages.search,
        stages.filter,
        stages.visibility_costs,
        stages.refine,
        stages.total
    );
    Ok(())
}

fn track(args: TrackArgs) -> anyhow::Result<()> {
    if args.window == 0 {
        super::usage!("--window 0: expected at least 1 scan per window");
    }
    let (map, prepared) = load_map_or_index(&args.map)?;
    let localizer = Localizer::prepared_or_new(
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
    let report = TrackReport {
        map: args.map.display().to_string(),
        scans_dir: args.scans.display().to_string(),
        odometry: args.odometry.display().to_string(),
        window: args.window,
        cost: results.first().map_or("reverse", |r| r.rank_by.name()),
        scans: names
            .iter()
            .zip(&results)
            .zip(&extracted)
            .map(|((name, r), e)| TrackRow::new(&map, name, r, e, args.top))
            .collect(),
        seconds: TrackSeconds {
            total: seconds,
            per_scan: seconds / files.len() as f64,
        },
    };
    if args.json {
        return super::print_json(&report);
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
    for row in &report.scans {
        let g = |v: Option<f64>| v.unwrap_or(f64::NAN);
        println!(
            "{:>24} {:>5} {:>11.6} {:>11.6} {:>8.2} {:>6.3}",
            row.scan,
            row.segments,
            g(row.lat),
            g(row.lon),
            g(row.yaw).to_degrees(),
            row.confidence
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

impl Method {
    /// The library's ranking method (`None` for `all`).
    fn rank_method(self) -> Option<RankMethod> {
        match self {
            Method::All => None,
            Method::Dcm => Some(RankMethod::Dcm),
            Method::Forward => Some(RankMethod::Forward),
            Method::Reverse => Some(RankMethod::Reverse),
            Method::Symmetric => Some(RankMethod::Symmetric),
            Method::Hashing => Some(RankMethod::Hashing),
        }
    }
}

fn eval(args: EvalArgs) -> anyhow::Result<()> {
    let methods: Vec<RankMethod> = if args.method.contains(&Method::All) || args.method.is_empty() {
        RankMethod::ALL.to_vec()
    } else {
        args.method.iter().filter_map(|m| m.rank_method()).collect()
    };
    let mcd = is_mcd(&args.dataset);
    if mcd && args.map.is_none() {
        super::usage!(
            "{} is an MCD sequence; give the map with --map (e.g. ../shared/data/osm/kth_campus_stockholm.osm)",
            args.dataset.display()
        );
    }
    if args.track == Some(0) {
        super::usage!("--track 0: expected a window of at least 1 scan");
    }
    let job = EvalJob {
        dataset: args.dataset.clone(),
        map: args.map.clone(),
        methods,
        options: options(
            CostKind::Reverse,
            args.grid_m,
            args.yaw_step_deg,
            &args.extract,
        )?,
        distractors: args.distractors.clone().map(|path| {
            let options = DistractorOptions {
                ring_m: args.distractor_ring_m,
                seed: args.distractor_seed,
                ..DistractorOptions::default()
            };
            (path, options)
        }),
        limit: args.limit,
        track: args.track.map(|window| TrackSetup {
            window,
            odometry_drift: args.odometry_drift,
            odometry_yaw_drift_deg: args.odometry_yaw_drift_deg,
        }),
        figures: args.figures.clone(),
    };
    let json = args.json;
    let report = match run_eval(&job, &mut |scan| {
        if !json {
            println!("{}", scan.line_text());
        }
    }) {
        Err(e @ LocalizeError::DistractorsNeedOsmMap { .. }) => super::usage!("{e}"),
        r => r?,
    };
    if args.json {
        return super::print_json(&report);
    }
    print!("{}", report.table_text(mcd));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

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
