//! The semantic map as files other tools open: one point per occupied cell (its centre) with
//! the class colour, class id and object id, written as PLY (CloudCompare, Rerun, MeshLab
//! show the `red`/`green`/`blue` colours and keep `label` and `object` as scalar fields) or
//! as a ROS 2 bag (MCAP: a `sensor_msgs/msg/PointCloud2` on [`CELLS_TOPIC`] and a Foxglove
//! `foxglove.SceneUpdate` in JSON on [`SCENE_TOPIC`] with one box per object and one line per
//! related pair of objects; Foxglove and `ros2 bag` open it).

use crate::error::Result;
use crate::semantic::SemanticMap;
use geodata::cloud::mcap::JsonMessage;
use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};
use serde_json::{json, Value};
use std::path::Path;

/// The topic of the cells' PointCloud2 message.
pub const CELLS_TOPIC: &str = "/semantic_map/cells";
/// The topic of the objects' and relations' `foxglove.SceneUpdate`.
pub const SCENE_TOPIC: &str = "/semantic_map/objects";
/// The frame every message is in.
pub const FRAME_ID: &str = "map";

/// The JSON Schema written for `foxglove.SceneUpdate` (the outline Foxglove needs; the full
/// message definition is Foxglove's).
const SCENE_UPDATE_SCHEMA: &str = r#"{"title":"foxglove.SceneUpdate","type":"object","properties":{"deletions":{"type":"array"},"entities":{"type":"array"}}}"#;

/// One point per occupied cell, in the map's cell order: the cell centre (f64), the class
/// colour ([`geodata::classes::Class::color_rgb`]), the class id (`label`) and the object id
/// (`object`, 0: none).
pub fn cells_cloud(map: &SemanticMap) -> PointCloud {
    let cells = &map.cells;
    let columns = Columns {
        rgb: true,
        label: true,
        object: true,
        ..Columns::default()
    };
    let occupied = cells.cells().iter().filter(|c| c.occupied());
    let mut cloud = PointCloud::with_columns(columns, Precision::F64, cells.len());
    for c in occupied {
        let class = c.class();
        cloud.push(&PointRecord {
            position: cells.centre(c.key),
            rgb: class.color_rgb(),
            label: class.id(),
            object: c.object,
            ..PointRecord::default()
        });
    }
    cloud
}

/// Writes [`cells_cloud`] as a binary little-endian PLY file (atomically); returns the
/// number of points.
pub fn write_ply(path: &Path, map: &SemanticMap) -> Result<usize> {
    let cloud = cells_cloud(map);
    geodata::cloud::write_cloud_with(
        path,
        &cloud,
        &geodata::cloud::WriteOptions {
            encoding: geodata::cloud::Encoding::BinaryLittleEndian,
        },
    )?;
    Ok(cloud.len())
}

/// A Foxglove colour from 8-bit RGB.
fn colour(rgb: [u8; 3], a: f64) -> Value {
    let c = |v: u8| f64::from(v) / 255.0;
    json!({"r": c(rgb[0]), "g": c(rgb[1]), "b": c(rgb[2]), "a": a})
}

/// A Foxglove point.
fn point(p: [f64; 3]) -> Value {
    json!({"x": p[0], "y": p[1], "z": p[2]})
}

/// The map's objects and relations as a `foxglove.SceneUpdate` (JSON): entity `objects`
/// with one CubePrimitive per object (its oriented box, class colour) and a TextPrimitive
/// naming it (`class #id`), and entity `relations` with one LinePrimitive (LINE_LIST) per
/// relation between object centroids, its relations listed in the entity's metadata.
pub fn scene_update(map: &SemanticMap) -> Value {
    let objects = &map.relations.objects;
    let cubes: Vec<Value> = objects
        .iter()
        .map(|o| {
            let b = &o.bbox;
            let (s, c) = (0.5 * b.yaw_rad).sin_cos();
            json!({
                "pose": {"position": point(b.centre), "orientation": {"x": 0.0, "y": 0.0, "z": s, "w": c}},
                "size": point(b.half_extents.map(|h| 2.0 * h)),
                "color": colour(o.class.color_rgb(), 0.4),
            })
        })
        .collect();
    let texts: Vec<Value> = objects
        .iter()
        .map(|o| {
            let mut top = o.bbox.centre;
            top[2] += o.bbox.half_extents[2] + 0.3;
            json!({
                "pose": {"position": point(top), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
                "billboard": true,
                "font_size": 14.0,
                "scale_invariant": true,
                "color": colour([255, 255, 255], 1.0),
                "text": format!("{} #{}", o.class.name(), o.id),
            })
        })
        .collect();
    let mut lines = Vec::new();
    let mut metadata = Vec::new();
    for e in &map.relations.edges {
        let (Some(a), Some(b)) = (map.relations.object(e.a), map.relations.object(e.b)) else {
            continue;
        };
        let names: Vec<&str> = e.relations().iter().map(|r| r.name()).collect();
        metadata.push(json!({"key": format!("{} {}", e.a, e.b), "value": names.join(",")}));
        lines.push(json!({
            "type": 2,
            "pose": {"position": point([0.0; 3]), "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}},
            "thickness": 0.05,
            "scale_invariant": false,
            "points": [point(a.centroid), point(b.centroid)],
            "color": colour([255, 200, 0], 1.0),
            "colors": [],
            "indices": [],
        }));
    }
    let entity = |id: &str, extra: Value| {
        let mut e = json!({
            "timestamp": {"sec": 0, "nsec": 0},
            "frame_id": FRAME_ID,
            "id": id,
            "lifetime": {"sec": 0, "nsec": 0},
            "frame_locked": true,
            "metadata": [],
            "arrows": [], "cubes": [], "spheres": [], "cylinders": [], "lines": [],
            "triangles": [], "texts": [], "models": [],
        });
        if let (Some(o), Some(x)) = (e.as_object_mut(), extra.as_object()) {
            for (k, v) in x {
                o.insert(k.clone(), v.clone());
            }
        }
        e
    };
    json!({
        "deletions": [],
        "entities": [
            entity("objects", json!({"cubes": cubes, "texts": texts})),
            entity("relations", json!({"lines": lines, "metadata": metadata})),
        ],
    })
}

/// Writes the map as a ROS 2 bag (atomically): [`cells_cloud`] as a PointCloud2 on
/// [`CELLS_TOPIC`] and [`scene_update`] on [`SCENE_TOPIC`], frame [`FRAME_ID`], time 0;
/// returns the number of points.
pub fn write_mcap(path: &Path, map: &SemanticMap) -> Result<usize> {
    let cloud = cells_cloud(map);
    let scene = JsonMessage {
        topic: SCENE_TOPIC.into(),
        schema_name: "foxglove.SceneUpdate".into(),
        schema: SCENE_UPDATE_SCHEMA.into(),
        message: scene_update(map),
    };
    geodata::cloud::mcap::write_bag_cloud(path, CELLS_TOPIC, FRAME_ID, &cloud, 0, &[scene])?;
    Ok(cloud.len())
}
