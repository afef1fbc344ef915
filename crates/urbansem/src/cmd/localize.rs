//! `urbansem localize …`: global localization of a scan on OSM building outlines (issue 6).
//!
//! - `urbansem localize --map MAP --scan SCAN [--cost dcm|forward|reverse|symmetric] [--top K] [--json] [--svg FILE] [--geojson FILE]`
//! - `urbansem localize eval --dataset DIR [--map MAP] [--method …] [--json] [--figures DIR]`
//!   (DIR: a simulated `localization` dataset, or an MCD sequence folder with `--map`).
//! - `urbansem localize extract-eval --dataset DIR [--stride N] [--json]` (DIR: a labelled
//!   KITTI-360 or MCD sequence): wall-extraction precision, recall, segments per scan.
//! - `urbansem localize track --map MAP --scans DIR --odometry FILE [--window K] [--history-m M] [--json] [--geojson FILE] [--poses-tum FILE] [--poses-kitti FILE]`:
//!   every scan of a folder with the windows of K scans before and after it (`--causal`:
//!   ending at it), tied by odometry.
//!
//! Every form takes `--sensor auto|terrestrial|hdl64|vlp16|os1-64|os1-128` and the extraction
//! knobs of [`ExtractArgs`] (issue 15).

use anyhow::Context;
use clap::{Args, Subcommand, ValueEnum};
use localize::distractors::DistractorOptions;
use localize::eval::real_sequence;
use localize::eval::report::{RankMethod, TrackSetup};
use localize::eval::run::{run_eval, EvalJob};
use localize::index::is_index;
use localize::jobs::{
    build_index, extract_eval_of, track_bag, track_folder, BagTrackJob, ScanInput, TrackJob,
};
use localize::pipeline::LocalizeOptions;
use localize::rank::CostKind;
use localize::sensor::{ExtractOverrides, SensorChoice, SensorKind, Vehicle};
use localize::LocalizeError;
use std::path::PathBuf;

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
    /// Wall-segment extraction quality on labelled scans (KITTI-360, MCD, simulated): precision,
    /// recall, segments per scan.
    ExtractEval(ExtractEvalArgs),
    /// Localize every scan of a track: scans tied by odometry, ranked by chains through the
    /// scans before and after each.
    Track(TrackArgs),
    /// Prepare a map once and save it as an index (`.uloc`) that every `localize` command
    /// accepts as `--map`.
    Index(IndexArgs),
    /// Draw a building map (OSM XML) from the building-labelled points of a real labelled
    /// sequence (KITTI-360, MCD), beside the streets of an OSM map: a map to localize that
    /// sequence's held-out scans on where the place's OSM buildings are not at hand.
    FacadeMap(FacadeMapArgs),
}

/// Arguments of `urbansem localize facade-map`.
#[derive(Args)]
pub struct FacadeMapArgs {
    /// A real labelled sequence folder (KITTI-360 or MCD layout).
    #[arg(long)]
    pub dataset: PathBuf,
    /// The OSM map (.osm or .osm.pbf) whose streets (highway ways) the map keeps, in its frame.
    #[arg(long)]
    pub roads: Option<PathBuf>,
    /// The OSM XML file to write.
    #[arg(long)]
    pub out: PathBuf,
    /// Leave every N-th scan (file-name order) out of the map, from --hold-out-offset.
    #[arg(long)]
    pub hold_out_every: Option<usize>,
    /// With --hold-out-every: the position of the first scan left out (0-based).
    #[arg(long, default_value_t = 0)]
    pub hold_out_offset: usize,
    /// Cell side of the building raster, metres.
    #[arg(long, default_value_t = 0.5)]
    pub cell_m: f64,
    /// Building points a cell needs.
    #[arg(long, default_value_t = 2)]
    pub min_points: u32,
    /// Use building points within this range of their scan's sensor, metres.
    #[arg(long, default_value_t = 50.0)]
    pub max_range_m: f64,
    /// Cells a building needs.
    #[arg(long, default_value_t = 8)]
    pub min_cells: usize,
    /// Douglas–Peucker tolerance of the outlines, metres.
    #[arg(long, default_value_t = 0.25)]
    pub simplify_m: f64,
    /// Depth given to the buildings behind the walls seen (away from the sensors that saw
    /// them), metres; 0: the walls as seen, one to a few cells thick.
    #[arg(long, default_value_t = 0.0)]
    pub depth_m: f64,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
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
    /// Cut the map into square tiles of this side, metres (a multiple of --grid-m): --out is
    /// then a folder that receives `manifest.json` and one index and map crop per tile, and
    /// `localize --map DIR/manifest.json` searches them as one map.
    #[arg(long)]
    pub tile_m: Option<f64>,
    /// With --tile-m: how far each tile reaches beyond its square, metres (tiled equals
    /// untiled for scans within this reach, and for a visibility range of 75 m plus 5 m).
    #[arg(long, default_value_t = 100.0, requires = "tile_m")]
    pub overlap_m: f64,
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
    #[arg(long, required_unless_present = "bag", conflicts_with = "bag")]
    pub scans: Option<PathBuf>,
    /// One line per scan, `x_m y_m yaw_rad` (optionally `scan x_m y_m yaw_rad`), in any
    /// local odometry frame; `#` starts a comment. The sensor's 3-D poses as LiDAR odometry
    /// writes them are read too: TUM lines `timestamp tx ty tz qx qy qz qw` or KITTI 3 × 4
    /// poses (12 numbers), in a frame whose z axis points up.
    #[arg(long, required_unless_present = "bag", conflicts_with = "bag")]
    pub odometry: Option<PathBuf>,
    /// A ROS 2 bag (.mcap) instead of --scans/--odometry: the scans of --topic, levelled and
    /// tied by the poses of --odometry-topic.
    #[arg(long, requires_all = ["topic", "odometry_topic"])]
    pub bag: Option<PathBuf>,
    /// The bag's PointCloud2 topic.
    #[arg(long, requires = "bag")]
    pub topic: Option<String>,
    /// The bag's Odometry, PoseStamped or TF topic (sensor pose in a gravity-aligned frame).
    #[arg(long, requires = "bag")]
    pub odometry_topic: Option<String>,
    /// With a TF topic: the child frame of the sensor's transform.
    #[arg(long, requires = "odometry_topic")]
    pub child_frame: Option<String>,
    /// With --bag: use every n-th scan.
    #[arg(long, default_value_t = 1)]
    pub every: usize,
    /// With --bag: leave out a scan more than this many seconds from both poses around it.
    #[arg(long, default_value_t = 0.5)]
    pub max_gap: f64,
    /// Scans per window (the scan and the K−1 before it).
    #[arg(long, default_value_t = 5)]
    pub window: usize,
    /// Odometry distance before the window, metres, through which a chain's consistency
    /// still counts (an older consistent chain beats a younger one; 0: the window only).
    #[arg(long, default_value_t = localize::track::TRACK_HISTORY_M)]
    pub history_m: f64,
    /// Rank each scan's candidates by the scans before it only, as a robot driving would
    /// (default: by the scans before and after it, a forward and a backward pass).
    #[arg(long)]
    pub causal: bool,
    /// Keep the smoothed chains' states as they are (default: each run of linked answers is
    /// moved to fit its walls and the odometry together, a pose graph that also estimates the
    /// odometry's scale error and heading bias).
    #[arg(long)]
    pub no_pose_graph: bool,
    /// Candidates printed per scan.
    #[arg(long, default_value_t = 5)]
    pub top: usize,
    /// Cost that ranks the candidates.
    #[arg(long, value_enum, default_value_t = CostArg::default_rank())]
    pub cost: CostArg,
    /// Print one JSON object.
    #[arg(long)]
    pub json: bool,
    /// Write the track as GeoJSON: a LineString of the best poses and one Point per scan
    /// (RFC 7946, WGS84, with the OSM attribution).
    #[arg(long)]
    pub geojson: Option<PathBuf>,
    /// Write the best pose of every localized scan as a TUM trajectory (`timestamp tx ty tz
    /// qx qy qz qw`; timestamp: the scan's 0-based index; map frame east, north, up; z = 0).
    #[arg(long)]
    pub poses_tum: Option<PathBuf>,
    /// Write the best pose of every localized scan as a KITTI trajectory (row-major 3×4
    /// `[R|t]` per line, localized scans in order; map frame east, north, up; z = 0).
    #[arg(long)]
    pub poses_kitti: Option<PathBuf>,
    /// Search grid, yaw step, extraction and acceptance.
    #[command(flatten)]
    pub search: SearchArgs,
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

/// What carries the sensor (`--vehicle`).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum VehicleArg {
    /// A car when the sensor profile is a car-mounted one.
    #[default]
    Auto,
    /// A car: poses head along a street.
    Car,
    /// Any heading.
    Free,
}

impl VehicleArg {
    /// The library's choice.
    pub fn vehicle(self) -> Vehicle {
        match self {
            VehicleArg::Auto => Vehicle::Auto,
            VehicleArg::Car => Vehicle::Car,
            VehicleArg::Free => Vehicle::Free,
        }
    }
}

/// How a scan is levelled before the extraction.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, ValueEnum)]
pub enum LevelArg {
    /// Estimate the up direction from the walls; level the scan when it leans 1–30°.
    Auto,
    /// Take the scan as gravity-levelled.
    #[default]
    Off,
}

impl LevelArg {
    /// The mode's name (`auto`, `off`), as `localize::level::options_named` takes it.
    pub fn name(self) -> &'static str {
        match self {
            LevelArg::Auto => "auto",
            LevelArg::Off => "off",
        }
    }

    /// The library's levelling options (`None`: off).
    pub fn options(self) -> Option<localize::level::LevelOptions> {
        // Both names are known to the library: no `Err` to lose.
        localize::level::options_named(self.name()).ok().flatten()
    }
}

/// When the answer is "no pose explains the scan well" (`"accepted": false` and a message;
/// the candidates and their confidence are still listed): the best candidate's symmetric
/// cost and its d_DCM both above their limits.
#[derive(Args, Clone)]
pub struct GateArgs {
    /// Largest symmetric cost of an accepted answer, metres (unless its d_DCM is below
    /// --max-accept-dcm-m); `inf` accepts every answer.
    #[arg(long, default_value_t = LocalizeOptions::default().max_accept_cost_m)]
    pub max_accept_cost_m: f64,
    /// Largest d_DCM of an accepted answer, metres (unless its symmetric cost is below
    /// --max-accept-cost-m); `inf` accepts every answer.
    #[arg(long, default_value_t = LocalizeOptions::default().max_accept_dcm_m)]
    pub max_accept_dcm_m: f64,
    /// Most poses kept from the search, the cheapest (0: every pose within the keep factor
    /// of the minimum).
    #[arg(long, default_value_t = LocalizeOptions::default().search.max_raw_poses)]
    pub max_raw_poses: usize,
    /// Box budget of the search: once the minimum is known, stop after bounding this many
    /// boxes and keep the cheapest poses found (0: search until the poses are proved the
    /// cheapest; `"truncated"` in the JSON search statistics says when the budget stopped it).
    #[arg(long, default_value_t = LocalizeOptions::default().search.max_boxes)]
    pub max_boxes: u64,
}

impl Default for GateArgs {
    fn default() -> Self {
        let o = LocalizeOptions::default();
        GateArgs {
            max_accept_cost_m: o.max_accept_cost_m,
            max_accept_dcm_m: o.max_accept_dcm_m,
            max_raw_poses: o.search.max_raw_poses,
            max_boxes: o.search.max_boxes,
        }
    }
}

/// The sensor profile and every knob of the wall extraction (unset: the profile's value).
#[derive(Args, Clone, Default)]
pub struct ExtractArgs {
    /// Sensor profile; `auto` estimates mount height, beams and field of view from each scan.
    #[arg(long, value_enum, default_value = "auto")]
    pub sensor: SensorArg,
    /// Levelling of a tilted scan: `auto` estimates the up direction from the scan's walls
    /// and levels it when it leans 1–30° (`localize::level`); `off` takes it as levelled.
    #[arg(long, value_enum, default_value = "off")]
    pub level: LevelArg,
    /// What carries the sensor: `car` keeps only poses heading along a street near them,
    /// `free` any heading, `auto` a car when the scan's sensor profile (given or detected)
    /// is a car-mounted one (every profile but `terrestrial`).
    #[arg(long, value_enum, default_value = "auto")]
    pub vehicle: VehicleArg,
    /// Largest angle between a car's heading and a street near it (either way), degrees
    /// (default 20).
    #[arg(long)]
    pub along_street_deg: Option<f64>,
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
    /// A labelled sequence folder: real (KITTI-360 or MCD layout) or a simulated
    /// `localization` dataset (`sim dataset --kind localization`).
    #[arg(long)]
    pub dataset: PathBuf,
    /// Use every N-th scan.
    #[arg(long, default_value_t = 1)]
    pub stride: usize,
    /// Score the scans in the sensor's own frame, as recorded (not levelled by the dataset
    /// poses), as a user's raw frames arrive; with `--level auto` the walls level them.
    #[arg(long)]
    pub as_recorded: bool,
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
    /// The library's cost kind.
    pub fn kind(self) -> CostKind {
        match self {
            CostArg::Dcm => CostKind::Dcm,
            CostArg::Forward => CostKind::Forward,
            CostArg::Reverse => CostKind::Reverse,
            CostArg::Symmetric => CostKind::Symmetric,
        }
    }

    /// The library's default ranking ([`LocalizeOptions::default`]), as the CLI's default.
    pub fn default_rank() -> CostArg {
        match LocalizeOptions::default().rank_by {
            CostKind::Dcm => CostArg::Dcm,
            CostKind::Forward => CostArg::Forward,
            CostKind::Reverse => CostArg::Reverse,
            CostKind::Symmetric => CostArg::Symmetric,
        }
    }
}

/// Arguments of one localization.
#[derive(Args)]
pub struct RunArgs {
    /// OSM map (.osm or .osm.pbf), its index (.uloc, from `localize index`), or a tiled
    /// map's manifest (.json, from `localize index --tile-m`).
    #[arg(long)]
    pub map: Option<PathBuf>,
    /// On a tiled map: search only the tiles within --radius-m of this coarse prior,
    /// `LAT,LON` in degrees.
    #[arg(long, value_name = "LAT,LON", requires = "radius_m")]
    pub near: Option<String>,
    /// With --near: the radius, metres.
    #[arg(long, requires = "near")]
    pub radius_m: Option<f64>,
    /// Gravity-levelled scan in the sensor frame (PLY, PCD, LAS/LAZ, KITTI .bin, or a
    /// message of a ROS 2 bag, .mcap).
    #[arg(long)]
    pub scan: Option<PathBuf>,
    /// The bag message to read when --scan is a .mcap file.
    #[command(flatten)]
    pub bag: super::BagPickArgs,
    /// Cost that ranks the candidates.
    #[arg(long, value_enum, default_value_t = CostArg::default_rank())]
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
    /// Write the listed candidates as GeoJSON Points with rank, headings and costs
    /// (RFC 7946, WGS84, with the OSM attribution).
    #[arg(long)]
    pub geojson: Option<PathBuf>,
    /// Search grid, yaw step, extraction and acceptance.
    #[command(flatten)]
    pub search: SearchArgs,
}

/// What every localizing command (`localize`, `localize track`, `localize eval`) searches
/// with: the grid and yaw step of the search, the extraction and the acceptance gate.
#[derive(Args, Clone)]
pub struct SearchArgs {
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
    /// When no pose explains the scan well.
    #[command(flatten)]
    pub gate: GateArgs,
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
    /// A `localization` dataset folder, or a real sequence folder (MCD, KITTI-360, KITTI
    /// raw; needs --map): its scans with their dataset poses as truth.
    #[arg(long)]
    pub dataset: PathBuf,
    /// OSM map, its index (.uloc), or a tiled map's manifest (.json, from `localize index
    /// --tile-m`: every scan searched together, tile by tile); default: the dataset's `map`.
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
    /// Evaluate only every N-th scan (file-name order), from --scan-offset: e.g. the scans a
    /// `localize facade-map --hold-out-every N --hold-out-offset K` left out of its map.
    #[arg(long)]
    pub scan_every: Option<usize>,
    /// With --scan-every: the position of the first scan evaluated (0-based).
    #[arg(long, default_value_t = 0)]
    pub scan_offset: usize,
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
    /// Track mode: localize each scan with the windows of K scans around it, tied by
    /// odometry made from the true poses with drift (scans in file-name order).
    #[arg(long)]
    pub track: Option<usize>,
    /// Track mode: odometry distance before the window, metres, through which a chain's
    /// consistency still counts (0: the window only).
    #[arg(long, default_value_t = localize::track::TRACK_HISTORY_M)]
    pub history_m: f64,
    /// Track mode: rank each scan's candidates by the scans before it only, as a robot
    /// driving would (default: by the scans before and after it).
    #[arg(long)]
    pub causal: bool,
    /// Track mode: keep the smoothed chains' states as they are (default: refined together
    /// with the odometry, a pose graph that also estimates the odometry's scale error and
    /// heading bias).
    #[arg(long)]
    pub no_pose_graph: bool,
    /// Track mode: odometry scale error (0.02: 2 % of the distance travelled).
    #[arg(long, default_value_t = localize::track::ODOMETRY_SCALE_DRIFT)]
    pub odometry_drift: f64,
    /// Track mode: odometry heading drift, degrees per 50 m travelled.
    #[arg(long, default_value_t = localize::track::ODOMETRY_YAW_DRIFT_DEG_PER_50M)]
    pub odometry_yaw_drift_deg: f64,
    /// Track mode: the same drift at every step (`systematic`, the worst case) or each step's
    /// scale error and heading bias drawn within those bounds (`random`, from `--odometry-seed`).
    #[arg(long, value_enum, default_value_t = DriftKind::Systematic)]
    pub odometry_drift_kind: DriftKind,
    /// Track mode: the seed of a random odometry drift.
    #[arg(long, default_value_t = 1)]
    pub odometry_seed: u64,
    /// Search grid, yaw step, extraction and acceptance.
    #[command(flatten)]
    pub search: SearchArgs,
}

/// How `localize eval --track` drifts the odometry it makes from the true poses.
#[derive(Debug, Clone, Copy, PartialEq, Eq, clap::ValueEnum)]
pub enum DriftKind {
    /// The same scale error and heading bias at every step.
    Systematic,
    /// Each step's drawn within the bounds.
    Random,
}

/// Runs `urbansem localize`.
pub fn run(args: LocalizeArgs) -> anyhow::Result<()> {
    match args.command {
        Some(LocalizeCommand::Eval(e)) => eval(e),
        Some(LocalizeCommand::ExtractEval(e)) => extract_eval(e),
        Some(LocalizeCommand::Track(t)) => track(t),
        Some(LocalizeCommand::Index(i)) => index(i),
        Some(LocalizeCommand::FacadeMap(f)) => facade_map(f),
        None => run_one(args.run),
    }
}

fn options(cost: CostKind, search: &SearchArgs) -> anyhow::Result<LocalizeOptions> {
    let &SearchArgs {
        grid_m,
        yaw_step_deg,
        ref extract,
        ref gate,
    } = search;
    if !(yaw_step_deg > 0.0 && yaw_step_deg <= 90.0) {
        super::usage!("--yaw-step-deg {yaw_step_deg}: expected a step in (0, 90] degrees");
    }
    for (name, v) in [
        ("--max-accept-cost-m", gate.max_accept_cost_m),
        ("--max-accept-dcm-m", gate.max_accept_dcm_m),
    ] {
        if v.is_nan() || v < 0.0 {
            super::usage!("{name} {v}: expected a length of 0 or more metres (inf: never refuse)");
        }
    }
    if let Some(d) = extract.along_street_deg {
        if !(0.0..=90.0).contains(&d) {
            super::usage!("--along-street-deg {d}: expected an angle in [0, 90] degrees");
        }
    }
    let mut o = LocalizeOptions {
        rank_by: cost,
        sensor: extract.sensor.choice(),
        vehicle: extract.vehicle.vehicle(),
        overrides: extract.overrides()?,
        level: extract.level.options(),
        max_accept_cost_m: gate.max_accept_cost_m,
        max_accept_dcm_m: gate.max_accept_dcm_m,
        ..LocalizeOptions::default()
    };
    o.chamfer.grid_m = grid_m;
    o.search.yaw_step_deg = yaw_step_deg;
    o.search.max_raw_poses = gate.max_raw_poses;
    o.search.max_boxes = gate.max_boxes;
    if let Some(d) = extract.along_street_deg {
        o.search.along_street_deg = d;
    }
    Ok(o)
}

fn index(args: IndexArgs) -> anyhow::Result<()> {
    if is_index(&args.map) {
        super::usage!(
            "--map {}: expected an OSM map, not an index",
            args.map.display()
        );
    }
    if let Some(tile_m) = args.tile_m {
        let mut o = LocalizeOptions::default();
        o.chamfer.grid_m = args.grid_m;
        let report = localize::tiles::build_tiles(
            &args.map,
            &args.out,
            localize::tiles::TileOptions {
                tile_m,
                overlap_m: args.overlap_m,
            },
            &o,
        )?;
        if args.json {
            return super::print_json(&report);
        }
        print!("{}", report.text());
        return Ok(());
    }
    if !is_index(&args.out) {
        super::usage!(
            "--out {}: the index file name must end in .uloc",
            args.out.display()
        );
    }
    let report = build_index(&args.map, &args.out, args.grid_m)?;
    if args.json {
        return super::print_json(&report);
    }
    print!("{}", report.text());
    Ok(())
}

fn run_one(args: RunArgs) -> anyhow::Result<()> {
    let (Some(map_path), Some(scan_path)) = (&args.map, &args.scan) else {
        super::usage!(
            "urbansem localize needs --map MAP and --scan SCAN (or the `eval` subcommand)"
        );
    };
    let options = options(args.cost.kind(), &args.search)?;
    let tiled = localize::tiles::is_manifest(map_path);
    if tiled && args.svg.is_some() {
        super::usage!("--svg draws on one map, not on a tiled map's manifest: use --geojson");
    }
    let near = match (&args.near, args.radius_m) {
        (Some(text), Some(radius_m)) => {
            if !tiled {
                super::usage!("--near needs a tiled map (--map DIR/manifest.json)");
            }
            let parts: Vec<Option<f64>> = text.split(',').map(|v| v.trim().parse().ok()).collect();
            match parts.as_slice() {
                [Some(lat), Some(lon)] if radius_m.is_finite() && radius_m >= 0.0 => {
                    Some(localize::jobs::Near {
                        lat: *lat,
                        lon: *lon,
                        radius_m,
                    })
                }
                _ => super::usage!(
                    "--near {text} --radius-m {radius_m}: expected LAT,LON in degrees and a radius ≥ 0"
                ),
            }
        }
        _ => None,
    };
    let is_bag =
        geodata::cloud::Format::from_path(scan_path).ok() == Some(geodata::cloud::Format::Mcap);
    let done = if is_bag || args.bag.given() {
        let (cloud, name, seconds) = args.bag.read(scan_path)?;
        localize::jobs::localize_scan_near(
            map_path,
            ScanInput::Cloud(&cloud, &name, seconds),
            options,
            args.top,
            args.svg.as_deref(),
            near,
        )?
    } else {
        localize::jobs::localize_scan_near(
            map_path,
            ScanInput::File(scan_path),
            options,
            args.top,
            args.svg.as_deref(),
            near,
        )?
    };
    if let Some(path) = &args.geojson {
        write_geojson(
            path,
            &localize::geojson::candidates_collection(&done.report),
        )?;
    }
    if args.json {
        return super::print_json(&done.report);
    }
    print!("{}", done.text());
    Ok(())
}

/// Writes a GeoJSON FeatureCollection after checking it against RFC 7946's rules.
fn write_geojson(path: &std::path::Path, fc: &serde_json::Value) -> anyhow::Result<()> {
    geodata::geojson::validate(fc).map_err(|e| anyhow::anyhow!("internal: {e}"))?;
    geodata::fsio::write_atomic(path, serde_json::to_vec_pretty(fc)?)
        .with_context(|| format!("writing {}", path.display()))
}

fn track(args: TrackArgs) -> anyhow::Result<()> {
    if args.window == 0 {
        super::usage!("--window 0: expected at least 1 scan per window");
    }
    if args.history_m.is_nan() || args.history_m < 0.0 {
        super::usage!("--history-m {}: expected 0 or more metres", args.history_m);
    }
    let writes_poses =
        args.geojson.is_some() || args.poses_tum.is_some() || args.poses_kitti.is_some();
    if args.top == 0 && writes_poses {
        super::usage!("--top 0: --geojson, --poses-tum and --poses-kitti need --top 1 or more");
    }
    if localize::tiles::is_manifest(&args.map) {
        super::usage!(
            "localize track searches one map or .uloc index, not a tiled map's manifest: localize each scan with `localize --map {} --near LAT,LON --radius-m R`, or a folder of scans with `shard plan --job localize`",
            args.map.display()
        );
    }
    let options = options(args.cost.kind(), &args.search)?;
    let report = match (&args.bag, &args.scans, &args.odometry) {
        (Some(bag), _, _) => {
            let job = BagTrackJob {
                map: args.map.clone(),
                bag: bag.clone(),
                cloud_topic: args.topic.clone().unwrap_or_default(),
                odometry_topic: args.odometry_topic.clone().unwrap_or_default(),
                child_frame: args.child_frame.clone(),
                every: args.every,
                max_gap_s: args.max_gap,
                window: args.window,
                history_m: args.history_m,
                smooth: !args.causal,
                pose_graph: !args.no_pose_graph,
                options,
                top: args.top,
            };
            let (report, without_pose) = track_bag(&job)?;
            if without_pose > 0 {
                eprintln!(
                    "warning: {without_pose} scans of {} left out: no pose of {} within {} s",
                    job.cloud_topic, job.odometry_topic, job.max_gap_s
                );
            }
            report
        }
        (None, Some(scans), Some(odometry)) => track_folder(&TrackJob {
            map: args.map.clone(),
            scans: scans.clone(),
            odometry: odometry.clone(),
            window: args.window,
            history_m: args.history_m,
            smooth: !args.causal,
            pose_graph: !args.no_pose_graph,
            options,
            top: args.top,
        })?,
        _ => {
            super::usage!("give --scans and --odometry, or --bag with --topic and --odometry-topic")
        }
    };
    if let Some(path) = &args.geojson {
        write_geojson(path, &localize::geojson::track_collection(&report))?;
    }
    let poses = localize::poses::track_poses(&report);
    for (path, text) in [
        (
            &args.poses_tum,
            localize::poses::tum_lines as fn(_) -> String,
        ),
        (&args.poses_kitti, localize::poses::kitti_lines),
    ] {
        if let Some(path) = path {
            geodata::fsio::write_atomic(path, text(&poses))
                .with_context(|| format!("writing {}", path.display()))?;
        }
    }
    if writes_poses && poses.len() < report.scans.len() {
        eprintln!(
            "localize track: {} of {} scans not localized, left out of the pose files",
            report.scans.len() - poses.len(),
            report.scans.len()
        );
    }
    if args.json {
        return super::print_json(&report);
    }
    print!("{}", report.text());
    Ok(())
}

/// Checks a selection of every N-th scan from an offset (`(flag, value)` of each).
fn every_nth(
    (every_flag, every): (&str, Option<usize>),
    (offset_flag, offset): (&str, usize),
) -> anyhow::Result<()> {
    match every {
        Some(0) => super::usage!("{every_flag} 0: expected every N-th scan, N ≥ 1"),
        Some(n) if offset >= n => {
            super::usage!("{offset_flag} {offset}: expected an offset below {every_flag} {n}")
        }
        None if offset != 0 => super::usage!("{offset_flag} needs {every_flag}"),
        _ => Ok(()),
    }
}

fn facade_map(args: FacadeMapArgs) -> anyhow::Result<()> {
    every_nth(
        ("--hold-out-every", args.hold_out_every),
        ("--hold-out-offset", args.hold_out_offset),
    )?;
    if real_sequence(&args.dataset).is_none() {
        super::usage!(
            "{}: not a real labelled sequence (expected the KITTI-360 or MCD layout)",
            args.dataset.display()
        );
    }
    let options = localize::facade_map::FacadeMapOptions {
        cell_m: args.cell_m,
        min_points: args.min_points,
        max_range_m: args.max_range_m,
        min_cells: args.min_cells,
        simplify_m: args.simplify_m,
        depth_m: args.depth_m,
        hold_out: args
            .hold_out_every
            .map(|every| (every, args.hold_out_offset)),
    };
    let summary = match localize::facade_map::write_facade_map(
        &args.dataset,
        args.roads.as_deref(),
        &args.out,
        &options,
    ) {
        Err(e @ LocalizeError::InvalidOption { .. }) => super::usage!("{e}"),
        r => r?,
    };
    if args.json {
        return super::print_json(&summary);
    }
    println!(
        "{}: {} buildings ({} vertices, {} read back) from {} building points of {} scans ({} held out), {} street segments",
        args.out.display(),
        summary.buildings,
        summary.vertices,
        summary.buildings_read_back,
        summary.building_points,
        summary.frames_used.len(),
        summary.frames_held_out.len(),
        summary.street_segments
    );
    Ok(())
}

fn extract_eval(args: ExtractEvalArgs) -> anyhow::Result<()> {
    if args.stride == 0 {
        super::usage!("--stride 0: expected a stride of at least 1");
    }
    let overrides = args.extract.overrides()?;
    let (sensor, level) = (args.extract.sensor.kind(), args.extract.level.options());
    // A simulated `localization` dataset is a labelled sequence too.
    let is_sim = geosim::sequence::SimLocalization::is_sim(&args.dataset);
    if !is_sim && geodata::datasets::SequenceKind::of(&args.dataset).is_none() {
        anyhow::bail!(
            "{}: not a labelled sequence: expected a KITTI-360 sequence (velodyne_points/), an \
             MCD one (pose_inW.csv) or a simulated localization dataset (dataset.json)",
            args.dataset.display()
        );
    }
    let seq = geosim::sequence::open_sequence(&args.dataset)
        .with_context(|| format!("reading {}", args.dataset.display()))?;
    let report = extract_eval_of(
        seq.as_ref(),
        args.stride,
        sensor,
        &overrides,
        level.as_ref(),
        args.as_recorded,
    )?;
    if args.json {
        return super::print_json(&report);
    }
    print!("{}", report.text());
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
    let tiled = args
        .map
        .as_deref()
        .is_some_and(localize::tiles::is_manifest);
    let all = args.method.contains(&Method::All) || args.method.is_empty();
    let methods: Vec<RankMethod> = if all {
        RankMethod::ALL
            .into_iter()
            // The hashing baseline indexes one whole map: left out on a tiled map unless asked for.
            .filter(|m| !(tiled && *m == RankMethod::Hashing))
            .collect()
    } else {
        args.method.iter().filter_map(|m| m.rank_method()).collect()
    };
    let real = real_sequence(&args.dataset);
    if let (Some(kind), None) = (real, &args.map) {
        super::usage!(
            "{} is a real {} sequence; give the map of the place it was recorded with --map (an OSM file with buildings or its .uloc index, e.g. ../shared/data/osm/kth_campus_stockholm.osm for MCD kth_day_06)",
            args.dataset.display(),
            kind.name()
        );
    }
    if args.track == Some(0) {
        super::usage!("--track 0: expected a window of at least 1 scan");
    }
    if args.causal && args.track.is_none() {
        super::usage!("--causal ranks a track's scans: it needs --track K");
    }
    if args.no_pose_graph && args.track.is_none() {
        super::usage!("--no-pose-graph refines a track's answers: it needs --track K");
    }
    if args.odometry_drift_kind == DriftKind::Random && args.track.is_none() {
        super::usage!("--odometry-drift-kind random drifts a track's odometry: it needs --track K");
    }
    every_nth(
        ("--scan-every", args.scan_every),
        ("--scan-offset", args.scan_offset),
    )?;
    if args.history_m.is_nan() || args.history_m < 0.0 {
        super::usage!("--history-m {}: expected 0 or more metres", args.history_m);
    }
    let job = EvalJob {
        dataset: args.dataset.clone(),
        map: args.map.clone(),
        methods,
        // The default ranking, as `localize` and `localize track` rank (track mode follows it).
        options: options(LocalizeOptions::default().rank_by, &args.search)?,
        distractors: args.distractors.clone().map(|path| {
            let options = DistractorOptions {
                ring_m: args.distractor_ring_m,
                seed: args.distractor_seed,
                ..DistractorOptions::default()
            };
            (path, options)
        }),
        limit: args.limit,
        select: args.scan_every.map(|every| (every, args.scan_offset)),
        track: args.track.map(|window| TrackSetup {
            window,
            history_m: args.history_m,
            smooth: !args.causal,
            pose_graph: !args.no_pose_graph,
            odometry_drift: args.odometry_drift,
            odometry_yaw_drift_deg: args.odometry_yaw_drift_deg,
            odometry_random_seed: (args.odometry_drift_kind == DriftKind::Random)
                .then_some(args.odometry_seed),
        }),
        figures: args.figures.clone(),
    };
    if tiled {
        if let Some(why) = localize::eval::run::tiled_refusal(&job) {
            super::usage!("{why}: drop that option, or give the map itself (or its .uloc index)");
        }
    }
    let json = args.json;
    let mut progress = |step: localize::tiles::BatchStep<'_>| {
        if step.tiles_done % 10 == 0 || step.tiles_done == step.tiles {
            eprintln!(
                "{}: {} of {} tiles, {} scans",
                step.round, step.tiles_done, step.tiles, step.scans
            );
        }
    };
    let report = match run_eval(
        &job,
        &mut |scan| {
            if !json {
                println!("{}", scan.line_text());
            }
        },
        &mut progress,
    ) {
        Err(e @ LocalizeError::DistractorsNeedOsmMap { .. }) => super::usage!("{e}"),
        r => r?,
    };
    if args.json {
        return super::print_json(&report);
    }
    print!("{}", report.table_text(real.map(|k| k.name())));
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn localize_without_map_or_scan_is_a_clear_error() {
        let err = run_one(RunArgs {
            near: None,
            radius_m: None,
            map: None,
            scan: None,
            bag: Default::default(),
            cost: CostArg::Reverse,
            top: 10,
            json: false,
            svg: None,
            geojson: None,
            search: SearchArgs {
                grid_m: 0.5,
                yaw_step_deg: 0.5,
                extract: ExtractArgs::default(),
                gate: GateArgs::default(),
            },
        })
        .unwrap_err();
        assert!(err.to_string().contains("--map"), "{err}");
    }
}
