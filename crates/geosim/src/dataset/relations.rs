//! The `relations` kind: viewpoint scenes with the true oriented box of every object seen
//! and the true and annotated spatial relations (On, LeftOf, Behind) of every pair.

use super::{io_err, scan_poses, write_json, DatasetSummary};
use crate::scene::{Pose, Scene, SceneObject, SceneOptions};
use crate::sensor::{ScanFrame, SensorOptions};
use crate::{purpose, stream_rng, SimError};
use geodata::classes::Class;
use geodata::cloud::{write_cloud, PointCloud};
use geodata::osm::geometry::{longest_edge_box, point_ring_distance, ring_bounds};
use geodata::osm::OsmMap;
use geodata::simfiles::{MapBuilding, MapBuildings, MAP_BUILDINGS_FILE};
use rand::Rng;
use serde::Serialize;
use serde_json::json;
use std::collections::BTreeMap;
use std::path::Path;

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
            let [a, b] = crate::truth::offset_centre_line(seg, t);
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
    let mut pair_count = 0usize;
    let mut true_counts = [0usize; 3];
    let each = |i: usize, pose: &Pose, cloud: PointCloud| {
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
        Ok(())
    };
    let frame = ScanFrame::World;
    let summary = scan_poses(&scene, &poses, &options.sensor, frame, seed, progress, each)?;
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
            "map_error": super::map_error_meta(&scene, &options.scene.map_error),
            "summary": summary,
        }),
    )?;
    Ok(summary)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::dataset::test_support::map;
    use serde_json::Value;

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
        // The dataset names its map-error model (off by default: nothing removed or added).
        assert_eq!(meta["map_error"]["removed_buildings"], json!(0));
        assert_eq!(meta["map_error"]["extra_buildings"], json!(0));
        assert!(meta["map_error"]["options"].is_object(), "{meta}");
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
