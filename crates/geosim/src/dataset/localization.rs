//! The `localization` kind: single scans in the sensor frame from sidewalk (or car) poses
//! among map buildings, with the true pose of each in the map's and the world's frame.

use super::{drive_route, io_err, route_poses, scan_poses, write_json, DatasetSummary};
use crate::scene::{MapErrorOptions, Pose, Scene, SceneOptions};
use crate::sensor::{ScanFrame, SensorOptions};
use crate::{mix64, SimError};
use geodata::cloud::{write_cloud, PointCloud};
use geodata::osm::OsmMap;
use geodata::sensors::SensorKind;
use geodata::simfiles::TruthPose;
use serde_json::json;
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
    let each = |i: usize, pose: &Pose, cloud: PointCloud| {
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
        Ok(())
    };
    let frame = ScanFrame::Sensor;
    let summary = scan_poses(&scene, &poses, &options.sensor, frame, seed, progress, each)?;
    write_json(&out.join("truth.json"), &truth)?;
    let (lat0, lon0) = scene.frame.origin();
    let mut map_error = super::map_error_meta(&scene, &options.scene.map_error);
    map_error["field"] = json!(scene.map_error.field);
    map_error["truth_frame"] = json!("map: x, y, yaw, yaw_grid, lat, lon are the world pose p mapped to p + D(p) and turned by the field's local rotation; world_* are the pose in the simulated world");
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
            "map_error": map_error,
            "summary": summary,
        }),
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::test_support::{fast_sensor, map};
    use geodata::classes::Class;
    use serde_json::Value;

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
}
