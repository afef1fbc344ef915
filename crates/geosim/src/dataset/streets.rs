//! The `streets` kind: scans along a drive registered into one labelled cloud, with the
//! true offset, width and sidewalk of every street segment.

use super::{drive_route, io_err, route_poses, scan_poses, write_json, DatasetSummary};
use crate::scene::{Pose, Scene, SceneOptions};
use crate::sensor::{ScanFrame, SensorOptions};
use crate::SimError;
use geodata::classes::Class;
use geodata::cloud::{write_cloud, PointCloud};
use geodata::osm::OsmMap;
use serde_json::{json, Value};
use std::path::Path;

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
    let mut cloud = PointCloud::default();
    let each = |i: usize, _: &Pose, part: PointCloud| {
        if i == 0 {
            cloud = part;
        } else {
            cloud.extend(&part);
        }
        Ok(())
    };
    let frame = ScanFrame::World;
    let summary = scan_poses(&scene, &poses, &options.sensor, frame, seed, progress, each)?;
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
            "map_error": super::map_error_meta(&scene, &options.scene.map_error),
            "summary": summary,
        }),
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::test_support::{fast_sensor, map};

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
        let meta: Value =
            serde_json::from_slice(&std::fs::read(dir.join("dataset.json")).unwrap()).unwrap();
        assert_eq!(meta["map_error"]["removed_buildings"], json!(0), "{meta}");
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
            let (along, u) = seg.coordinates([p[0], p[1]]);
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
