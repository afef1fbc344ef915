//! The command-line jobs as library calls, each returning the typed report the CLI prints
//! (and the Python package and shard runner return): build a map index, localize one scan
//! file, localize a folder of scans along a track, score wall extraction on a labelled
//! sequence. `eval::run` is the dataset evaluation.

use crate::extract_eval::{evaluate_layout, labelled_scans_of, open_labelled, ExtractEval};
use crate::figure::result_svg;
use crate::index::{load_map_or_index, PreparedMap};
use crate::pipeline::{LocalizeOptions, Localizer, ScanSegments};
use crate::report::{LocalizeReport, TrackReport, TrackRow, TrackSeconds};
use crate::sensor::{ExtractOverrides, SensorKind};
use crate::track::{read_odometry, TrackOptions};
use crate::{LocalizeError, Result, WithContext};
use geodata::datasets::LidarSequence;
use geodata::osm::OsmMap;
use rayon::prelude::*;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::time::Instant;

/// Seconds of `localize index`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct IndexSeconds {
    /// Reading the OSM map.
    pub load_map: f64,
    /// Preparing edges, tensor, pyramid and feasible mask.
    pub prepare: crate::index::MapSeconds,
    /// Writing the index.
    pub write: f64,
    /// Reading the index and its map back.
    pub load_index: f64,
}

/// What `localize index` wrote.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct IndexReport {
    /// The index file.
    pub index: PathBuf,
    /// The OSM map it indexes.
    pub map: PathBuf,
    /// Size of the index file.
    pub bytes: u64,
    /// Building outline edges.
    pub edges: usize,
    /// Distance-transform tensor width, height, orientation channels.
    pub tensor: [usize; 3],
    /// Tensor cell size, metres.
    pub grid_m: f64,
    /// Seconds per step.
    pub seconds: IndexSeconds,
}

/// Prepares the map of `map_path` at `grid_m` and writes its index to `out` (`.uloc`).
pub fn build_index(map_path: &Path, out: &Path, grid_m: f64) -> Result<IndexReport> {
    let t = Instant::now();
    let map = OsmMap::load(map_path)
        .context_with(|| format!("loading the map {}", map_path.display()))?;
    let load_s = t.elapsed().as_secs_f64();
    let mut o = LocalizeOptions::default();
    o.chamfer.grid_m = grid_m;
    let prepared = PreparedMap::build(&map, &o.chamfer, &o.search)
        .context_with(|| format!("preparing the map {}", map_path.display()))?;
    let t = Instant::now();
    prepared.write(out, map_path)?;
    let write_s = t.elapsed().as_secs_f64();
    let bytes = std::fs::metadata(out).map(|m| m.len()).unwrap_or(0);
    let t = Instant::now();
    let (_, source) = PreparedMap::read(out)?;
    source.load(out)?;
    let load_index_s = t.elapsed().as_secs_f64();
    let dt = &prepared.dt;
    Ok(IndexReport {
        index: out.to_path_buf(),
        map: map_path.to_path_buf(),
        bytes,
        edges: prepared.edges.len(),
        tensor: [dt.width, dt.height, dt.channels],
        grid_m: dt.grid_m,
        seconds: IndexSeconds {
            load_map: load_s,
            prepare: prepared.seconds,
            write: write_s,
            load_index: load_index_s,
        },
    })
}

impl IndexReport {
    /// The one-line summary the command line prints.
    pub fn text(&self) -> String {
        let s = &self.seconds.prepare;
        format!(
            "{}: {:.1} MB ({} edges, tensor {}×{}×{} at {} m); prepared in {:.2} s (tensor {:.2}, pyramid {:.2}, feasible {:.2}), written in {:.2} s; loading it back (index and map) takes {:.3} s\n",
            self.index.display(),
            self.bytes as f64 / 1e6,
            self.edges,
            self.tensor[0],
            self.tensor[1],
            self.tensor[2],
            self.grid_m,
            s.edges + s.distance_transform + s.pyramid + s.feasible,
            s.distance_transform,
            s.pyramid,
            s.feasible,
            self.seconds.write,
            self.seconds.load_index
        )
    }
}

/// One scan file localized on a map file ([`localize_file`]).
#[derive(Debug, Clone)]
pub struct FileLocalization {
    /// The report, its best candidates listed.
    pub report: LocalizeReport,
    /// Points in the scan file.
    pub points: usize,
}

/// Localizes the scan file `scan_path` on the map (or index) `map_path`, listing the `top`
/// best candidates; draws the result to `svg` when given.
pub fn localize_file(
    map_path: &Path,
    scan_path: &Path,
    options: LocalizeOptions,
    top: usize,
    svg: Option<&Path>,
) -> Result<FileLocalization> {
    localize_scan(map_path, ScanInput::File(scan_path), options, top, svg)
}

/// Where [`localize_scan`] takes the scan from.
#[derive(Debug, Clone, Copy)]
pub enum ScanInput<'a> {
    /// A cloud file, read here.
    File(&'a Path),
    /// A cloud already read (e.g. a message of a bag), with the name the report gives it and
    /// the seconds reading it took.
    Cloud(&'a geodata::cloud::PointCloud, &'a str, f64),
}

/// Localizes one scan (a file or a cloud in memory) on the map (or index) `map_path`, listing
/// the `top` best candidates; draws the result to `svg` when given.
pub fn localize_scan(
    map_path: &Path,
    scan: ScanInput<'_>,
    options: LocalizeOptions,
    top: usize,
    svg: Option<&Path>,
) -> Result<FileLocalization> {
    localize_scan_near(map_path, scan, options, top, svg, None)
}

/// A coarse prior: only the map tiles within `radius_m` of (`lat`, `lon`) are searched.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Near {
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Radius, metres.
    pub radius_m: f64,
}

fn read_scan<'c>(
    scan: ScanInput<'c>,
    read: &'c mut Option<geodata::cloud::PointCloud>,
) -> Result<(&'c geodata::cloud::PointCloud, String, f64)> {
    let t = Instant::now();
    Ok(match scan {
        ScanInput::File(path) => {
            let cloud = geodata::cloud::read_cloud(path)
                .context_with(|| format!("reading the scan {}", path.display()))?;
            let cloud = read.insert(cloud);
            (cloud, path.display().to_string(), t.elapsed().as_secs_f64())
        }
        ScanInput::Cloud(cloud, name, seconds) => (cloud, name.to_owned(), seconds),
    })
}

/// [`localize_scan`] on a map, an index or a tile manifest (`.json`, [`crate::tiles`]);
/// on a tiled map only the tiles `near` a coarse prior are searched when one is given.
pub fn localize_scan_near(
    map_path: &Path,
    scan: ScanInput<'_>,
    options: LocalizeOptions,
    top: usize,
    svg: Option<&Path>,
    near: Option<Near>,
) -> Result<FileLocalization> {
    if crate::tiles::is_manifest(map_path) {
        return localize_scan_tiled(map_path, scan, options, top, near);
    }
    let t = Instant::now();
    let (map, prepared) = load_map_or_index(map_path)?;
    let load_map_s = t.elapsed().as_secs_f64();
    let localizer = Localizer::prepared_or_new(&map, prepared, options, map_path)?;
    let mut read = None;
    let (cloud, name, read_scan_s) = read_scan(scan, &mut read)?;
    let result = localizer
        .localize_points(&cloud.positions)
        .context_with(|| format!("localizing {name}"))?;
    if let Some(svg_path) = svg {
        write_file(svg_path, result_svg(&localizer, &result, None, 100.0))?;
    }
    let report = LocalizeReport::new(
        &localizer,
        &map_path.display().to_string(),
        &name,
        &result,
        top,
        load_map_s,
        read_scan_s,
    );
    Ok(FileLocalization {
        report,
        points: cloud.len(),
    })
}

/// One scan on a tiled map ([`localize_scan_near`]).
fn localize_scan_tiled(
    manifest_path: &Path,
    scan: ScanInput<'_>,
    options: LocalizeOptions,
    top: usize,
    near: Option<Near>,
) -> Result<FileLocalization> {
    let t = Instant::now();
    let manifest = crate::tiles::Manifest::read(manifest_path)?;
    let only = match near {
        None => None,
        Some(n) => {
            let frame = manifest.frame(manifest_path)?;
            Some(manifest.tiles_near(frame.to_local(n.lat, n.lon), n.radius_m))
        }
    };
    let manifest_s = t.elapsed().as_secs_f64();
    let mut read = None;
    let (cloud, name, read_scan_s) = read_scan(scan, &mut read)?;
    let t0 = Instant::now();
    let extracted = crate::pipeline::scan_segments(&options, &cloud.positions)
        .context_with(|| format!("localizing {name}"))?;
    let tiled = crate::tiles::localize_tiled(manifest_path, &extracted, &options, only.as_deref())?;
    let mut result = tiled.result;
    result.record_scan(&extracted, cloud.len());
    result.seconds.total = t0.elapsed().as_secs_f64() - tiled.load_seconds;
    let mut report = LocalizeReport::of_map(
        &tiled.frame_map,
        &crate::index::MapSeconds::default(),
        (&manifest_path.display().to_string(), &name),
        &result,
        top,
        manifest_s + tiled.load_seconds,
        read_scan_s,
    );
    report.tiles = Some(crate::report::TilesUsed {
        searched: tiled.tiles_searched,
        exact: tiled.exact,
        max_tile_memory_bytes: tiled.max_tile_memory_bytes,
        load_seconds: tiled.load_seconds,
    });
    Ok(FileLocalization {
        report,
        points: cloud.len(),
    })
}

/// A folder of scans localized along a track ([`track_folder`]).
#[derive(Debug, Clone)]
pub struct TrackJob {
    /// The map (OSM file or `.uloc` index).
    pub map: PathBuf,
    /// The folder of gravity-levelled scans, taken in file-name order.
    pub scans: PathBuf,
    /// The odometry file (one relative pose per scan).
    pub odometry: PathBuf,
    /// Scans per window.
    pub window: usize,
    /// Odometry distance before the window through which chains still count, metres.
    pub history_m: f64,
    /// Whether the scans after each scan count too ([`TrackOptions::smooth`]).
    pub smooth: bool,
    /// Whether smoothed answers are refined together ([`TrackOptions::refine_poses`]).
    pub pose_graph: bool,
    /// The localizer's options.
    pub options: LocalizeOptions,
    /// Candidates listed per scan.
    pub top: usize,
}

/// Localizes every scan of a folder with the window of scans ending at it, tied by odometry.
pub fn track_folder(job: &TrackJob) -> Result<TrackReport> {
    let (map, prepared) = load_map_or_index(&job.map)?;
    let localizer = Localizer::prepared_or_new(&map, prepared, job.options.clone(), &job.map)?;
    let mut files: Vec<PathBuf> = std::fs::read_dir(&job.scans)
        .map_err(|source| LocalizeError::Io {
            action: "listing",
            path: job.scans.clone(),
            source,
        })?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| geodata::cloud::Format::from_path(p).is_ok())
        .collect();
    files.sort();
    if files.is_empty() {
        return Err(LocalizeError::Dataset {
            path: job.scans.clone(),
            message: "no scan files (PLY, PCD, LAS/LAZ, KITTI .bin)".into(),
        });
    }
    let names: Vec<String> = files
        .iter()
        .map(|p| {
            p.file_name()
                .map_or(String::new(), |n| n.to_string_lossy().into_owned())
        })
        .collect();
    let odometry = read_odometry(&job.odometry, &names)?;
    let t = Instant::now();
    let mut extracted = Vec::with_capacity(files.len());
    for f in &files {
        let cloud = geodata::cloud::read_cloud(f)
            .context_with(|| format!("reading the scan {}", f.display()))?;
        extracted.push(
            localizer
                .scan_segments(&cloud.positions)
                .context_with(|| format!("extracting walls from {}", f.display()))?,
        );
    }
    let track = TrackOptions {
        window: job.window,
        history_m: job.history_m,
        smooth: job.smooth,
        refine_poses: job.pose_graph,
        ..Default::default()
    };
    let scans = track_rows(&localizer, &names, &extracted, &odometry, &track, job.top)?;
    let seconds = t.elapsed().as_secs_f64();
    Ok(TrackReport {
        map: job.map.display().to_string(),
        scans_dir: job.scans.display().to_string(),
        odometry: job.odometry.display().to_string(),
        window: job.window,
        history_m: job.history_m,
        smoothed: job.smooth,
        pose_graph: job.smooth && job.pose_graph,
        cost: job.options.rank_by.name(),
        scans,
        seconds: TrackSeconds {
            total: seconds,
            per_scan: seconds / files.len() as f64,
        },
    })
}

/// `urbansem localize track --bag`: the scans of a ROS 2 bag's point cloud topic, levelled
/// and tied by the poses of its odometry topic.
#[derive(Debug, Clone)]
pub struct BagTrackJob {
    /// The map (OSM file or `.uloc` index).
    pub map: PathBuf,
    /// The bag (.mcap).
    pub bag: PathBuf,
    /// Its `sensor_msgs/msg/PointCloud2` topic (scans in the sensor frame).
    pub cloud_topic: String,
    /// Its Odometry, PoseStamped or TF topic: the sensor's pose in a gravity-aligned
    /// odometry frame (roll and pitch level the scans; x, y, yaw tie them).
    pub odometry_topic: String,
    /// For a TF topic: the child frame of the sensor's transform.
    pub child_frame: Option<String>,
    /// Use every n-th scan (1: all).
    pub every: usize,
    /// A scan more than this many seconds from both poses around it is left out.
    pub max_gap_s: f64,
    /// Scans per window.
    pub window: usize,
    /// Odometry distance before the window through which chains still count, metres.
    pub history_m: f64,
    /// Whether the scans after each scan count too ([`TrackOptions::smooth`]).
    pub smooth: bool,
    /// Whether smoothed answers are refined together ([`TrackOptions::refine_poses`]).
    pub pose_graph: bool,
    /// The localizer's options.
    pub options: LocalizeOptions,
    /// Candidates listed per scan.
    pub top: usize,
}

/// Localizes the scans of a bag as [`track_folder`] does a folder's: each scan is levelled by
/// its pose's roll and pitch (interpolated at its stamp, or its log time when unstamped),
/// and the poses' x, y and yaw are the odometry. Rows are named `TOPIC#INDEX`. Also returns
/// how many scans were left out for want of a pose.
pub fn track_bag(job: &BagTrackJob) -> Result<(TrackReport, usize)> {
    use geodata::cloud::mcap::{for_each_bag_cloud, Next, PoseTrack};
    if job.every == 0 || job.max_gap_s.is_nan() || job.max_gap_s < 0.0 {
        return Err(LocalizeError::Dataset {
            path: job.bag.clone(),
            message: format!(
                "every = {} and max gap = {} s: expected every ≥ 1 and a gap ≥ 0",
                job.every, job.max_gap_s
            ),
        });
    }
    let (map, prepared) = load_map_or_index(&job.map)?;
    let localizer = Localizer::prepared_or_new(&map, prepared, job.options.clone(), &job.map)?;
    let t = Instant::now();
    let track = PoseTrack::read(
        &job.bag,
        &job.odometry_topic,
        job.child_frame.as_deref(),
        job.max_gap_s,
    )?;
    let mut names = Vec::new();
    let mut odometry = Vec::new();
    let mut extracted = Vec::new();
    let mut failure = None;
    let mut without_pose = 0;
    for_each_bag_cloud(
        &job.bag,
        &job.cloud_topic,
        &geodata::cloud::ReadOptions::default(),
        |scan| {
            if scan.index % job.every != 0 {
                return Next::Continue;
            }
            let Some(pose) = track.at(&scan) else {
                without_pose += 1;
                return Next::Continue;
            };
            let yaw = pose.yaw();
            let level = crate::levelling_rotation(&pose.matrix(), yaw);
            let points: Vec<[f64; 3]> = scan
                .cloud
                .positions
                .iter()
                .map(|p| {
                    std::array::from_fn(|i| {
                        level[i][0] * p[0] + level[i][1] * p[1] + level[i][2] * p[2]
                    })
                })
                .collect();
            let name = format!("{}#{}", job.cloud_topic, scan.index);
            match localizer
                .scan_segments(&points)
                .context_with(|| format!("extracting walls from {name}"))
            {
                Ok(segments) => extracted.push(segments),
                Err(e) => {
                    failure = Some(e);
                    return Next::Stop;
                }
            }
            names.push(name);
            odometry.push(crate::Pose2 {
                x: pose.translation[0],
                y: pose.translation[1],
                yaw_rad: yaw,
            });
            Next::Continue
        },
    )?;
    if let Some(e) = failure {
        return Err(e);
    }
    if names.is_empty() {
        return Err(LocalizeError::Dataset {
            path: job.bag.clone(),
            message: format!(
                "no scan of {} has a pose of {} within {} s",
                job.cloud_topic, job.odometry_topic, job.max_gap_s
            ),
        });
    }
    let track = TrackOptions {
        window: job.window,
        history_m: job.history_m,
        smooth: job.smooth,
        refine_poses: job.pose_graph,
        ..Default::default()
    };
    let scans = track_rows(&localizer, &names, &extracted, &odometry, &track, job.top)?;
    let seconds = t.elapsed().as_secs_f64();
    let report = TrackReport {
        map: job.map.display().to_string(),
        scans_dir: format!("{} {}", job.bag.display(), job.cloud_topic),
        odometry: format!("{} {}", job.bag.display(), job.odometry_topic),
        window: job.window,
        history_m: job.history_m,
        smoothed: job.smooth,
        pose_graph: job.smooth && job.pose_graph,
        cost: job.options.rank_by.name(),
        seconds: TrackSeconds {
            total: seconds,
            per_scan: seconds / names.len() as f64,
        },
        scans,
    };
    Ok((report, without_pose))
}

/// The rows of a track ([`track_folder`] and the Python package): the scans' extracted walls
/// (`extracted`, named `names`) localized with the window of scans ending at each (`track`),
/// tied by `odometry` (one pose per scan in any odometry frame); `top` candidates per row.
pub fn track_rows(
    localizer: &Localizer<'_>,
    names: &[String],
    extracted: &[ScanSegments],
    odometry: &[crate::Pose2],
    track: &TrackOptions,
    top: usize,
) -> Result<Vec<TrackRow>> {
    let results = localizer.localize_track(extracted, odometry, track)?;
    Ok(names
        .iter()
        .zip(&results)
        .zip(extracted)
        .map(|((name, r), e)| TrackRow::new(localizer.map, name, r, e, top))
        .collect())
}

/// Seconds of `localize extract-eval`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ExtractEvalSeconds {
    /// Reading the scans.
    pub read: f64,
    /// Extracting walls and scoring them.
    pub extract_and_score: f64,
}

/// Wall-extraction quality on a labelled sequence, as `localize extract-eval` prints it.
#[derive(Debug, Clone, Serialize)]
pub struct ExtractEvalReport {
    /// The scores.
    #[serde(flatten)]
    pub eval: ExtractEval,
    /// The sequence folder.
    pub dataset: String,
    /// The sensor profile asked for (`auto`: detected per scan).
    pub sensor: &'static str,
    /// Seconds per step.
    pub seconds: ExtractEvalSeconds,
}

/// Scores wall extraction on every `stride`-th scan of a labelled KITTI-360 or MCD sequence
/// (levelled by its pose unless `as_recorded`), each levelled by its walls first when `level`
/// is given.
pub fn extract_eval_sequence(
    dataset: &Path,
    stride: usize,
    sensor: Option<SensorKind>,
    overrides: &ExtractOverrides,
    level: Option<&crate::level::LevelOptions>,
    as_recorded: bool,
) -> Result<ExtractEvalReport> {
    let (_, seq) =
        open_labelled(dataset).context_with(|| format!("reading {}", dataset.display()))?;
    extract_eval_of(seq.as_ref(), stride, sensor, overrides, level, as_recorded)
}

/// [`extract_eval_sequence`] on an opened labelled sequence of any layout (a simulated
/// `localization` dataset included: `geosim::sequence::open_sequence`).
pub fn extract_eval_of(
    seq: &dyn LidarSequence,
    stride: usize,
    sensor: Option<SensorKind>,
    overrides: &ExtractOverrides,
    level: Option<&crate::level::LevelOptions>,
    as_recorded: bool,
) -> Result<ExtractEvalReport> {
    let t = Instant::now();
    let dataset = seq.dir();
    let mut scans = labelled_scans_of(seq, stride, as_recorded)
        .context_with(|| format!("reading {}", dataset.display()))?;
    if let Some(lo) = level {
        // Each point keeps its class: only the frame turns.
        scans.par_iter_mut().for_each(|s| {
            crate::level::level(&mut s.points, lo);
        });
    }
    if scans.is_empty() {
        return Err(LocalizeError::Dataset {
            path: dataset.to_path_buf(),
            message: "no scans".into(),
        });
    }
    let read_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let eval = evaluate_layout(seq.name(), &scans, sensor, &|s, seg| {
        overrides.apply(s, seg)
    })?;
    Ok(ExtractEvalReport {
        eval,
        dataset: dataset.display().to_string(),
        sensor: sensor.map_or("auto", SensorKind::name),
        seconds: ExtractEvalSeconds {
            read: read_s,
            extract_and_score: t.elapsed().as_secs_f64(),
        },
    })
}

/// Writes a figure atomically.
pub(crate) fn write_file(path: &Path, text: String) -> Result<()> {
    geodata::fsio::write_atomic(path, text).map_err(|source| LocalizeError::Io {
        action: "writing",
        path: path.to_path_buf(),
        source,
    })
}

impl FileLocalization {
    /// The result as the command line prints it: counts, sensor, candidates, seconds.
    pub fn text(&self) -> String {
        let r = &self.report;
        let (s, stages) = (&r.seconds, &r.seconds.scan);
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{}: {} points, {} vertical cells, {} segments; {} raw poses → {} after suppression → {} candidates (ranked by {})",
            r.scan,
            self.points,
            r.vertical_cells,
            r.segments,
            r.raw_poses,
            r.after_suppression,
            r.candidate_count,
            r.cost
        );
        if let Some(sensor) = &r.sensor {
            let _ = writeln!(
                out,
                "sensor {} ({}): mount {:.2} m, vertical field of view {:.1}° … {:.1}°, {} beams; wall clearance {:.2} m",
                sensor.profile,
                if sensor.detected { "detected" } else { "named" },
                sensor.geometry.mount_height_m,
                sensor.geometry.vfov_deg[0],
                sensor.geometry.vfov_deg[1],
                sensor.geometry.beams,
                r.clearance_m
            );
        }
        if let Some(m) = &r.message {
            let _ = writeln!(out, "note: {m}");
        }
        let _ = writeln!(
            out,
            "{:>4} {:>10} {:>10} {:>11} {:>11} {:>8} {:>7} {:>7} {:>7} {:>7}",
            "rank", "x", "y", "lat", "lon", "yaw°", "dcm", "fwd", "rev", "sym"
        );
        for c in &r.candidates {
            let _ = writeln!(
                out,
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
        if r.candidate_count > 1 && r.confidence < crate::rank::AMBIGUOUS_CONFIDENCE {
            let _ = writeln!(
                out,
                "confidence {:.3}: ambiguous, another place fits the scan within {:.1} % of the best cost; consecutive scans tied by odometry (`urbansem localize track`) can tell such places apart",
                r.confidence,
                100.0 * r.confidence
            );
        } else {
            let _ = writeln!(out, "confidence {:.3}", r.confidence);
        }
        let _ = writeln!(
            out,
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
        out
    }
}

impl TrackReport {
    /// The track as the command line prints it: one row per scan.
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{}: {} scans, window {}, {:.2} s per scan",
            self.scans_dir,
            self.scans.len(),
            self.window,
            self.seconds.per_scan
        );
        let _ = writeln!(
            out,
            "{:>24} {:>5} {:>11} {:>11} {:>8} {:>6}",
            "scan", "segs", "lat", "lon", "yaw°", "conf"
        );
        for row in &self.scans {
            let g = |v: Option<f64>| v.unwrap_or(f64::NAN);
            let _ = writeln!(
                out,
                "{:>24} {:>5} {:>11.6} {:>11.6} {:>8.2} {:>6.3}",
                row.scan,
                row.segments,
                g(row.lat),
                g(row.lon),
                g(row.yaw).to_degrees(),
                row.confidence
            );
        }
        // Each run the pose graph refined, once, with the odometry drift it estimated.
        let mut last = None;
        for run in self.scans.iter().filter_map(|r| r.odometry_run) {
            if last == Some(run.first_scan) {
                continue;
            }
            last = Some(run.first_scan);
            let first = self.scans.get(run.first_scan).map_or("?", |r| &r.scan);
            let _ = write!(
                out,
                "run of {} scans from {first} ({:.0} m of odometry)",
                run.scans, run.length_m
            );
            match run.drift {
                Some(d) => {
                    let _ = writeln!(
                        out,
                        ": odometry scale error {:+.2} ± {:.2} %, heading bias {:+.2} ± {:.2}° per 100 m",
                        100.0 * d.scale_error,
                        100.0 * d.scale_error_sd,
                        d.heading_bias_deg_per_100m,
                        d.heading_bias_sd_deg_per_100m
                    );
                }
                None => {
                    let _ = writeln!(out);
                }
            }
        }
        out
    }
}

impl ExtractEvalReport {
    /// The scores as the command line prints them: totals, sensors, one row per scan.
    pub fn text(&self) -> String {
        let r = &self.eval;
        let mut out = String::new();
        let _ = writeln!(
            out,
            "{} ({}, {} scans): precision {:.3} ({:.3} counting the {:.0} % amid unlabelled points as wrong), recall {:.3}, {:.1} segments per scan",
            self.dataset,
            r.kind,
            r.scans,
            r.precision,
            r.precision_all,
            100.0 * r.unjudged,
            r.recall,
            r.segments_per_scan
        );
        let profiles: Vec<String> = r
            .profiles
            .iter()
            .map(|(p, n)| format!("{p} ×{n}"))
            .collect();
        let _ = writeln!(out, "sensor: {}", profiles.join(", "));
        let off: Vec<String> = r
            .off_building_m
            .iter()
            .map(|(c, m)| format!("{c} {m:.0} m"))
            .collect();
        let _ = writeln!(
            out,
            "segment length off buildings, by the class around it: {}",
            off.join(", ")
        );
        let _ = writeln!(
            out,
            "{:>12} {:>9} {:>7} {:>6} {:>7} {:>5} {:>9} {:>9} {:>6} {:>6}",
            "scan",
            "profile",
            "mount",
            "top°",
            "clear",
            "segs",
            "seg m",
            "on bldg",
            "facade",
            "cover"
        );
        for s in &r.per_scan {
            let _ = writeln!(
                out,
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
        let _ = writeln!(
            out,
            "seconds: read {:.2}, extract and score {:.2}",
            self.seconds.read, self.seconds.extract_and_score
        );
        out
    }
}
