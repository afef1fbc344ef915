//! Simulated datasets with exact ground truth, written as PLY + JSON.
//!
//! Every dataset folder has a `dataset.json` with `kind`, `map` (the map path as given),
//! `seed`, the options used and what the simulator changed. Coordinates are in the local
//! frame of `OsmMap::load(map)` (east, north, up in metres); yaws are radians
//! counter-clockwise. The kinds:
//!
//! - **localization** ([`write_localization`]): `scan_000.ply` … in the gravity-levelled
//!   sensor frame (origin at the sensor, x along the heading, z up) and `truth.json`
//!   mapping each scan file name to `{"x", "y", "z", "yaw", "lat", "lon", "yaw_grid",
//!   "world_x", "world_y", "world_yaw", "world_yaw_grid"}`. The world carries the OSM
//!   map-error model unless disabled, so the world and the map disagree; like the thesis'
//!   scans, "manually aligned with the data retrieved from OpenStreetMap", the truth is the
//!   pose in the *map's* frame: `x`, `y` = p + D(p) for the world position p and the
//!   map-error field D, `yaw_grid` = the world heading plus the field's local rotation
//!   ½(∂D_y/∂x − ∂D_x/∂y), both in the local frame; `yaw` the same from *geographic* east
//!   (plus meridian convergence); `lat`, `lon` of (`x`, `y`); `z` the sensor height in the
//!   local frame. `world_x`, `world_y`, `world_yaw_grid`, `world_yaw` are the pose in the
//!   simulated world (equal to the map pose without map error). Poses are sidewalk poses
//!   from which at least `min_map_building_view` of the horizon (720 horizontal rays at
//!   sensor height, through clutter) meets a building the map has within `view_range_m`:
//!   like the thesis' Munich and Bremen scans, they are taken among buildings.
//! - **streets** ([`write_streets`]): scans every `spacing_m` along a route driven on the
//!   true street centre lines, registered into one `cloud.ply` in the local frame (labels:
//!   street = driving area, sidewalk, …), `segments.json` — one entry per segment of
//!   `map.streets.segments` in order, `{"segment", "offset_m", "width_m", "sidewalk_m",
//!   "drivable", "observed", "points"}` (see [`super::truth`] for the offset convention;
//!   `points` counts the cloud's driving-area points of the segment, `observed` is
//!   `points ≥ 200`) — and the scan poses in `dataset.json` (`poses`).
//! - **relations** ([`write_relations`]): viewpoint scenes `scene_000.ply` (a scan from a
//!   sidewalk viewpoint, in the local frame) with `scene_000.json`: the `viewpoint`
//!   `{"x", "y", "z", "yaw"}`, the `objects` seen (≥ `min_points` points within
//!   `max_range_m`) with class and true oriented box, and `pairs`: for every ordered pair
//!   of a non-ground object `a` and any other object `b`, the true `On`, `LeftOf`,
//!   `Behind` and the `annotated` ones (each flipped with the annotator-noise rate). The
//!   geometric definitions are in [`relations_between`]. `dataset.json` lists the `train`
//!   and `test` scene indices.
//!
//! Each kind has its own module (`localization`, `streets`, `relations`); this one holds what
//! they share: [`DatasetSummary`], the scan loop, JSON writing, per-scan seeds, and the drive
//! route with its poses (car-mounted localization and streets both drive).

use crate::scene::{Pose, Scene};
use crate::sensor::{scan_with, ScanFrame, SensorOptions};
use crate::{mix64, purpose, stream_rng, SimError};
use geodata::cloud::PointCloud;
pub use geodata::simfiles::{MapBuilding, MapBuildings, TruthPose, MAP_BUILDINGS_FILE};
use rand::Rng;
use serde::Serialize;
use std::collections::BTreeMap;
use std::path::Path;

mod localization;
mod relations;
mod streets;

pub use localization::{map_building_view, write_localization, LocalizationOptions};
pub use relations::{
    relations_between, write_relations, PairRelations, RelationObject, RelationsOptions,
    MAP_BUILDINGS_MARGIN_M,
};
pub use streets::{write_streets, StreetsOptions};

/// What a dataset writer produced.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct DatasetSummary {
    /// Scans simulated.
    pub scans: usize,
    /// Rays cast.
    pub rays: usize,
    /// Points written.
    pub points: usize,
    /// Seconds spent ray casting (not written to `dataset.json`, which must be the same
    /// bytes for the same seed on every run).
    #[serde(skip)]
    pub cast_seconds: f64,
}

/// Scans from every pose in turn (scan `i` seeded with [`scan_seed`]`(seed, i)`), hands
/// `each(i, pose, cloud)` every scan, and counts what was cast; `progress(done, total)` is
/// called after each scan.
fn scan_poses(
    scene: &Scene,
    poses: &[Pose],
    sensor: &SensorOptions,
    frame: ScanFrame,
    seed: u64,
    progress: &(dyn Fn(usize, usize) + Sync),
    mut each: impl FnMut(usize, &Pose, PointCloud) -> Result<(), SimError>,
) -> Result<DatasetSummary, SimError> {
    let started = std::time::Instant::now();
    let mut summary = DatasetSummary::default();
    for (i, pose) in poses.iter().enumerate() {
        let (cloud, stats) = scan_with(scene, pose, sensor, scan_seed(seed, i), frame)?;
        each(i, pose, cloud)?;
        summary.scans += 1;
        summary.rays += stats.rays;
        summary.points += stats.points;
        progress(i + 1, poses.len());
    }
    summary.cast_seconds = started.elapsed().as_secs_f64();
    Ok(summary)
}

/// Maps an I/O error on `path` to [`SimError::Io`] naming the path.
fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SimError + '_ {
    move |source| SimError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Writes `value` as pretty JSON plus a newline to `path`, atomically.
/// The `map_error` entry of a dataset's `dataset.json`: the model's options and what it did
/// to the scene's map.
fn map_error_meta(scene: &Scene, options: &crate::scene::MapErrorOptions) -> serde_json::Value {
    serde_json::json!({
        "options": options,
        "removed_buildings": scene.map_error.removed.len(),
        "extra_buildings": scene.map_error.extra,
        "mean_shift_m": scene.map_error.mean_shift_m,
    })
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), SimError> {
    let text = serde_json::to_string_pretty(value).map_err(|source| SimError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    geodata::fsio::write_atomic(path, text + "\n").map_err(io_err(path))
}

/// The seed of scan (or scene) `index` of a dataset with seed `seed`.
fn scan_seed(seed: u64, index: usize) -> u64 {
    mix64(seed ^ mix64(index as u64 + 1))
}

/// A route through the street network: segment indices and direction (`true`: a→b).
fn drive_route(scene: &Scene, route_m: f64, seed: u64) -> Result<Vec<(usize, bool)>, SimError> {
    let drivable: Vec<usize> = (0..scene.segments.len())
        .filter(|&s| {
            scene.truth[s].drivable && scene.truth[s].on_ground && scene.segments[s].length_m > 0.0
        })
        .collect();
    if drivable.is_empty() {
        return Err(SimError::NoRoute);
    }
    let mut at_node: BTreeMap<i64, Vec<usize>> = BTreeMap::new();
    for &s in &drivable {
        at_node
            .entry(scene.segments[s].from_node)
            .or_default()
            .push(s);
        at_node
            .entry(scene.segments[s].to_node)
            .or_default()
            .push(s);
    }
    let mut rng = stream_rng(seed, purpose::ROUTE, 0);
    let mut visited = vec![false; scene.segments.len()];
    let mut route = Vec::new();
    let mut length = 0.0;
    let mut current: Option<(usize, bool)> = None;
    while length < route_m {
        let next = match current {
            None => {
                let fresh: Vec<usize> = drivable.iter().copied().filter(|&s| !visited[s]).collect();
                if fresh.is_empty() {
                    break;
                }
                Some((fresh[rng.gen_range(0..fresh.len())], rng.gen::<bool>()))
            }
            Some((s, forward)) => {
                let seg = &scene.segments[s];
                let node = if forward { seg.to_node } else { seg.from_node };
                let dir = if forward {
                    [seg.b[0] - seg.a[0], seg.b[1] - seg.a[1]]
                } else {
                    [seg.a[0] - seg.b[0], seg.a[1] - seg.b[1]]
                };
                // Prefer unvisited segments, then the straightest continuation.
                at_node
                    .get(&node)
                    .into_iter()
                    .flatten()
                    .filter(|&&n| n != s && !visited[n])
                    .map(|&n| {
                        let ns = &scene.segments[n];
                        let fwd = ns.from_node == node;
                        let nd = if fwd {
                            [ns.b[0] - ns.a[0], ns.b[1] - ns.a[1]]
                        } else {
                            [ns.a[0] - ns.b[0], ns.a[1] - ns.b[1]]
                        };
                        let cos = (dir[0] * nd[0] + dir[1] * nd[1])
                            / ((dir[0].hypot(dir[1]) * nd[0].hypot(nd[1])).max(1e-12));
                        (n, fwd, cos + 0.5 * rng.gen::<f64>())
                    })
                    .max_by(|a, b| a.2.total_cmp(&b.2))
                    .map(|(n, fwd, _)| (n, fwd))
            }
        };
        match next {
            Some((s, forward)) => {
                visited[s] = true;
                length += scene.segments[s].length_m;
                route.push((s, forward));
                current = Some((s, forward));
            }
            None if current.is_some() => current = None,
            None => break,
        }
    }
    Ok(route)
}

/// Poses every `spacing_m` along the true centre lines of a route, `height_m` above the street.
fn route_poses(scene: &Scene, route: &[(usize, bool)], spacing_m: f64, height_m: f64) -> Vec<Pose> {
    let mut poses = Vec::new();
    let mut carry = 0.0;
    for &(s, forward) in route {
        let seg = &scene.segments[s];
        let [a, b] = crate::truth::offset_centre_line(seg, &scene.truth[s]);
        let (p0, p1) = if forward { (a, b) } else { (b, a) };
        let yaw = (p1[1] - p0[1]).atan2(p1[0] - p0[0]);
        let mut t = carry;
        while t <= seg.length_m {
            let f = t / seg.length_m;
            let p = [p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1])];
            if scene.clear_of_shapes(p, 1.0) && !scene.inside_building(p) {
                let z = scene.ground_at(p).z + height_m;
                poses.push(Pose {
                    position: [p[0], p[1], z],
                    yaw_rad: yaw,
                });
            }
            t += spacing_m;
        }
        carry = t - seg.length_m;
    }
    poses
}

/// Fixtures shared by the tests of the dataset kinds.
#[cfg(test)]
mod test_support {
    use crate::sensor::SensorOptions;
    use geodata::osm::OsmMap;

    /// The procedural test city the dataset tests simulate.
    pub(super) fn map() -> OsmMap {
        crate::scene::tests::small_map(8)
    }

    /// A coarse scanner, so that the tests run fast.
    pub(super) fn fast_sensor() -> SensorOptions {
        SensorOptions {
            h_step_deg: 2.0,
            v_step_deg: 2.0,
            ..SensorOptions::default()
        }
    }
}
