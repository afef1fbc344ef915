//! ROS 2 bags (issue 18): bags written here with the `mcap` crate's writer from real KITTI-360
//! scans, in several PointCloud2 layouts and chunk compressions, read back to the same points;
//! malformed bags give an error naming the bag, never a panic.

#![allow(clippy::unwrap_used, clippy::expect_used)]

use geodata::cloud::error::MessageProblem;
use geodata::cloud::kitti::read_kitti_bin;
use geodata::cloud::mcap::{
    bag_info, read_bag_cloud, read_bag_cloud_at, read_bag_poses, Pick, ODOMETRY, POINT_CLOUD2,
    TF_MESSAGE,
};
use geodata::cloud::{
    read_cloud, read_cloud_with, CloudError, Columns, PointCloud, PointRecord, Precision,
    ReadOptions,
};
use mcap::records::MessageHeader;
use mcap::{Compression, WriteOptions};
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

/// A scratch directory removed when dropped.
struct TmpDir(PathBuf);

impl TmpDir {
    fn join(&self, name: impl AsRef<Path>) -> PathBuf {
        self.0.join(name)
    }
}

impl Drop for TmpDir {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn tmp_dir(name: &str) -> TmpDir {
    let d = std::env::temp_dir().join(format!("urbansem-mcap-{}-{name}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    TmpDir(d)
}

fn data_file(rel: &str) -> PathBuf {
    let p = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../../../shared/data")).join(rel);
    assert!(p.exists(), "missing shared data: {}", p.display());
    p
}

/// A KITTI-360 Velodyne scan (f32 x y z reflectance).
fn kitti360_scan(frame: u32) -> PointCloud {
    let path = data_file(&format!(
        "lidar/kitti360_2013_05_28_drive_0009/velodyne_points/{frame:010}.bin"
    ));
    read_kitti_bin(&path, &ReadOptions::default()).unwrap().0
}

/// PointField datatypes.
const UINT8: u8 = 2;
const UINT16: u8 = 4;
const FLOAT32: u8 = 7;
const FLOAT64: u8 = 8;

/// One PointField.
#[derive(Clone)]
struct Field {
    name: &'static str,
    offset: u32,
    datatype: u8,
}

/// A PointCloud2 layout and how to write one point's values into it.
#[derive(Clone)]
struct Layout {
    fields: Vec<Field>,
    point_step: u32,
    /// Point data big-endian (`is_bigendian`).
    big_endian_data: bool,
    /// CDR encapsulation big-endian.
    big_endian_cdr: bool,
}

/// x y z intensity as FLOAT32, 16 bytes a point: what KITTI's Velodyne driver publishes.
fn kitti_layout() -> Layout {
    Layout {
        fields: vec![
            Field {
                name: "x",
                offset: 0,
                datatype: FLOAT32,
            },
            Field {
                name: "y",
                offset: 4,
                datatype: FLOAT32,
            },
            Field {
                name: "z",
                offset: 8,
                datatype: FLOAT32,
            },
            Field {
                name: "intensity",
                offset: 12,
                datatype: FLOAT32,
            },
        ],
        point_step: 16,
        big_endian_data: false,
        big_endian_cdr: false,
    }
}

/// x y z FLOAT64, intensity and ring UINT16, t FLOAT32, padded to 40 bytes (Ouster-like).
fn ouster_layout() -> Layout {
    Layout {
        fields: vec![
            Field {
                name: "x",
                offset: 0,
                datatype: FLOAT64,
            },
            Field {
                name: "y",
                offset: 8,
                datatype: FLOAT64,
            },
            Field {
                name: "z",
                offset: 16,
                datatype: FLOAT64,
            },
            Field {
                name: "intensity",
                offset: 24,
                datatype: UINT16,
            },
            Field {
                name: "ring",
                offset: 26,
                datatype: UINT16,
            },
            Field {
                name: "t",
                offset: 28,
                datatype: FLOAT32,
            },
        ],
        point_step: 40,
        big_endian_data: false,
        big_endian_cdr: false,
    }
}

/// The KITTI layout with big-endian point data in a big-endian CDR message.
fn big_endian_layout() -> Layout {
    Layout {
        big_endian_data: true,
        big_endian_cdr: true,
        ..kitti_layout()
    }
}

/// CDR writer: primitives aligned to their size, counted from after the 4-byte header.
struct Cdr {
    buf: Vec<u8>,
    big_endian: bool,
}

impl Cdr {
    fn new(big_endian: bool) -> Self {
        let id = if big_endian { 0u8 } else { 1u8 };
        Self {
            buf: vec![0, id, 0, 0],
            big_endian,
        }
    }
    fn align(&mut self, n: usize) {
        while (self.buf.len() - 4) % n != 0 {
            self.buf.push(0);
        }
    }
    fn u8(&mut self, v: u8) {
        self.buf.push(v);
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.buf.extend_from_slice(&b);
    }
    fn string(&mut self, s: &str) {
        self.u32(s.len() as u32 + 1);
        self.buf.extend_from_slice(s.as_bytes());
        self.buf.push(0);
    }
    fn f64(&mut self, v: f64) {
        self.align(8);
        let b = if self.big_endian {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.buf.extend_from_slice(&b);
    }
    fn header(&mut self, stamp_s: u32, frame: &str) {
        self.u32(stamp_s);
        self.u32(0);
        self.string(frame);
    }
    fn pose(&mut self, xyz: [f64; 3], yaw: f64) {
        for v in xyz {
            self.f64(v);
        }
        for v in [0.0, 0.0, (yaw / 2.0).sin(), (yaw / 2.0).cos()] {
            self.f64(v);
        }
    }
}

/// Writes value `v` of `datatype` at `at`.
fn put(point: &mut [u8], at: u32, datatype: u8, v: f64, big_endian: bool) {
    let bytes: Vec<u8> = match (datatype, big_endian) {
        (FLOAT32, false) => (v as f32).to_le_bytes().to_vec(),
        (FLOAT32, true) => (v as f32).to_be_bytes().to_vec(),
        (FLOAT64, false) => v.to_le_bytes().to_vec(),
        (FLOAT64, true) => v.to_be_bytes().to_vec(),
        (UINT16, false) => (v as u16).to_le_bytes().to_vec(),
        (UINT16, true) => (v as u16).to_be_bytes().to_vec(),
        (UINT8, _) => vec![v as u8],
        _ => unreachable!("datatype {datatype}"),
    };
    point[at as usize..at as usize + bytes.len()].copy_from_slice(&bytes);
}

/// The value a layout field takes for point `i` of `cloud`.
fn value_of(name: &str, cloud: &PointCloud, i: usize) -> f64 {
    let p = cloud.positions[i];
    match name {
        "x" => p[0],
        "y" => p[1],
        "z" => p[2],
        "intensity" => f64::from(cloud.intensity.as_ref().map_or(0.0, |v| v[i])),
        "label" => f64::from(cloud.label.as_ref().map_or(0, |v| v[i])),
        "ring" => (i % 64) as f64,
        "t" => i as f64 * 1e-6,
        _ => 0.0,
    }
}

/// A PointCloud2 message of `cloud` in `layout`; `width` overrides the point count claimed.
fn encode(cloud: &PointCloud, layout: &Layout, width: Option<u32>) -> Vec<u8> {
    let mut w = Cdr::new(layout.big_endian_cdr);
    w.u32(1_369_000_000); // stamp.sec
    w.u32(250_000_000); // stamp.nanosec
    w.string("velodyne");
    w.u32(1); // height
    w.u32(width.unwrap_or(cloud.len() as u32));
    w.u32(layout.fields.len() as u32);
    for f in &layout.fields {
        w.string(f.name);
        w.u32(f.offset);
        w.u8(f.datatype);
        w.u32(1);
    }
    w.u8(u8::from(layout.big_endian_data));
    w.u32(layout.point_step);
    let width = width.unwrap_or(cloud.len() as u32);
    w.u32(width.wrapping_mul(layout.point_step)); // row_step
    let mut data = vec![0u8; cloud.len() * layout.point_step as usize];
    for (i, point) in data.chunks_mut(layout.point_step as usize).enumerate() {
        for f in &layout.fields {
            put(
                point,
                f.offset,
                f.datatype,
                value_of(f.name, cloud, i),
                layout.big_endian_data,
            );
        }
    }
    w.u32(data.len() as u32);
    w.buf.extend_from_slice(&data);
    w.u8(1); // is_dense
    w.buf
}

/// A std_msgs/msg/String message.
fn encode_string(text: &str) -> Vec<u8> {
    let mut w = Cdr::new(false);
    w.string(text);
    w.buf
}

/// One message to write: topic, schema, CDR bytes.
struct Message {
    topic: &'static str,
    schema: &'static str,
    data: Vec<u8>,
}

/// Writes `messages` as a rosbag2-style MCAP bag with `compression` (small chunks, so that a
/// scan spans several).
fn write_bag(path: &Path, messages: &[Message], compression: Option<Compression>) {
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    let mut w = WriteOptions::new()
        .profile("ros2")
        .compression(compression)
        .chunk_size(Some(256 * 1024))
        .create(file)
        .unwrap();
    let mut channels: BTreeMap<&str, u16> = BTreeMap::new();
    for (seq, m) in messages.iter().enumerate() {
        let channel_id = match channels.get(m.topic) {
            Some(&id) => id,
            None => {
                let schema_id = w.add_schema(m.schema, "ros2msg", b"").unwrap();
                let id = w
                    .add_channel(schema_id, m.topic, "cdr", &BTreeMap::new())
                    .unwrap();
                channels.insert(m.topic, id);
                id
            }
        };
        let header = MessageHeader {
            channel_id,
            sequence: seq as u32,
            log_time: 1_000 + seq as u64,
            publish_time: 1_000 + seq as u64,
        };
        w.write_to_known_channel(&header, &m.data).unwrap();
    }
    w.finish().unwrap();
}

/// What reading `cloud` back through the Ouster layout gives: positions as written (f64),
/// intensity as the UINT16 written.
fn ouster_expected(cloud: &PointCloud) -> PointCloud {
    let mut out = PointCloud::with_columns(
        Columns {
            intensity: true,
            ..Columns::default()
        },
        Precision::F64,
        cloud.len(),
    );
    for i in 0..cloud.len() {
        out.push(&PointRecord {
            position: ouster_position(cloud.positions[i]),
            intensity: f32::from(ouster_intensity(cloud, i)),
            ..PointRecord::default()
        });
    }
    out
}

/// Ouster-layout positions: shifted off the f32 grid, so that only f64 holds them.
fn ouster_position(p: [f64; 3]) -> [f64; 3] {
    [p[0] + 0.1, p[1] - 0.1, p[2] + 1e-9]
}

/// Ouster-layout intensity: KITTI reflectance scaled to UINT16.
fn ouster_intensity(cloud: &PointCloud, i: usize) -> u16 {
    (cloud.intensity.as_ref().unwrap()[i] * 65_535.0).round() as u16
}

/// The cloud as the Ouster layout's encoder sees it.
fn ouster_source(cloud: &PointCloud) -> PointCloud {
    let mut src = cloud.clone();
    for (i, p) in src.positions.iter_mut().enumerate() {
        *p = ouster_position(cloud.positions[i]);
    }
    src.intensity = Some(
        (0..cloud.len())
            .map(|i| f32::from(ouster_intensity(cloud, i)))
            .collect(),
    );
    src
}

/// Two KITTI-360 scans on two point cloud topics (KITTI and Ouster layouts) plus a
/// `std_msgs/msg/String` topic, interleaved.
fn two_topic_messages(a: &PointCloud, b: &PointCloud) -> Vec<Message> {
    let velodyne = |c: &PointCloud| Message {
        topic: "/velodyne_points",
        schema: POINT_CLOUD2,
        data: encode(c, &kitti_layout(), None),
    };
    let ouster = |c: &PointCloud| Message {
        topic: "/ouster/points",
        schema: POINT_CLOUD2,
        data: encode(&ouster_source(c), &ouster_layout(), None),
    };
    let chatter = |text: &str| Message {
        topic: "/chatter",
        schema: "std_msgs/msg/String",
        data: encode_string(text),
    };
    vec![
        chatter("start"),
        velodyne(a),
        ouster(b),
        chatter("between"),
        velodyne(b),
        ouster(a),
    ]
}

#[test]
fn two_topics_read_back_identically_with_every_chunk_compression() {
    let a = kitti360_scan(2000);
    let b = kitti360_scan(2040);
    assert!(a.len() > 50_000 && b.len() > 50_000);
    let dir = tmp_dir("two-topics");
    let messages = two_topic_messages(&a, &b);
    for (name, compression) in [
        ("none.mcap", None),
        ("zstd.mcap", Some(Compression::Zstd)),
        ("lz4.mcap", Some(Compression::Lz4)),
    ] {
        let bag = dir.join(name);
        write_bag(&bag, &messages, compression);
        let read = |topic: &str, index: usize| {
            read_bag_cloud(&bag, Some(topic), index, &ReadOptions::default()).unwrap()
        };
        // KITTI layout: every f32 coordinate and intensity bit for bit.
        for (index, scan) in [(0, &a), (1, &b)] {
            let (cloud, report) = read("/velodyne_points", index);
            assert_eq!(&cloud, scan, "{name} /velodyne_points {index}");
            assert_eq!(cloud.precision, Precision::F32);
            assert_eq!(report.points_in_file, scan.len());
        }
        // Ouster layout: f64 positions equal to the f64 written, UINT16 intensity.
        for (index, scan) in [(0, &b), (1, &a)] {
            let (cloud, _) = read("/ouster/points", index);
            assert_eq!(
                cloud,
                ouster_expected(scan),
                "{name} /ouster/points {index}"
            );
        }

        let info = bag_info(&bag).unwrap();
        let topics: Vec<(&str, usize, &str)> = info
            .topics
            .iter()
            .map(|t| (t.topic.as_str(), t.messages, t.schema.as_str()))
            .collect();
        assert_eq!(
            topics,
            [
                ("/chatter", 2, "std_msgs/msg/String"),
                ("/ouster/points", 2, POINT_CLOUD2),
                ("/velodyne_points", 2, POINT_CLOUD2),
            ],
            "{name}"
        );
        assert!(info.topics.iter().all(|t| t.message_encoding == "cdr"));
        assert!(info.topics[0].cloud.is_none());
        let ouster = info.topics[1].cloud.as_ref().unwrap();
        assert_eq!(
            (ouster.width, ouster.height, ouster.point_step),
            (b.len() as u32, 1, 40)
        );
        let fields: Vec<(&str, u32, u8, u32)> = ouster
            .fields
            .iter()
            .map(|f| (f.name.as_str(), f.offset, f.datatype, f.count))
            .collect();
        assert_eq!(
            fields,
            [
                ("x", 0, FLOAT64, 1),
                ("y", 8, FLOAT64, 1),
                ("z", 16, FLOAT64, 1),
                ("intensity", 24, UINT16, 1),
                ("ring", 26, UINT16, 1),
                ("t", 28, FLOAT32, 1),
            ]
        );
        let text = info.text();
        assert!(
            text.contains("/velodyne_points  2 messages  sensor_msgs/msg/PointCloud2 (cdr)"),
            "{text}"
        );
        assert!(text.contains("ring:UINT16@26"), "{text}");
        let json = serde_json::to_value(&info).unwrap();
        assert_eq!(json["topics"][2]["cloud"]["fields"][3]["name"], "intensity");

        // Without a topic the choice is ambiguous: the error lists both.
        let e = read_bag_cloud(&bag, None, 0, &ReadOptions::default()).unwrap_err();
        assert!(matches!(e, CloudError::Topic { .. }), "{e}");
        let text = e.to_string();
        assert!(
            text.contains(&bag.display().to_string())
                && text.contains("/ouster/points, /velodyne_points"),
            "{text}"
        );
    }
}

#[test]
fn big_endian_data_and_read_cloud_dispatch() {
    let a = kitti360_scan(2000);
    let dir = tmp_dir("big-endian");
    let bag = dir.join("be.mcap");
    let message = Message {
        topic: "/points",
        schema: POINT_CLOUD2,
        data: encode(&a, &big_endian_layout(), None),
    };
    write_bag(&bag, &[message], Some(Compression::Zstd));
    assert_eq!(read_cloud(&bag).unwrap(), a);
    let info = bag_info(&bag).unwrap();
    assert!(info.topics[0].cloud.as_ref().unwrap().is_bigendian);
    // Writing a bag is not offered.
    let e = geodata::cloud::write_cloud(dir.join("out.mcap"), &a).unwrap_err();
    assert!(matches!(e, CloudError::Unsupported { .. }), "{e}");
}

#[test]
fn labels_and_non_finite_points_follow_the_other_readers() {
    let mut cloud = PointCloud::with_columns(
        Columns {
            intensity: true,
            label: true,
            ..Columns::default()
        },
        Precision::F32,
        3,
    );
    for (i, z) in [0.5, f64::NAN, -1.0].into_iter().enumerate() {
        cloud.push(&PointRecord {
            position: [i as f64, 2.0, z],
            intensity: 0.25,
            label: 3,
            ..PointRecord::default()
        });
    }
    let mut layout = kitti_layout();
    layout.fields.push(Field {
        name: "label",
        offset: 16,
        datatype: UINT8,
    });
    layout.point_step = 20;
    let dir = tmp_dir("nan");
    let bag = dir.join("nan.mcap");
    let message = Message {
        topic: "/points",
        schema: POINT_CLOUD2,
        data: encode(&cloud, &layout, None),
    };
    write_bag(&bag, &[message], None);
    let e = read_bag_cloud(&bag, None, 0, &ReadOptions::default()).unwrap_err();
    match &e {
        CloudError::InMessage {
            topic,
            index: 0,
            source,
        } => {
            assert_eq!(topic, "/points");
            assert!(
                matches!(**source, CloudError::NonFinite { point: 1, .. }),
                "{e}"
            );
        }
        _ => panic!("{e}"),
    }
    assert!(e.to_string().contains(&bag.display().to_string()), "{e}");
    let (back, report) = read_cloud_with(
        &bag,
        &ReadOptions {
            drop_non_finite: true,
        },
    )
    .unwrap();
    assert_eq!((report.points_in_file, report.dropped_non_finite), (3, 1));
    assert_eq!(back, cloud.filter(|i| i != 1));
    assert_eq!(back.label, Some(vec![3, 3]));
}

/// Reads `bag` every way; each must fail with an error naming the bag.
fn assert_fails_naming(bag: &Path, what: &str) -> Vec<CloudError> {
    let mut errors = vec![bag_info(bag).expect_err(what)];
    errors.push(read_bag_cloud(bag, None, 0, &ReadOptions::default()).expect_err(what));
    for e in &errors {
        assert!(
            e.to_string().contains(&bag.display().to_string()),
            "{what}: {e}"
        );
    }
    errors
}

#[test]
fn truncated_and_foreign_files_are_errors_naming_the_bag() {
    let a = kitti360_scan(2000);
    let dir = tmp_dir("truncated");
    let whole = dir.join("whole.mcap");
    let message = Message {
        topic: "/points",
        schema: POINT_CLOUD2,
        data: encode(&a, &kitti_layout(), None),
    };
    for compression in [None, Some(Compression::Zstd), Some(Compression::Lz4)] {
        write_bag(&whole, std::slice::from_ref(&message), compression);
        let bytes = std::fs::read(&whole).unwrap();
        let n = bytes.len();
        for cut in [0, 4, 8, 20, 200, n / 3, n / 2, n - 200, n - 9, n - 1] {
            let bag = dir.join(format!("cut-{cut}.mcap"));
            std::fs::write(&bag, &bytes[..cut]).unwrap();
            let errors = assert_fails_naming(&bag, &format!("cut at {cut} of {n}"));
            assert!(
                matches!(errors[0], CloudError::Mcap { .. }),
                "{}",
                errors[0]
            );
            // A cut inside the message's chunk fails for the named topic too.
            if cut < n / 2 {
                assert!(read_bag_cloud(&bag, Some("/points"), 0, &ReadOptions::default()).is_err());
            }
        }
    }
    let ply = dir.join("not-a-bag.mcap");
    std::fs::write(
        &ply,
        b"ply\nformat ascii 1.0\nelement vertex 0\nend_header\n",
    )
    .unwrap();
    let errors = assert_fails_naming(&ply, "a PLY file");
    assert!(
        matches!(errors[0], CloudError::Mcap { .. }),
        "{}",
        errors[0]
    );
}

#[test]
fn wrong_topics_schemas_and_indices_are_named() {
    let a = kitti360_scan(2000);
    let b = kitti360_scan(2040);
    let dir = tmp_dir("topics");
    let bag = dir.join("two.mcap");
    write_bag(&bag, &two_topic_messages(&a, &b), Some(Compression::Lz4));
    let read = |topic: &str, index: usize| {
        read_bag_cloud(&bag, Some(topic), index, &ReadOptions::default()).unwrap_err()
    };
    let e = read("/chatter", 0);
    assert!(
        matches!(&e, CloudError::WrongSchema { schema, .. } if schema == "std_msgs/msg/String"),
        "{e}"
    );
    let e = read("/lidar", 0);
    assert!(matches!(e, CloudError::Topic { .. }), "{e}");
    assert!(e.to_string().contains("no topic \"/lidar\""), "{e}");
    let e = read("/velodyne_points", 2);
    assert!(
        matches!(
            e,
            CloudError::NoMessage {
                messages: 2,
                index: 2,
                ..
            }
        ),
        "{e}"
    );
    for e in [
        read("/chatter", 0),
        read("/lidar", 0),
        read("/velodyne_points", 2),
    ] {
        assert!(e.to_string().contains(&bag.display().to_string()), "{e}");
    }
}

/// A one-message bag holding `data` on `/points`.
fn bag_with(dir: &TmpDir, name: &str, data: Vec<u8>) -> PathBuf {
    let bag = dir.join(name);
    write_bag(
        &bag,
        &[Message {
            topic: "/points",
            schema: POINT_CLOUD2,
            data,
        }],
        None,
    );
    bag
}

/// The problem of reading the only message of `bag`.
fn problem(bag: &Path) -> MessageProblem {
    let e = read_bag_cloud(bag, None, 0, &ReadOptions::default()).unwrap_err();
    let text = e.to_string();
    assert!(
        text.contains(&bag.display().to_string()) && text.contains("/points message 0"),
        "{text}"
    );
    match e {
        CloudError::BadMessage { problem, .. } => *problem,
        other => panic!("{other}"),
    }
}

#[test]
fn malformed_point_cloud_messages_are_clear_errors() {
    let mut a = kitti360_scan(2000);
    a.positions.truncate(1000);
    a.intensity.as_mut().unwrap().truncate(1000);
    let dir = tmp_dir("malformed");

    let mut no_z = kitti_layout();
    no_z.fields.retain(|f| f.name != "z");
    let bag = bag_with(&dir, "no-z.mcap", encode(&a, &no_z, None));
    assert!(matches!(
        problem(&bag),
        MessageProblem::MissingField { name: "z", .. }
    ));

    // The header claims one point more than the data holds.
    let bag = bag_with(&dir, "short.mcap", encode(&a, &kitti_layout(), Some(1001)));
    assert!(matches!(
        problem(&bag),
        MessageProblem::DataLength {
            width: 1001,
            data: 16_000,
            ..
        }
    ));

    // 4 G points: an error before any allocation.
    let bag = bag_with(
        &dir,
        "huge.mcap",
        encode(&a, &kitti_layout(), Some(u32::MAX)),
    );
    assert!(matches!(
        problem(&bag),
        MessageProblem::DataLength {
            width: u32::MAX,
            ..
        }
    ));

    // A field past the end of the point.
    let mut outside = kitti_layout();
    outside.fields[3].offset = 14;
    let bag = bag_with(
        &dir,
        "outside.mcap",
        encode(&PointCloud::default(), &outside, None),
    );
    assert!(matches!(
        problem(&bag),
        MessageProblem::FieldOutsidePoint { end: 18, .. }
    ));

    // The message cut anywhere: a truncation error with the field and the bytes left.
    let full = encode(&a, &kitti_layout(), None);
    for cut in [0, 3, 4, 7, 12, 30, 60, 100, full.len() / 2, full.len() - 1] {
        let bag = bag_with(&dir, &format!("cut-{cut}.mcap"), full[..cut].to_vec());
        assert!(
            matches!(problem(&bag), MessageProblem::Truncated { .. }),
            "cut {cut}"
        );
    }

    // Not plain CDR.
    let mut xcdr = full.clone();
    xcdr[1] = 7;
    let bag = bag_with(&dir, "xcdr2.mcap", xcdr);
    assert!(matches!(
        problem(&bag),
        MessageProblem::Encapsulation { id: 7 }
    ));

    // bag_info reports the first message's problem too.
    let e = bag_info(&dir.join("no-z.mcap"));
    assert!(
        e.is_ok(),
        "missing z is a reading problem, not a listing one"
    );
    let e = bag_info(&dir.join("huge.mcap")).unwrap_err();
    assert!(matches!(e, CloudError::BadMessage { .. }), "{e}");
}

/// An Odometry message (`odom` → `base_link`) at `stamp_s` seconds, big- or little-endian CDR.
fn encode_odometry(stamp_s: u32, xyz: [f64; 3], yaw: f64, big_endian: bool) -> Vec<u8> {
    let mut w = Cdr::new(big_endian);
    w.header(stamp_s, "odom");
    w.string("base_link");
    w.pose(xyz, yaw);
    for _ in 0..36 {
        w.f64(0.01); // pose covariance
    }
    for _ in 0..(6 + 36) {
        w.f64(0.0); // twist and its covariance
    }
    w.buf
}

/// A TFMessage with `odom → base_link` and `base_link → velodyne`.
fn encode_tf(stamp_s: u32, x: f64) -> Vec<u8> {
    let mut w = Cdr::new(false);
    w.u32(2);
    w.header(stamp_s, "odom");
    w.string("base_link");
    w.pose([x, 0.0, 0.0], 0.25);
    w.header(stamp_s, "base_link");
    w.string("velodyne");
    w.pose([0.0, 0.0, 1.73], 0.0);
    w.buf
}

#[test]
fn poses_from_odometry_and_tf_and_clouds_picked_by_time() {
    let dir = tmp_dir("poses");
    let scans = [
        kitti360_scan(2000),
        kitti360_scan(2040),
        kitti360_scan(2080),
    ];
    let mut messages = Vec::new();
    for (i, scan) in scans.iter().enumerate() {
        messages.push(Message {
            topic: "/velodyne_points",
            schema: POINT_CLOUD2,
            data: encode(scan, &kitti_layout(), None),
        });
        messages.push(Message {
            topic: "/odom",
            schema: ODOMETRY,
            data: encode_odometry(
                100 + i as u32,
                [i as f64 * 2.0, 1.0, 0.0],
                0.1 * i as f64,
                i == 1,
            ),
        });
        messages.push(Message {
            topic: "/tf",
            schema: TF_MESSAGE,
            data: encode_tf(100 + i as u32, i as f64),
        });
    }
    let bag = dir.join("drive.mcap");
    write_bag(&bag, &messages, Some(Compression::Zstd));

    let odom = read_bag_poses(&bag, "/odom", None).unwrap();
    assert_eq!(odom.len(), 3);
    for (i, p) in odom.iter().enumerate() {
        assert_eq!(p.stamp_ns, (100 + i as i64) * 1_000_000_000);
        assert_eq!(p.log_time_ns, 1_000 + 3 * i as u64 + 1);
        assert_eq!(p.translation, [i as f64 * 2.0, 1.0, 0.0]);
        assert!(
            (p.yaw() - 0.1 * i as f64).abs() < 1e-12,
            "big-endian message {i}"
        );
        assert_eq!(
            (p.frame_id.as_str(), p.child_frame_id.as_str()),
            ("odom", "base_link")
        );
    }
    let tf = read_bag_poses(&bag, "/tf", None).unwrap();
    assert_eq!(tf.len(), 6);
    let base = read_bag_poses(&bag, "/tf", Some("base_link")).unwrap();
    assert_eq!(base.len(), 3);
    assert!(base
        .iter()
        .enumerate()
        .all(|(i, p)| p.translation[0] == i as f64));

    // Log times of the clouds are 1000, 1003, 1006: each time picks the nearest.
    for (at, want) in [
        (0, 0),
        (1_001, 0),
        (1_002, 1),
        (1_004, 1),
        (1_005, 2),
        (u64::MAX, 2),
    ] {
        let (c, _) = read_bag_cloud_at(
            &bag,
            Some("/velodyne_points"),
            Pick::Time(at),
            &ReadOptions::default(),
        )
        .unwrap();
        assert_eq!(c.positions, scans[want].positions, "time {at}");
    }
    let (c, _) = read_bag_cloud_at(&bag, None, Pick::Index(2), &ReadOptions::default()).unwrap();
    assert_eq!(c.positions, scans[2].positions);

    // Wrong topics name the pose topics; clouds are not poses and poses not clouds.
    for (topic, what) in [
        ("/nope", "no topic"),
        ("/velodyne_points", "holds no poses"),
    ] {
        let e = read_bag_poses(&bag, topic, None).unwrap_err().to_string();
        assert!(
            e.contains(what) && e.contains("/odom, /tf") && e.contains("drive.mcap"),
            "{e}"
        );
    }
    let e = read_bag_cloud(&bag, Some("/odom"), 0, &ReadOptions::default()).unwrap_err();
    assert!(e.to_string().contains(ODOMETRY), "{e}");

    // A truncated odometry message is an error naming the topic and message.
    let mut short = encode_odometry(1, [0.0; 3], 0.0, false);
    short.truncate(40);
    let broken = dir.join("broken.mcap");
    write_bag(
        &broken,
        &[Message {
            topic: "/odom",
            schema: ODOMETRY,
            data: short,
        }],
        None,
    );
    let e = read_bag_poses(&broken, "/odom", None)
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("broken.mcap") && e.contains("/odom") && e.contains("ends inside"),
        "{e}"
    );
}
