//! Simulated datasets with exact ground truth, written as PLY + JSON.
//!
//! Every dataset folder has a `dataset.json` with `kind`, `map` (the map path as given),
//! `seed`, the options used and what the simulator changed. Coordinates are in the local
//! frame of `OsmMap::load(map)` (east, north, up in metres); yaws are radians
//! counter-clockwise. The kinds:
//!
//! - **localization** ([`write_localization`]): `scan_000.ply` … in the gravity-levelled
//!   sensor frame (origin at the sensor, x along the heading, z up) and `truth.json`
//!   mapping each scan file name to `{"x", "y", "z", "yaw", "lat", "lon", "yaw_grid"}`:
//!   `x`, `y`, `z` the sensor origin in the local frame, `yaw` from *geographic* east
//!   (grid yaw plus meridian convergence), `yaw_grid` from the local frame's x axis. The
//!   world carries the OSM map-error model unless disabled.
//! - **streets** ([`write_streets`]): scans every `spacing_m` along a route driven on the
//!   true street centre lines, registered into one `cloud.ply` in the local frame (labels:
//!   street = driving area, sidewalk, …), `segments.json` — one entry per segment of
//!   `map.streets.segments` in order, `{"segment", "offset_m", "width_m", "sidewalk_m",
//!   "drivable", "observed", "points"}` (see [`super::truth`] for the offset convention;
//!   `points` counts the cloud's driving-area points of the segment, `observed` is
//!   `points ≥ 200`) — and the scan poses in `dataset.json` (`poses`).

use super::scene::{MapErrorOptions, Pose, Scene, SceneOptions};
use super::sensor::{scan_with, ScanFrame, SensorOptions};
use super::{mix64, purpose, stream_rng, SimError};
use crate::classes::Class;
use crate::cloud::{write_cloud, PointCloud};
use crate::osm::OsmMap;
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
        }
    }
}

/// The true pose of one localization scan as written to `truth.json`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct TruthPose {
    /// Sensor origin east, metres in the local frame.
    pub x: f64,
    /// Sensor origin north, metres in the local frame.
    pub y: f64,
    /// Sensor origin height above the street surface, metres.
    pub z: f64,
    /// Heading counter-clockwise from geographic east, radians.
    pub yaw: f64,
    /// WGS84 latitude, degrees.
    pub lat: f64,
    /// WGS84 longitude, degrees.
    pub lon: f64,
    /// Heading counter-clockwise from the local frame's x axis, radians.
    pub yaw_grid: f64,
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
    /// Seconds spent ray casting.
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
    std::fs::write(path, text + "\n").map_err(io_err(path))
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
    let poses = scene.sample_poses_with_height(options.scans, options.sensor_height_m, seed)?;
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
        let xy = [pose.position[0], pose.position[1]];
        let (lat, lon) = scene.frame.to_wgs84(xy);
        truth.insert(
            name,
            TruthPose {
                x: pose.position[0],
                y: pose.position[1],
                z: pose.position[2],
                yaw: pose.yaw_rad + scene.frame.convergence_rad(xy),
                lat,
                lon,
                yaw_grid: pose.yaw_rad,
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
            "sensor_height_m": options.sensor_height_m,
            "map_error": {
                "options": options.scene.map_error,
                "removed_buildings": scene.map_error.removed.len(),
                "extra_buildings": scene.map_error.extra,
                "mean_shift_m": scene.map_error.mean_shift_m,
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
    let mut poses = Vec::new();
    let mut carry = 0.0;
    for &(s, forward) in &route {
        let seg = &scene.segments[s];
        let [a, b] = super::truth::offset_centre_line(seg, &scene.truth[s]);
        let (p0, p1) = if forward { (a, b) } else { (b, a) };
        let yaw = (p1[1] - p0[1]).atan2(p1[0] - p0[0]);
        let mut t = carry;
        while t <= seg.length_m {
            let f = t / seg.length_m;
            let p = [p0[0] + f * (p1[0] - p0[0]), p0[1] + f * (p1[1] - p0[1])];
            if scene.clear_of_shapes(p, 1.0) && !scene.inside_building(p) {
                let z = scene.ground_at(p).z + options.sensor_height_m;
                poses.push(Pose {
                    position: [p[0], p[1], z],
                    yaw_rad: yaw,
                });
            }
            t += options.spacing_m;
        }
        carry = t - seg.length_m;
        if options.max_scans > 0 && poses.len() >= options.max_scans {
            poses.truncate(options.max_scans);
            break;
        }
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::city::{generate_city, CityOptions};

    fn map() -> OsmMap {
        let xml = generate_city(
            &CityOptions {
                size_m: 400.0,
                ..CityOptions::default()
            },
            8,
        )
        .unwrap();
        OsmMap::from_xml_str(&xml).unwrap()
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
        for key in ["x", "y", "z", "yaw", "lat", "lon"] {
            assert!(pose[key].is_f64(), "{key} missing");
        }
        let cloud = crate::cloud::read_cloud(a.join("scan_000.ply")).unwrap();
        assert!(cloud.len() > 500);
        std::fs::remove_dir_all(&dir).ok();
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
        let cloud = crate::cloud::read_cloud(dir.join("cloud.ply")).unwrap();
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
}
