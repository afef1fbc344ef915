//! The semantic map exported as PLY: read back by geodata's reader and by an independent
//! minimal PLY parser written here.
#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::classes::Class;
use geodata::cloud::{Columns, PointCloud, PointRecord, Precision};
use srtree::map::{MapOptions, SrMap};
use srtree::objects::ObjectOptions;
use srtree::semantic::SemanticMap;
use std::path::PathBuf;

/// A small labelled scene: a car (object 1), a pole (object 2), street ground (object 0).
pub fn scene() -> SemanticMap {
    let columns = Columns {
        label: true,
        object: true,
        ..Columns::default()
    };
    let mut cloud = PointCloud::with_columns(columns, Precision::F64, 0);
    let mut add = |p: [f64; 3], class: Class, object: u32| {
        cloud.push(&PointRecord {
            position: p,
            label: class.id(),
            object,
            ..PointRecord::default()
        })
    };
    for i in 0..20 {
        for j in 0..10 {
            add([i as f64 * 0.25, j as f64 * 0.25, 0.0], Class::Street, 0);
        }
    }
    for i in 0..8 {
        for j in 0..4 {
            for k in 0..3 {
                let p = [
                    1.0 + i as f64 * 0.25,
                    0.5 + j as f64 * 0.25,
                    0.3 + k as f64 * 0.25,
                ];
                add(p, Class::Car, 1);
            }
        }
    }
    for k in 0..12 {
        add([4.0, 2.0, 0.25 * k as f64], Class::Pole, 2);
    }
    let mut map = SrMap::new(MapOptions {
        resolution_m: 0.25,
        ..MapOptions::default()
    })
    .unwrap();
    map.insert_cloud(&cloud, None).unwrap();
    SemanticMap::with_objects(map, &ObjectOptions::default())
}

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("srtree-export-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

/// A minimal binary little-endian PLY vertex reader: (property names, rows as f64).
fn parse_ply(bytes: &[u8]) -> (Vec<String>, Vec<Vec<f64>>) {
    let end = bytes
        .windows(11)
        .position(|w| w == b"end_header\n")
        .unwrap()
        + 11;
    let header = std::str::from_utf8(&bytes[..end]).unwrap();
    let mut lines = header.lines();
    assert_eq!(lines.next(), Some("ply"));
    let (mut count, mut props) = (0usize, Vec::<(String, String)>::new());
    for line in lines {
        let f: Vec<&str> = line.split_whitespace().collect();
        match f.as_slice() {
            ["format", fmt, "1.0"] => assert_eq!(*fmt, "binary_little_endian"),
            ["element", "vertex", n] => count = n.parse().unwrap(),
            ["element", other, ..] => panic!("unexpected element {other}"),
            ["property", ty, name] => props.push((ty.to_string(), name.to_string())),
            _ => {}
        }
    }
    let size = |ty: &str| match ty {
        "double" => 8,
        "float" | "uint" | "int" => 4,
        "uchar" | "char" => 1,
        "ushort" | "short" => 2,
        t => panic!("type {t}"),
    };
    let mut at = end;
    let mut rows = Vec::with_capacity(count);
    for _ in 0..count {
        let mut row = Vec::with_capacity(props.len());
        for (ty, _) in &props {
            let b = &bytes[at..at + size(ty)];
            row.push(match ty.as_str() {
                "double" => f64::from_le_bytes(b.try_into().unwrap()),
                "float" => f64::from(f32::from_le_bytes(b.try_into().unwrap())),
                "uint" => f64::from(u32::from_le_bytes(b.try_into().unwrap())),
                "uchar" => f64::from(b[0]),
                t => panic!("type {t}"),
            });
            at += size(ty);
        }
        rows.push(row);
    }
    assert_eq!(at, bytes.len(), "trailing bytes");
    (props.into_iter().map(|(_, n)| n).collect(), rows)
}

#[test]
fn ply_export_reads_back_with_class_colour_and_object() {
    let map = scene();
    let cloud = srtree::export::cells_cloud(&map);
    let occupied = map.cells.cells().iter().filter(|c| c.occupied()).count();
    assert_eq!(cloud.len(), occupied);
    assert!(occupied > 100, "{occupied}");
    let path = temp("map.ply");
    assert_eq!(srtree::export::write_ply(&path, &map).unwrap(), occupied);

    // geodata's reader.
    let back = geodata::cloud::read_cloud(&path).unwrap();
    assert_eq!(back.positions, cloud.positions);
    assert_eq!(back.label, cloud.label);
    assert_eq!(back.object, cloud.object);
    assert_eq!(back.rgb, cloud.rgb);

    // An independent parse of the bytes.
    let (names, rows) = parse_ply(&std::fs::read(&path).unwrap());
    assert_eq!(
        names,
        ["x", "y", "z", "red", "green", "blue", "label", "object"]
    );
    assert_eq!(rows.len(), occupied);
    let mut classes = std::collections::BTreeSet::new();
    let mut objects = std::collections::BTreeSet::new();
    for (i, r) in rows.iter().enumerate() {
        assert_eq!([r[0], r[1], r[2]], cloud.positions[i]);
        let class = Class::from_id(r[6] as u8).unwrap();
        let rgb = class.color_rgb();
        assert_eq!([r[3], r[4], r[5]], rgb.map(f64::from));
        // The centre lies in a cell of this class and object.
        let cell = map
            .cells
            .cell_at_key(map.cells.key_of(cloud.positions[i]))
            .unwrap();
        assert_eq!(cell.class(), class);
        assert_eq!(f64::from(cell.object), r[7]);
        classes.insert(class);
        objects.insert(r[7] as u32);
    }
    assert!(classes.contains(&Class::Car) && classes.contains(&Class::Pole));
    assert!(objects.contains(&1) && objects.contains(&2));
    std::fs::remove_file(&path).ok();
}

#[test]
fn mcap_export_reads_back_with_mcap_and_urbansem() {
    use srtree::graph::{Relation, RelationEdge};
    let mut map = scene();
    map.relations.edges.push(RelationEdge {
        a: 1,
        b: 2,
        bits: Relation::On.bit() | Relation::Behind.bit(),
    });
    let cloud = srtree::export::cells_cloud(&map);
    let path = temp("map.mcap");
    assert_eq!(
        srtree::export::write_mcap(&path, &map).unwrap(),
        cloud.len()
    );

    // urbansem's reader (the only PointCloud2 topic).
    let back = geodata::cloud::read_cloud(&path).unwrap();
    assert_eq!(back.positions, cloud.positions);
    assert_eq!(back.rgb, cloud.rgb);
    assert_eq!(back.label, cloud.label);
    assert_eq!(back.object, cloud.object);

    // The mcap crate's reader: the two topics, their encodings and the scene.
    let bytes = std::fs::read(&path).unwrap();
    let messages: Vec<_> = mcap::MessageStream::new(&bytes)
        .unwrap()
        .map(|m| m.unwrap())
        .collect();
    assert_eq!(messages.len(), 2);
    assert_eq!(messages[0].channel.topic, srtree::export::CELLS_TOPIC);
    let schema = messages[0].channel.schema.as_ref().unwrap();
    assert_eq!(
        (schema.name.as_str(), schema.encoding.as_str()),
        ("sensor_msgs/msg/PointCloud2", "ros2msg")
    );
    assert!(std::str::from_utf8(&schema.data)
        .unwrap()
        .contains("MSG: sensor_msgs/PointField"));
    let s = &messages[1];
    assert_eq!(s.channel.topic, srtree::export::SCENE_TOPIC);
    assert_eq!(s.channel.message_encoding, "json");
    let schema = s.channel.schema.as_ref().unwrap();
    assert_eq!(
        (schema.name.as_str(), schema.encoding.as_str()),
        ("foxglove.SceneUpdate", "jsonschema")
    );
    let v: serde_json::Value = serde_json::from_slice(&s.data).unwrap();
    let objects = &v["entities"][0];
    assert_eq!(objects["frame_id"], "map");
    let cubes = objects["cubes"].as_array().unwrap();
    assert_eq!(cubes.len(), map.relations.objects.len());
    assert!(cubes.len() >= 2);
    for c in cubes {
        assert!(c["size"]["x"].as_f64().unwrap() > 0.0);
        let q = &c["pose"]["orientation"];
        let norm: f64 = ["x", "y", "z", "w"]
            .iter()
            .map(|k| q[k].as_f64().unwrap().powi(2))
            .sum();
        assert!((norm - 1.0).abs() < 1e-9);
    }
    let lines = v["entities"][1]["lines"].as_array().unwrap();
    assert_eq!(lines.len(), 1);
    assert_eq!(lines[0]["points"].as_array().unwrap().len(), 2);
    assert_eq!(v["entities"][1]["metadata"][0]["value"], "On,Behind");
    std::fs::remove_file(&path).ok();
}
