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

use super::scene::SceneObject;
use super::scene::{MapErrorOptions, Pose, Scene, SceneOptions};
use super::sensor::{scan_with, ScanFrame, SensorOptions};
use super::{mix64, purpose, stream_rng, SimError};
use geodata::classes::Class;
use geodata::cloud::{write_cloud, PointCloud};
use geodata::osm::geometry::{longest_edge_box, point_ring_distance, ring_bounds};
use geodata::osm::OsmMap;
use geodata::sensors::SensorKind;
pub use geodata::simfiles::{MapBuilding, MapBuildings, TruthPose, MAP_BUILDINGS_FILE};
use rand::Rng;
use serde::Serialize;
use serde_json::{json, Value};
use std::collections::BTreeMap;
use std::path::Path;

/// Options of a `localization` dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct LocalizationOptions {
    /// Number of scans.
    pub scans: usize,
    /// The world (map-error model on by default).
    pub scene: SceneOptions,
    /// The scanner.
    pub sensor: SensorOptions,
    /// Sensor height above the sidewalk, metres.
    pub sensor_height_m: f64,
    /// Smallest fraction of the horizon (horizontal rays from the sensor) that must meet a
    /// building the map has within `view_range_m`: scans are taken among buildings, as the
    /// thesis' datasets were (0: any sidewalk pose).
    pub min_map_building_view: f64,
    /// Range of that view test, metres.
    pub view_range_m: f64,
    /// The sensor model the scanner imitates: terrestrial scans are taken on sidewalks,
    /// car-mounted ones on the road, heading along it, every `spacing_m` along a drive.
    pub sensor_kind: SensorKind,
    /// Distance between car-mounted scans along the drive, metres.
    pub spacing_m: f64,
}

impl LocalizationOptions {
    /// The options of a sensor model: its beams, azimuth step, range and mount height.
    pub fn for_sensor(kind: SensorKind) -> LocalizationOptions {
        LocalizationOptions {
            sensor: SensorOptions::of_kind(kind),
            sensor_height_m: kind.mount_height_m(),
            sensor_kind: kind,
            ..LocalizationOptions::default()
        }
    }
}

impl Default for LocalizationOptions {
    fn default() -> Self {
        LocalizationOptions {
            scans: 80,
            scene: SceneOptions {
                map_error: MapErrorOptions::osm_like(),
                ..SceneOptions::default()
            },
            sensor: SensorOptions::default(),
            sensor_height_m: 1.8,
            min_map_building_view: 0.1,
            view_range_m: 60.0,
            sensor_kind: SensorKind::Terrestrial,
            spacing_m: 10.0,
        }
    }
}

/// Fraction of 720 horizontal rays from the sensor that meet a building the map has (not an
/// extra world building) within `range_m`.
pub fn map_building_view(scene: &Scene, pose: &Pose, range_m: f64) -> f64 {
    const RAYS: usize = 720;
    let hits = (0..RAYS)
        .filter(|&k| {
            let a = k as f64 * std::f64::consts::TAU / RAYS as f64;
            scene
                .cast(pose.position, [a.cos(), a.sin(), 0.0], range_m)
                .and_then(|h| {
                    let id = h.surface.object as usize;
                    id.checked_sub(1).and_then(|i| scene.buildings.get(i))
                })
                .is_some_and(|b| b.map_index.is_some())
        })
        .count();
    hits as f64 / RAYS as f64
}

/// Sidewalk poses with at least `min_map_building_view` of the horizon on map buildings,
/// drawn in seeded batches.
fn localization_poses(
    scene: &Scene,
    options: &LocalizationOptions,
    seed: u64,
) -> Result<Vec<Pose>, SimError> {
    let h = options.sensor_height_m;
    if options.sensor_kind.on_car() {
        return car_poses(scene, options, seed);
    }
    if options.min_map_building_view <= 0.0 {
        return scene.sample_poses_with_height(options.scans, h, seed);
    }
    let mut out = Vec::with_capacity(options.scans);
    let mut tried = 0;
    for batch in 0..50u64 {
        let batch_seed = if batch == 0 {
            seed
        } else {
            mix64(seed ^ mix64(batch))
        };
        for pose in scene.sample_poses_with_height(options.scans.max(1), h, batch_seed)? {
            tried += 1;
            if out.len() < options.scans
                && map_building_view(scene, &pose, options.view_range_m)
                    >= options.min_map_building_view
            {
                out.push(pose);
            }
        }
        if out.len() >= options.scans {
            return Ok(out);
        }
    }
    Err(SimError::NoPoses {
        wanted: options.scans,
        found: out.len(),
        tries: tried,
    })
}

/// Car poses every `spacing_m` along a seeded drive (on the true centre line, heading along
/// it), those with enough of the horizon on map buildings, at most `scans`.
fn car_poses(
    scene: &Scene,
    options: &LocalizationOptions,
    seed: u64,
) -> Result<Vec<Pose>, SimError> {
    if !(options.spacing_m.is_finite() && options.spacing_m >= 0.5) {
        return Err(SimError::InvalidOption {
            name: "spacing_m",
            value: options.spacing_m,
            expected: "a spacing ≥ 0.5 m",
        });
    }
    // Drive eight times the needed length: poses without a view of map buildings are skipped.
    let route_m = 8.0 * options.spacing_m * options.scans.max(1) as f64;
    let route = drive_route(scene, route_m, seed)?;
    let poses: Vec<Pose> = route_poses(scene, &route, options.spacing_m, options.sensor_height_m)
        .into_iter()
        .filter(|p| {
            options.min_map_building_view <= 0.0
                || map_building_view(scene, p, options.view_range_m)
                    >= options.min_map_building_view
        })
        .take(options.scans)
        .collect();
    if poses.len() < options.scans {
        return Err(SimError::NoCarPoses {
            wanted: options.scans,
            found: poses.len(),
            route_m,
        });
    }
    Ok(poses)
}

/// Poses every `spacing_m` along the true centre lines of a route, `height_m` above the street.
fn route_poses(scene: &Scene, route: &[(usize, bool)], spacing_m: f64, height_m: f64) -> Vec<Pose> {
    let mut poses = Vec::new();
    let mut carry = 0.0;
    for &(s, forward) in route {
        let seg = &scene.segments[s];
        let [a, b] = super::truth::offset_centre_line(seg, &scene.truth[s]);
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

fn io_err(path: &Path) -> impl FnOnce(std::io::Error) -> SimError + '_ {
    move |source| SimError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn write_json(path: &Path, value: &impl Serialize) -> Result<(), SimError> {
    let text = serde_json::to_string_pretty(value).map_err(|source| SimError::Json {
        path: path.to_path_buf(),
        source,
    })?;
    geodata::fsio::write_atomic(path, text + "\n").map_err(io_err(path))
}

fn scan_seed(seed: u64, index: usize) -> u64 {
    mix64(seed ^ mix64(index as u64 + 1))
}

/// Writes a `localization` dataset; `progress(done, total)` is called after each scan.
pub fn write_localization(
    map: &OsmMap,
    map_path: &str,
    out: &Path,
    options: &LocalizationOptions,
    seed: u64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<DatasetSummary, SimError> {
    std::fs::create_dir_all(out).map_err(io_err(out))?;
    let scene = Scene::build(map, &options.scene, seed)?;
    let poses = localization_poses(&scene, options, seed)?;
    let mut truth = BTreeMap::new();
    let mut summary = DatasetSummary::default();
    let started = std::time::Instant::now();
    for (i, pose) in poses.iter().enumerate() {
        let (cloud, stats) = scan_with(
            &scene,
            pose,
            &options.sensor,
            scan_seed(seed, i),
            ScanFrame::Sensor,
        )?;
        let name = format!("scan_{i:03}.ply");
        write_cloud(out.join(&name), &cloud)?;
        let world_xy = [pose.position[0], pose.position[1]];
        let field = &scene.map_error.field;
        let xy = field.map_from_world(world_xy);
        let yaw_grid = pose.yaw_rad + field.rotation_rad(world_xy);
        let (lat, lon) = scene.frame.to_wgs84(xy);
        truth.insert(
            name,
            TruthPose {
                x: xy[0],
                y: xy[1],
                z: pose.position[2],
                yaw: yaw_grid + scene.frame.convergence_rad(xy),
                lat,
                lon,
                yaw_grid,
                world_x: world_xy[0],
                world_y: world_xy[1],
                world_yaw: pose.yaw_rad + scene.frame.convergence_rad(world_xy),
                world_yaw_grid: pose.yaw_rad,
            },
        );
        summary.scans += 1;
        summary.rays += stats.rays;
        summary.points += stats.points;
        progress(i + 1, poses.len());
    }
    summary.cast_seconds = started.elapsed().as_secs_f64();
    write_json(&out.join("truth.json"), &truth)?;
    let (lat0, lon0) = scene.frame.origin();
    write_json(
        &out.join("dataset.json"),
        &json!({
            "kind": "localization",
            "map": map_path,
            "seed": seed,
            "scans": summary.scans,
            "frame_origin": {"lat": lat0, "lon": lon0},
            "sensor": options.sensor,
            "sensor_profile": options.sensor_kind.name(),
            "sensor_height_m": options.sensor_height_m,
            "min_map_building_view": options.min_map_building_view,
            "view_range_m": options.view_range_m,
            "map_error": {
                "options": options.scene.map_error,
                "removed_buildings": scene.map_error.removed.len(),
                "extra_buildings": scene.map_error.extra,
                "mean_shift_m": scene.map_error.mean_shift_m,
                "field": scene.map_error.field,
                "truth_frame": "map: x, y, yaw, yaw_grid, lat, lon are the world pose p mapped to p + D(p) and turned by the field's local rotation; world_* are the pose in the simulated world",
            },
            "summary": summary,
        }),
    )?;
    Ok(summary)
}

/// Options of a `streets` dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct StreetsOptions {
    /// Length of the route to drive, metres.
    pub route_m: f64,
    /// Distance between scans along the route, metres.
    pub spacing_m: f64,
    /// Largest number of scans (0: as many as the route gives).
    pub max_scans: usize,
    /// The world (no map error by default: the street truth is what matters here).
    pub scene: SceneOptions,
    /// The scanner.
    pub sensor: SensorOptions,
    /// Sensor height above the street, metres.
    pub sensor_height_m: f64,
}

impl Default for StreetsOptions {
    fn default() -> Self {
        StreetsOptions {
            route_m: 2500.0,
            spacing_m: 20.0,
            max_scans: 0,
            scene: SceneOptions::default(),
            sensor: SensorOptions {
                h_step_deg: 0.5,
                v_min_deg: -50.0,
                v_max_deg: 20.0,
                v_step_deg: 0.5,
                range_max_m: 30.0,
                ..SensorOptions::default()
            },
            sensor_height_m: 1.8,
        }
    }
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

/// Writes a `streets` dataset; `progress(done, total)` is called after each scan.
pub fn write_streets(
    map: &OsmMap,
    map_path: &str,
    out: &Path,
    options: &StreetsOptions,
    seed: u64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<DatasetSummary, SimError> {
    if !(options.spacing_m.is_finite() && options.spacing_m >= 1.0) {
        return Err(SimError::InvalidOption {
            name: "spacing_m",
            value: options.spacing_m,
            expected: "a spacing ≥ 1 m",
        });
    }
    std::fs::create_dir_all(out).map_err(io_err(out))?;
    let scene = Scene::build(map, &options.scene, seed)?;
    let route = drive_route(&scene, options.route_m, seed)?;
    // Scan poses every spacing_m along the true centre lines of the route.
    let mut poses = route_poses(&scene, &route, options.spacing_m, options.sensor_height_m);
    if options.max_scans > 0 {
        poses.truncate(options.max_scans);
    }
    let started = std::time::Instant::now();
    let mut summary = DatasetSummary::default();
    let mut cloud = PointCloud::default();
    for (i, pose) in poses.iter().enumerate() {
        let (part, stats) = scan_with(
            &scene,
            pose,
            &options.sensor,
            scan_seed(seed, i),
            ScanFrame::World,
        )?;
        if i == 0 {
            cloud = part;
        } else {
            cloud.extend(&part);
        }
        summary.scans += 1;
        summary.rays += stats.rays;
        summary.points += stats.points;
        progress(i + 1, poses.len());
    }
    summary.cast_seconds = started.elapsed().as_secs_f64();
    // Driving-area points per segment, from the object ids.
    let mut points = vec![0usize; scene.segments.len()];
    if let (Some(labels), Some(objects)) = (&cloud.label, &cloud.object) {
        let first = scene.street_object(0);
        for (&l, &o) in labels.iter().zip(objects) {
            if l == Class::Street.id() && o >= first {
                if let Some(c) = points.get_mut((o - first) as usize) {
                    *c += 1;
                }
            }
        }
    }
    write_cloud(out.join("cloud.ply"), &cloud)?;
    let segments: Vec<Value> = scene
        .truth
        .iter()
        .enumerate()
        .map(|(s, t)| {
            json!({
                "segment": s,
                "offset_m": t.offset_m,
                "width_m": t.width_m,
                "sidewalk_m": t.sidewalk_m,
                "drivable": t.drivable,
                "observed": points[s] >= 200,
                "points": points[s],
            })
        })
        .collect();
    write_json(&out.join("segments.json"), &segments)?;
    let route_m: f64 = route.iter().map(|&(s, _)| scene.segments[s].length_m).sum();
    write_json(
        &out.join("dataset.json"),
        &json!({
            "kind": "streets",
            "map": map_path,
            "seed": seed,
            "route": route.iter().map(|&(s, f)| json!({"segment": s, "forward": f})).collect::<Vec<_>>(),
            "route_m": route_m,
            "poses": poses.iter().map(|p| p.position).collect::<Vec<_>>(),
            "yaws": poses.iter().map(|p| p.yaw_rad).collect::<Vec<_>>(),
            "sensor": options.sensor,
            "sensor_height_m": options.sensor_height_m,
            "observed_segments": points.iter().filter(|&&p| p >= 200).count(),
            "summary": summary,
        }),
    )?;
    Ok(summary)
}

/// Options of a `relations` dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct RelationsOptions {
    /// Number of viewpoint scenes.
    pub scenes: usize,
    /// How many of them (the first ones) are for training.
    pub train: usize,
    /// Probability that the annotator flips one relation label of one pair.
    pub annotator_noise: f64,
    /// Objects farther than this from the viewpoint are left out, metres.
    pub max_range_m: f64,
    /// Objects with fewer points in the scan are left out.
    pub min_points: usize,
    /// The world.
    pub scene: SceneOptions,
    /// The scanner.
    pub sensor: SensorOptions,
    /// Sensor height above the sidewalk, metres.
    pub sensor_height_m: f64,
}

impl Default for RelationsOptions {
    fn default() -> Self {
        RelationsOptions {
            scenes: 62,
            train: 48,
            annotator_noise: 0.0,
            max_range_m: 25.0,
            min_points: 30,
            scene: SceneOptions::default(),
            sensor: SensorOptions {
                h_step_deg: 0.5,
                v_min_deg: -40.0,
                v_max_deg: 40.0,
                v_step_deg: 0.5,
                range_max_m: 30.0,
                ..SensorOptions::default()
            },
            sensor_height_m: 1.8,
        }
    }
}

/// An object of a relations scene with its true oriented box.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct RelationObject {
    /// Object id (as in the scan's `object` column).
    pub id: u32,
    /// Class name.
    pub class: Class,
    /// A ground surface (driving area or sidewalk) rather than a thing standing on it.
    pub ground: bool,
    /// Box centre, metres in the local frame.
    pub centre: [f64; 3],
    /// Half extents along the box's yaw direction, across, and up, metres.
    pub half_extents: [f64; 3],
    /// Yaw of the box's first axis, counter-clockwise from east, radians.
    pub yaw_rad: f64,
    /// Points of the object in the scan.
    pub points: usize,
    /// Id of the ground object under the box's footprint centre (0: none).
    pub support: u32,
}

/// The three base relations of a pair (RightOf and InFrontOf are their converses).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize)]
#[allow(non_snake_case)]
pub struct PairRelations {
    /// `a` stands on `b`.
    pub On: bool,
    /// `a` is left of `b` as seen from the viewpoint.
    pub LeftOf: bool,
    /// `a` is behind `b` as seen from the viewpoint.
    pub Behind: bool,
}

/// Angular interval (radians, left positive, relative to the viewing direction), nearest
/// corner range and centre range of a box seen from a viewpoint; `None` if not in front.
fn view_interval(viewpoint: &Pose, o: &RelationObject) -> Option<(f64, f64, f64, f64)> {
    let (s, c) = o.yaw_rad.sin_cos();
    let (sy, cy) = viewpoint.yaw_rad.sin_cos();
    let to_view = |p: [f64; 2]| {
        let q = [p[0] - viewpoint.position[0], p[1] - viewpoint.position[1]];
        [cy * q[0] + sy * q[1], -sy * q[0] + cy * q[1]]
    };
    let centre = to_view([o.centre[0], o.centre[1]]);
    if centre[0] <= 0.0 {
        return None;
    }
    let (mut lo, mut hi, mut near) = (f64::INFINITY, f64::NEG_INFINITY, f64::INFINITY);
    for (kx, ky) in [(-1.0, -1.0), (1.0, -1.0), (1.0, 1.0), (-1.0, 1.0)] {
        let (hx, hy) = (kx * o.half_extents[0], ky * o.half_extents[1]);
        let p = to_view([o.centre[0] + c * hx - s * hy, o.centre[1] + s * hx + c * hy]);
        let angle = p[1].atan2(p[0]);
        lo = lo.min(angle);
        hi = hi.max(angle);
        near = near.min(p[0].hypot(p[1]));
    }
    Some((lo, hi, near, centre[0].hypot(centre[1])))
}

/// The true relations of the ordered pair (a, b) seen from a viewpoint.
///
/// Definitions (angles about the viewpoint, left positive, from the box footprint corners):
/// - **On**(a, b): `b` is the ground surface under `a`'s footprint centre (`a.support`).
/// - **LeftOf**(a, b): both boxes lie in front of the viewpoint, neither is a ground
///   surface, their angular intervals overlap by at most 20 % of the narrower one, and
///   `a`'s interval centre is left of `b`'s.
/// - **Behind**(a, b): both in front, neither a ground surface, the angular intervals
///   overlap by at least 30 % of the narrower one, `a`'s centre is ≥ 1 m farther than
///   `b`'s, and `a`'s nearest corner is farther than `b`'s.
pub fn relations_between(
    viewpoint: &Pose,
    a: &RelationObject,
    b: &RelationObject,
) -> PairRelations {
    let mut r = PairRelations {
        On: !a.ground && b.ground && a.support == b.id && b.id != 0,
        ..PairRelations::default()
    };
    if a.ground || b.ground {
        return r;
    }
    let (Some(ia), Some(ib)) = (view_interval(viewpoint, a), view_interval(viewpoint, b)) else {
        return r;
    };
    let overlap = (ia.1.min(ib.1) - ia.0.max(ib.0)).max(0.0);
    let narrower = (ia.1 - ia.0).min(ib.1 - ib.0).max(1e-9);
    let fraction = overlap / narrower;
    r.LeftOf = fraction <= 0.2 && 0.5 * (ia.0 + ia.1) > 0.5 * (ib.0 + ib.1);
    r.Behind = fraction >= 0.3 && ia.3 >= ib.3 + 1.0 && ia.2 > ib.2;
    r
}

/// The true box of every object a scan sees (ids with ≥ `min_points` points within range).
fn scene_objects(
    scene: &Scene,
    cloud: &PointCloud,
    viewpoint: &Pose,
    options: &RelationsOptions,
) -> Vec<RelationObject> {
    let mut counts: BTreeMap<u32, usize> = BTreeMap::new();
    if let Some(objects) = &cloud.object {
        for (p, &o) in cloud.positions.iter().zip(objects) {
            let d = (p[0] - viewpoint.position[0]).hypot(p[1] - viewpoint.position[1]);
            if o != 0 && d <= options.max_range_m {
                *counts.entry(o).or_default() += 1;
            }
        }
    }
    let by_id: BTreeMap<u32, &SceneObject> = scene.objects.iter().map(|o| (o.id, o)).collect();
    let first_street = scene.street_object(0);
    let first_sidewalk = scene.sidewalk_object(0);
    let segments = scene.segments.len() as u32;
    let mut out = Vec::new();
    for (&id, &points) in &counts {
        if points < options.min_points {
            continue;
        }
        let object = if let Some(o) = by_id.get(&id) {
            let support = scene.ground_at([o.centre[0], o.centre[1]]).object;
            RelationObject {
                id,
                class: o.class,
                ground: false,
                centre: o.centre,
                half_extents: o.half_extents,
                yaw_rad: o.yaw_rad,
                points,
                support,
            }
        } else if id >= 1 && (id as usize) <= scene.buildings.len() {
            let b = &scene.buildings[id as usize - 1];
            let Some(rb) = longest_edge_box(&b.outer) else {
                continue;
            };
            RelationObject {
                id,
                class: Class::Building,
                ground: false,
                centre: [rb.centre[0], rb.centre[1], 0.5 * b.height_m],
                half_extents: [rb.half[0], rb.half[1], 0.5 * b.height_m],
                yaw_rad: rb.yaw_rad,
                points,
                support: 0,
            }
        } else if id >= first_street && id < first_street + segments
            || id >= first_sidewalk && id < first_sidewalk + segments
        {
            let street = id < first_sidewalk;
            let s = (id - if street { first_street } else { first_sidewalk }) as usize;
            let (seg, t) = (&scene.segments[s], &scene.truth[s]);
            let [a, b] = super::truth::offset_centre_line(seg, t);
            let half_width = if street {
                0.5 * t.width_m
            } else {
                0.5 * t.width_m + t.sidewalk_m
            };
            let top = if street { 0.0 } else { scene.kerb_m };
            RelationObject {
                id,
                class: if street {
                    Class::Street
                } else {
                    Class::Sidewalk
                },
                ground: true,
                centre: [0.5 * (a[0] + b[0]), 0.5 * (a[1] + b[1]), top - 0.05],
                half_extents: [0.5 * seg.length_m, half_width, 0.05],
                yaw_rad: (b[1] - a[1]).atan2(b[0] - a[0]),
                points,
                support: 0,
            }
        } else {
            continue;
        };
        out.push(object);
    }
    out
}

/// How much farther than the scenes' range [`MAP_BUILDINGS_FILE`] reaches, metres.
pub const MAP_BUILDINGS_MARGIN_M: f64 = 10.0;

/// The map's buildings whose outline comes within `reach_m` of a pose (top view).
fn map_buildings_near(map: &OsmMap, poses: &[Pose], reach_m: f64) -> MapBuildings {
    let near = |outer: &[[f64; 2]]| {
        let (lo, hi) = ring_bounds(outer);
        poses.iter().any(|pose| {
            let p = [pose.position[0], pose.position[1]];
            let outside = (0..2).any(|k| p[k] < lo[k] - reach_m || p[k] > hi[k] + reach_m);
            !outside && point_ring_distance(p, outer) <= reach_m
        })
    };
    MapBuildings {
        frame: "local".into(),
        buildings: map
            .buildings
            .iter()
            .filter(|b| b.outer.len() >= 3 && near(&b.outer))
            .map(|b| MapBuilding {
                osm_id: b.osm_id,
                outer: b.outer.clone(),
            })
            .collect(),
    }
}

/// Writes a `relations` dataset; `progress(done, total)` is called after each scene.
pub fn write_relations(
    map: &OsmMap,
    map_path: &str,
    out: &Path,
    options: &RelationsOptions,
    seed: u64,
    progress: &(dyn Fn(usize, usize) + Sync),
) -> Result<DatasetSummary, SimError> {
    if !(0.0..=1.0).contains(&options.annotator_noise) {
        return Err(SimError::InvalidOption {
            name: "annotator_noise",
            value: options.annotator_noise,
            expected: "a probability in [0, 1]",
        });
    }
    std::fs::create_dir_all(out).map_err(io_err(out))?;
    let scene = Scene::build(map, &options.scene, seed)?;
    let poses = scene.sample_poses_with_height(options.scenes, options.sensor_height_m, seed)?;
    let started = std::time::Instant::now();
    let mut summary = DatasetSummary::default();
    let mut pair_count = 0usize;
    let mut true_counts = [0usize; 3];
    for (i, pose) in poses.iter().enumerate() {
        let (cloud, stats) = scan_with(
            &scene,
            pose,
            &options.sensor,
            scan_seed(seed, i),
            ScanFrame::World,
        )?;
        let objects = scene_objects(&scene, &cloud, pose, options);
        let mut rng = stream_rng(seed, purpose::ANNOTATOR, i as u64);
        let mut pairs = Vec::new();
        for a in objects.iter().filter(|o| !o.ground) {
            for b in objects.iter().filter(|b| b.id != a.id) {
                let truth = relations_between(pose, a, b);
                let mut flip = |v: bool| {
                    let draw: f64 = rng.gen();
                    v ^ (draw < options.annotator_noise)
                };
                let annotated = PairRelations {
                    On: flip(truth.On),
                    LeftOf: flip(truth.LeftOf),
                    Behind: flip(truth.Behind),
                };
                true_counts[0] += usize::from(truth.On);
                true_counts[1] += usize::from(truth.LeftOf);
                true_counts[2] += usize::from(truth.Behind);
                pairs.push(json!({"a": a.id, "b": b.id, "truth": truth, "annotated": annotated}));
            }
        }
        pair_count += pairs.len();
        let name = format!("scene_{i:03}");
        write_cloud(out.join(format!("{name}.ply")), &cloud)?;
        write_json(
            &out.join(format!("{name}.json")),
            &json!({
                "viewpoint": {"x": pose.position[0], "y": pose.position[1], "z": pose.position[2], "yaw": pose.yaw_rad},
                "objects": objects,
                "pairs": pairs,
            }),
        )?;
        summary.scans += 1;
        summary.rays += stats.rays;
        summary.points += stats.points;
        progress(i + 1, poses.len());
    }
    summary.cast_seconds = started.elapsed().as_secs_f64();
    let train = options.train.min(poses.len());
    write_json(
        &out.join(MAP_BUILDINGS_FILE),
        &map_buildings_near(map, &poses, options.max_range_m + MAP_BUILDINGS_MARGIN_M),
    )?;
    write_json(
        &out.join("dataset.json"),
        &json!({
            "kind": "relations",
            "map": map_path,
            "map_buildings": MAP_BUILDINGS_FILE,
            "seed": seed,
            "scenes": poses.len(),
            "train": (0..train).collect::<Vec<_>>(),
            "test": (train..poses.len()).collect::<Vec<_>>(),
            "annotator_noise": options.annotator_noise,
            "max_range_m": options.max_range_m,
            "min_points": options.min_points,
            "pairs": pair_count,
            "true_pairs": {"On": true_counts[0], "LeftOf": true_counts[1], "Behind": true_counts[2]},
            "definitions": {
                "On": "b is the ground surface (driving area or sidewalk) under a's footprint centre",
                "LeftOf": "both in front of the viewpoint, not ground; angular intervals overlap <= 20% of the narrower; a's interval centre left of b's",
                "Behind": "both in front, not ground; angular overlap >= 30% of the narrower; a's centre >= 1 m farther and a's nearest corner farther than b's",
            },
            "sensor": options.sensor,
            "summary": summary,
        }),
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn map() -> OsmMap {
        crate::scene::tests::small_map(8)
    }

    fn fast_sensor() -> SensorOptions {
        SensorOptions {
            h_step_deg: 2.0,
            v_step_deg: 2.0,
            ..SensorOptions::default()
        }
    }

    #[test]
    fn localization_dataset_is_byte_identical_for_a_seed() {
        let map = map();
        let dir = std::env::temp_dir().join(format!("urbansem-sim-loc-{}", std::process::id()));
        let options = LocalizationOptions {
            scans: 2,
            sensor: fast_sensor(),
            ..LocalizationOptions::default()
        };
        let (a, b) = (dir.join("a"), dir.join("b"));
        write_localization(&map, "city.osm", &a, &options, 3, &|_, _| {}).unwrap();
        write_localization(&map, "city.osm", &b, &options, 3, &|_, _| {}).unwrap();
        for name in ["truth.json", "scan_000.ply", "scan_001.ply"] {
            let x = std::fs::read(a.join(name)).unwrap();
            let y = std::fs::read(b.join(name)).unwrap();
            assert!(x == y, "{name} differs between two runs with one seed");
        }
        let truth: Value =
            serde_json::from_slice(&std::fs::read(a.join("truth.json")).unwrap()).unwrap();
        let pose = &truth["scan_000.ply"];
        for key in [
            "x",
            "y",
            "z",
            "yaw",
            "lat",
            "lon",
            "world_x",
            "world_y",
            "world_yaw",
        ] {
            assert!(pose[key].is_f64(), "{key} missing");
        }
        // The map-error model is on: the map pose is the world pose through the field.
        let shift = (pose["x"].as_f64().unwrap() - pose["world_x"].as_f64().unwrap())
            .hypot(pose["y"].as_f64().unwrap() - pose["world_y"].as_f64().unwrap());
        assert!(shift > 1e-3 && shift < 10.0, "shift {shift}");
        let cloud = geodata::cloud::read_cloud(a.join("scan_000.ply")).unwrap();
        assert!(cloud.len() > 500);
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn localization_poses_see_map_buildings() {
        let map = map();
        let options = LocalizationOptions {
            scans: 6,
            min_map_building_view: 0.2,
            ..LocalizationOptions::default()
        };
        let scene = Scene::build(&map, &options.scene, 4).unwrap();
        let poses = localization_poses(&scene, &options, 4).unwrap();
        assert_eq!(poses.len(), 6);
        for p in &poses {
            assert!(map_building_view(&scene, p, 60.0) >= 0.2, "{p:?}");
        }
        let again = localization_poses(&scene, &options, 4).unwrap();
        assert_eq!(poses, again);
    }

    #[test]
    fn car_sensor_scans_from_the_road_along_it_and_names_its_sensor() {
        let map = map();
        let options = LocalizationOptions {
            scans: 4,
            min_map_building_view: 0.05,
            ..LocalizationOptions::for_sensor(SensorKind::Hdl64)
        };
        let scene = Scene::build(&map, &options.scene, 3).unwrap();
        let poses = localization_poses(&scene, &options, 3).unwrap();
        assert_eq!(poses.len(), 4);
        for p in &poses {
            let ground = scene.ground_at([p.position[0], p.position[1]]);
            assert_eq!(ground.class, Class::Street, "{p:?}");
            assert!((p.position[2] - ground.z - 1.73).abs() < 1e-9, "{p:?}");
        }
        let dir = std::env::temp_dir().join(format!("urbansem-car-{}", std::process::id()));
        write_localization(&map, "m.osm", &dir, &options, 3, &|_, _| {}).unwrap();
        let meta: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.join("dataset.json")).unwrap())
                .unwrap();
        assert_eq!(meta["sensor_profile"], "hdl64");
        assert_eq!(
            meta["sensor"]["elevations_deg"].as_array().unwrap().len(),
            64
        );
        let cloud = geodata::cloud::read_cloud(dir.join("scan_000.ply")).unwrap();
        // Beams reach +2° at most (plus range noise).
        let top = cloud
            .positions
            .iter()
            .filter(|q| q[0].hypot(q[1]) > 10.0)
            .map(|q| q[2].atan2(q[0].hypot(q[1])).to_degrees())
            .fold(f64::NEG_INFINITY, f64::max);
        assert!(top < 2.2, "{top}");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn streets_dataset_labels_lie_in_the_true_strips() {
        let map = map();
        let dir = std::env::temp_dir().join(format!("urbansem-sim-streets-{}", std::process::id()));
        let options = StreetsOptions {
            route_m: 300.0,
            max_scans: 6,
            sensor: SensorOptions {
                range_noise_m: 0.0,
                ..fast_sensor()
            },
            ..StreetsOptions::default()
        };
        let summary = write_streets(&map, "city.osm", &dir, &options, 5, &|_, _| {}).unwrap();
        assert_eq!(summary.scans, 6);
        let segments: Vec<Value> =
            serde_json::from_slice(&std::fs::read(dir.join("segments.json")).unwrap()).unwrap();
        assert_eq!(segments.len(), map.streets.segments.len());
        assert!(segments.iter().any(|s| s["observed"] == json!(true)));
        let cloud = geodata::cloud::read_cloud(dir.join("cloud.ply")).unwrap();
        let labels = cloud.label.as_ref().unwrap();
        let objects = cloud.object.as_ref().unwrap();
        let scene = Scene::build(&map, &options.scene, 5).unwrap();
        let mut checked = 0;
        for ((p, &l), &o) in cloud.positions.iter().zip(labels).zip(objects) {
            if l != Class::Street.id() {
                continue;
            }
            let s = (o - scene.street_object(0)) as usize;
            let t = &segments[s];
            let seg = &map.streets.segments[s];
            let (along, u) = super::super::truth::segment_coordinates(seg, [p[0], p[1]]);
            let w = t["width_m"].as_f64().unwrap();
            let d = t["offset_m"].as_f64().unwrap();
            if (0.0..=seg.length_m).contains(&along) {
                // f32 positions: allow a millimetre.
                assert!(
                    (u - d).abs() <= w / 2.0 + 1e-3,
                    "street point {p:?} outside segment {s}'s strip"
                );
                checked += 1;
            }
        }
        assert!(checked > 1000, "only {checked} street points checked");
        std::fs::remove_dir_all(&dir).ok();
    }

    #[test]
    fn relations_follow_their_definitions() {
        let vp = Pose {
            position: [0.0, 0.0, 1.8],
            yaw_rad: 0.0,
        };
        let object = |id, x: f64, y: f64| RelationObject {
            id,
            class: Class::Car,
            ground: false,
            centre: [x, y, 0.75],
            half_extents: [1.0, 1.0, 0.75],
            yaw_rad: 0.0,
            points: 100,
            support: 99,
        };
        let (left, right) = (object(1, 10.0, 5.0), object(2, 10.0, -5.0));
        assert!(relations_between(&vp, &left, &right).LeftOf);
        assert!(!relations_between(&vp, &right, &left).LeftOf);
        let (far, near) = (object(3, 20.0, 0.2), object(4, 8.0, 0.0));
        let r = relations_between(&vp, &far, &near);
        assert!(r.Behind && !r.LeftOf);
        assert!(!relations_between(&vp, &near, &far).Behind);
        let street = RelationObject {
            id: 99,
            ground: true,
            class: Class::Street,
            ..object(99, 10.0, 0.0)
        };
        assert!(relations_between(&vp, &left, &street).On);
        assert!(!relations_between(&vp, &street, &left).On);
        // Behind the viewpoint: no LeftOf/Behind.
        let back = object(5, -10.0, 3.0);
        assert_eq!(
            relations_between(&vp, &back, &right),
            PairRelations {
                On: false,
                ..Default::default()
            }
        );
    }

    #[test]
    fn relations_dataset_has_true_relations_of_every_kind() {
        let map = map();
        let dir = std::env::temp_dir().join(format!("urbansem-sim-rel-{}", std::process::id()));
        let options = RelationsOptions {
            scenes: 4,
            train: 3,
            annotator_noise: 0.1,
            sensor: SensorOptions {
                h_step_deg: 1.0,
                v_step_deg: 1.0,
                ..RelationsOptions::default().sensor
            },
            ..RelationsOptions::default()
        };
        write_relations(&map, "city.osm", &dir, &options, 2, &|_, _| {}).unwrap();
        let meta: Value =
            serde_json::from_slice(&std::fs::read(dir.join("dataset.json")).unwrap()).unwrap();
        assert_eq!(meta["train"], json!([0, 1, 2]));
        assert_eq!(meta["test"], json!([3]));
        for key in ["On", "LeftOf", "Behind"] {
            assert!(
                meta["true_pairs"][key].as_u64().unwrap() > 0,
                "no true {key}"
            );
        }
        let scene: Value =
            serde_json::from_slice(&std::fs::read(dir.join("scene_000.json")).unwrap()).unwrap();
        let pairs = scene["pairs"].as_array().unwrap();
        let flipped = pairs
            .iter()
            .filter(|p| p["truth"] != p["annotated"])
            .count();
        assert!(
            flipped > 0 && flipped < pairs.len() / 2,
            "{flipped} of {} flipped",
            pairs.len()
        );
        // The map's outlines of every building a scene lists, and none beyond reach.
        assert_eq!(meta["map_buildings"], json!(MAP_BUILDINGS_FILE));
        let outlines: MapBuildings =
            serde_json::from_slice(&std::fs::read(dir.join(MAP_BUILDINGS_FILE)).unwrap()).unwrap();
        assert_eq!(outlines.frame, "local");
        let ids: Vec<i64> = outlines.buildings.iter().map(|b| b.osm_id).collect();
        let scene = Scene::build(&map, &options.scene, 2).unwrap();
        let reach = options.max_range_m + MAP_BUILDINGS_MARGIN_M;
        let mut viewpoints = Vec::new();
        for i in 0..4 {
            let s: Value = serde_json::from_slice(
                &std::fs::read(dir.join(format!("scene_{i:03}.json"))).unwrap(),
            )
            .unwrap();
            viewpoints.push([
                s["viewpoint"]["x"].as_f64().unwrap(),
                s["viewpoint"]["y"].as_f64().unwrap(),
            ]);
            for o in s["objects"].as_array().unwrap() {
                if o["class"] == "Building" {
                    let b = &scene.buildings[o["id"].as_u64().unwrap() as usize - 1];
                    let m = &map.buildings[b.map_index.unwrap()];
                    assert!(ids.contains(&m.osm_id), "scene {i}: building {}", m.osm_id);
                }
            }
        }
        let distance = |outer: &[[f64; 2]]| {
            viewpoints
                .iter()
                .map(|&p| point_ring_distance(p, outer))
                .fold(f64::INFINITY, f64::min)
        };
        for m in &map.buildings {
            let kept = outlines.buildings.iter().find(|b| b.osm_id == m.osm_id);
            assert_eq!(kept.is_some(), distance(&m.outer) <= reach, "{}", m.osm_id);
            if let Some(b) = kept {
                // serde_json reads floats to within an ulp or so.
                assert_eq!(b.outer.len(), m.outer.len());
                for (p, q) in b.outer.iter().zip(&m.outer) {
                    assert!((p[0] - q[0]).abs() < 1e-9 && (p[1] - q[1]).abs() < 1e-9);
                }
            }
        }
        std::fs::remove_dir_all(&dir).ok();
    }
}
