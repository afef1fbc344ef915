//! Answers as the command line, the Python package and the fleet jobs return them: candidates
//! in WGS84 ([`GeoCandidate`]), one scan's [`LocalizeReport`] and a track's [`TrackReport`].

use crate::candidates::{FilterCounts, SearchStats};
use crate::pipeline::{Candidate, Localization, Localizer, ScanSegments, StageSeconds};
use crate::sensor::SensorReport;
use geodata::osm::OsmMap;
use serde::Serialize;

/// A ranked candidate with its pose in the map frame and in WGS84.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct GeoCandidate {
    /// Rank, 1 = best.
    pub rank: usize,
    /// Metres east in the map's local frame.
    pub x: f64,
    /// Metres north in the map's local frame.
    pub y: f64,
    /// Latitude, degrees.
    pub lat: f64,
    /// Longitude, degrees.
    pub lon: f64,
    /// Heading from true east, radians in [0, 2π) (grid heading plus meridian convergence).
    pub yaw: f64,
    /// Heading from grid east, radians.
    pub yaw_grid: f64,
    /// d_DCM, metres.
    pub dcm: f64,
    /// Forward cost, metres.
    pub forward: f64,
    /// Reverse cost, metres.
    pub reverse: f64,
    /// Symmetric cost, metres.
    pub symmetric: f64,
    /// Whether the pose was refined.
    pub refined: bool,
    /// Margin to the best distinct other candidate, [0, 1].
    pub confidence: f64,
}

impl GeoCandidate {
    /// The candidate at 0-based `rank` on `map`.
    pub fn new(map: &OsmMap, rank: usize, c: &Candidate) -> Self {
        let xy = [c.pose.x, c.pose.y];
        let (lat, lon) = map.frame.to_wgs84(xy);
        let yaw =
            (c.pose.yaw_rad + map.frame.convergence_rad(xy)).rem_euclid(std::f64::consts::TAU);
        GeoCandidate {
            rank: rank + 1,
            x: c.pose.x,
            y: c.pose.y,
            lat,
            lon,
            yaw,
            yaw_grid: c.pose.yaw_rad,
            dcm: c.costs.dcm,
            forward: c.costs.forward,
            reverse: c.costs.reverse,
            symmetric: c.costs.symmetric,
            refined: c.refined,
            confidence: c.confidence,
        }
    }

    /// The `top` best candidates of `result`.
    pub fn top(map: &OsmMap, result: &Localization, top: usize) -> Vec<Self> {
        result
            .candidates
            .iter()
            .take(top)
            .enumerate()
            .map(|(i, c)| GeoCandidate::new(map, i, c))
            .collect()
    }
}

/// Seconds of one `localize` run, map preparation included.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct LocalizeSeconds {
    /// Loading the map (or index).
    pub load_map: f64,
    /// Map edges.
    pub map_edges: f64,
    /// Distance-transform tensor.
    pub distance_transform: f64,
    /// Lower-bound pyramid.
    pub pyramid: f64,
    /// Feasible-pose mask.
    pub feasible_mask: f64,
    /// Reading the scan.
    pub read_scan: f64,
    /// The scan's stages.
    #[serde(flatten)]
    pub scan: StageSeconds,
}

/// One scan localized (`localize --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct LocalizeReport {
    /// The map (or index) file.
    pub map: String,
    /// The scan file.
    pub scan: String,
    /// The cost that ranks the candidates.
    pub cost: &'static str,
    /// The best candidates.
    pub candidates: Vec<GeoCandidate>,
    /// All candidates.
    pub candidate_count: usize,
    /// Confidence of the top candidate.
    pub confidence: f64,
    /// Wall segments extracted.
    pub segments: usize,
    /// The sensor the scan was processed as.
    pub sensor: Option<SensorReport>,
    /// Wall clearance above ground, metres.
    pub clearance_m: f64,
    /// The scan's tilt estimated from its walls and whether it was levelled (`null`: off).
    pub level: Option<crate::level::Levelling>,
    /// Vertical-surface cells.
    pub vertical_cells: usize,
    /// Poses the search returned.
    pub raw_poses: usize,
    /// Poses after non-maximum suppression.
    pub after_suppression: usize,
    /// Candidates dropped after refinement, for having converged on a better-ranked one.
    pub refined_duplicates: usize,
    /// Why candidates were dropped.
    pub filtered: FilterCounts,
    /// Search statistics.
    pub search: SearchStats,
    /// Why the scan could not be localized, or why its best candidate is not accepted.
    pub message: Option<String>,
    /// Whether the best candidate passes the acceptance gate (`--max-accept-cost-m`); the
    /// candidates are listed either way.
    pub accepted: bool,
    /// Seconds.
    pub seconds: LocalizeSeconds,
    /// On a tiled map: the tiles searched.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub tiles: Option<TilesUsed>,
}

/// The tiles of a tiled map one scan was searched on.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TilesUsed {
    /// Tiles searched.
    pub searched: usize,
    /// Whether the answer equals the whole map's (the scan and the visibility range lie
    /// within the tiles' overlap).
    pub exact: bool,
    /// The largest memory one tile held (tensor, pyramid, mask), bytes.
    pub max_tile_memory_bytes: u64,
    /// Seconds reading tiles and crops.
    pub load_seconds: f64,
}

impl LocalizeReport {
    /// The report of `result`, its `top` best candidates listed.
    pub fn new(
        localizer: &Localizer<'_>,
        map: &str,
        scan: &str,
        result: &Localization,
        top: usize,
        load_map_seconds: f64,
        read_scan_seconds: f64,
    ) -> Self {
        Self::of_map(
            localizer.map,
            &localizer.seconds,
            (map, scan),
            result,
            top,
            load_map_seconds,
            read_scan_seconds,
        )
    }

    /// The report of `result` on a map whose frame `frame_map` has, prepared in `prepared`
    /// seconds; `names` are the map's and the scan's.
    pub fn of_map(
        frame_map: &OsmMap,
        prepared: &crate::index::MapSeconds,
        names: (&str, &str),
        result: &Localization,
        top: usize,
        load_map_seconds: f64,
        read_scan_seconds: f64,
    ) -> Self {
        let (map, scan) = names;
        LocalizeReport {
            map: map.to_owned(),
            scan: scan.to_owned(),
            cost: result.rank_by.name(),
            candidates: GeoCandidate::top(frame_map, result, top),
            candidate_count: result.candidates.len(),
            confidence: result.confidence,
            segments: result.segments.len(),
            sensor: result.sensor,
            clearance_m: result.clearance_m,
            level: result.levelling,
            vertical_cells: result.vertical_cells,
            raw_poses: result.raw_poses,
            after_suppression: result.after_suppression,
            refined_duplicates: result.refined_duplicates,
            filtered: result.filtered,
            search: result.search,
            message: result.message.clone(),
            accepted: result.accepted,
            seconds: LocalizeSeconds {
                load_map: load_map_seconds,
                map_edges: prepared.edges,
                distance_transform: prepared.distance_transform,
                pyramid: prepared.pyramid,
                feasible_mask: prepared.feasible,
                read_scan: read_scan_seconds,
                scan: result.seconds,
            },
            tiles: None,
        }
    }
}

/// One scan of a track: its best pose (none when nothing was found) and candidates.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrackRow {
    /// Scan file name.
    pub scan: String,
    /// Latitude of the best candidate, degrees.
    pub lat: Option<f64>,
    /// Longitude of the best candidate, degrees.
    pub lon: Option<f64>,
    /// Heading of the best candidate from true east, radians.
    pub yaw: Option<f64>,
    /// Metres east of the best candidate in the map frame.
    pub x: Option<f64>,
    /// Metres north of the best candidate in the map frame.
    pub y: Option<f64>,
    /// Confidence.
    pub confidence: f64,
    /// The best candidates.
    pub candidates: Vec<GeoCandidate>,
    /// Wall segments extracted.
    pub segments: usize,
    /// The sensor the scan was processed as.
    pub sensor: Option<SensorReport>,
    /// Why the scan could not be localized, or that the odometry alone placed it (no walls).
    pub message: Option<String>,
    /// The run of scans whose answers the pose graph refined with this one, and the odometry
    /// drift estimated over it (`null` outside a run, or without the graph).
    pub odometry_run: Option<crate::graph::OdometryRun>,
}

impl TrackRow {
    /// The row of one scan of a track.
    pub fn new(
        map: &OsmMap,
        scan: &str,
        result: &Localization,
        extracted: &ScanSegments,
        top: usize,
    ) -> Self {
        let best = result
            .candidates
            .first()
            .map(|c| GeoCandidate::new(map, 0, c));
        TrackRow {
            scan: scan.to_owned(),
            lat: best.map(|b| b.lat),
            lon: best.map(|b| b.lon),
            yaw: best.map(|b| b.yaw),
            x: best.map(|b| b.x),
            y: best.map(|b| b.y),
            confidence: result.confidence,
            candidates: GeoCandidate::top(map, result, top),
            segments: extracted.segments.len(),
            sensor: extracted.sensor,
            message: result.message.clone(),
            odometry_run: result.odometry_run,
        }
    }
}

/// Seconds of a track.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TrackSeconds {
    /// Everything after map preparation.
    pub total: f64,
    /// Per scan.
    pub per_scan: f64,
}

/// A track localized (`localize track --json`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct TrackReport {
    /// The map (or index) file.
    pub map: String,
    /// The folder of scans.
    pub scans_dir: String,
    /// The odometry file.
    pub odometry: String,
    /// Scans per window.
    pub window: usize,
    /// Odometry distance before the window through which chains still count, metres.
    pub history_m: f64,
    /// Whether the scans after each scan counted too (`--causal`: only those before it).
    pub smoothed: bool,
    /// Whether the smoothed answers were refined together (`--no-pose-graph`: not).
    pub pose_graph: bool,
    /// The cost that ranks the candidates.
    pub cost: &'static str,
    /// One row per scan, in file-name order.
    pub scans: Vec<TrackRow>,
    /// Seconds.
    pub seconds: TrackSeconds,
}
