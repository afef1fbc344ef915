//! Writing a [`PointCloud`] as a ROS 2 bag (rosbag2 MCAP): one `sensor_msgs/msg/PointCloud2`
//! message in CDR, the inverse of the reader in `point_cloud2`, plus optional JSON messages
//! on other topics (e.g. Foxglove `foxglove.SceneUpdate`).
//!
//! The point layout follows the cloud's columns: `x y z` (FLOAT64, or FLOAT32 for a
//! [`Precision::F32`] cloud), `intensity` FLOAT32, colour both as PCL's packed `rgb` FLOAT32
//! (what RViz and Foxglove colour by) and as `r g b` UINT8 (what urbansem's readers keep),
//! `label` UINT8 (class id), `raw_label` UINT32 and `object` UINT32, each at an offset
//! aligned to its size; little-endian data and CDR.

use super::super::{io_err, CloudError, PointCloud, Precision, Result};
use super::POINT_CLOUD2;
use serde_json::Value;
use std::collections::BTreeMap;
use std::path::Path;

/// The ROS 2 message definition of PointCloud2 with its dependencies (the `ros2msg` schema
/// data viewers decode the CDR with).
pub const POINT_CLOUD2_DEFINITION: &str = "\
# This message holds a collection of N-dimensional points
std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool    is_bigendian
uint32  point_step
uint32  row_step
uint8[] data
bool is_dense
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: sensor_msgs/PointField
uint8 INT8    = 1
uint8 UINT8   = 2
uint8 INT16   = 3
uint8 UINT16  = 4
uint8 INT32   = 5
uint8 UINT32  = 6
uint8 FLOAT32 = 7
uint8 FLOAT64 = 8
string name
uint32 offset
uint8  datatype
uint32 count
";

/// A JSON-encoded message on its own topic (schema encoding `jsonschema`, message
/// encoding `json`).
#[derive(Debug, Clone)]
pub struct JsonMessage {
    /// Topic, e.g. `/semantic_map/objects`.
    pub topic: String,
    /// Schema name, e.g. `foxglove.SceneUpdate`.
    pub schema_name: String,
    /// The JSON Schema text of the message.
    pub schema: String,
    /// The message.
    pub message: Value,
}

/// One point field: name, offset, datatype, size.
struct Field {
    name: &'static str,
    offset: u32,
    datatype: u8,
}

const UINT8: u8 = 2;
const UINT32: u8 = 6;
const FLOAT32: u8 = 7;
const FLOAT64: u8 = 8;

fn size_of(datatype: u8) -> u32 {
    match datatype {
        UINT8 => 1,
        UINT32 | FLOAT32 => 4,
        _ => 8,
    }
}

/// The layout of the cloud's columns and the point step.
fn layout(cloud: &PointCloud) -> (Vec<Field>, u32) {
    let c = cloud.columns();
    let xyz = match cloud.precision {
        Precision::F32 => FLOAT32,
        Precision::F64 => FLOAT64,
    };
    let mut wanted: Vec<(&'static str, u8)> = vec![("x", xyz), ("y", xyz), ("z", xyz)];
    if c.intensity {
        wanted.push(("intensity", FLOAT32));
    }
    if c.rgb {
        wanted.extend([("rgb", FLOAT32), ("r", UINT8), ("g", UINT8), ("b", UINT8)]);
    }
    if c.label {
        wanted.push(("label", UINT8));
    }
    if c.raw_label {
        wanted.push(("raw_label", UINT32));
    }
    if c.object {
        wanted.push(("object", UINT32));
    }
    let mut offset = 0u32;
    let mut fields = Vec::with_capacity(wanted.len());
    for (name, datatype) in wanted {
        let size = size_of(datatype);
        offset = offset.div_ceil(size) * size;
        fields.push(Field {
            name,
            offset,
            datatype,
        });
        offset += size;
    }
    let step = offset.div_ceil(size_of(xyz)) * size_of(xyz);
    (fields, step)
}

/// CDR writer (little-endian): primitives aligned to their size after the 4-byte header.
struct Cdr(Vec<u8>);

impl Cdr {
    fn align(&mut self, n: usize) {
        while (self.0.len() - 4) % n != 0 {
            self.0.push(0);
        }
    }
    fn u32(&mut self, v: u32) {
        self.align(4);
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn string(&mut self, s: &str) -> Option<()> {
        self.u32(u32::try_from(s.len() + 1).ok()?);
        self.0.extend_from_slice(s.as_bytes());
        self.0.push(0);
        Some(())
    }
}

/// A `sensor_msgs/msg/PointCloud2` message (CDR, little-endian) of the cloud: one row of
/// `len` points, stamped `stamp_ns` nanoseconds, in frame `frame_id`. `None` when the
/// cloud is too large for the message's 32-bit sizes.
pub fn encode_point_cloud2(cloud: &PointCloud, frame_id: &str, stamp_ns: u64) -> Option<Vec<u8>> {
    let (fields, step) = layout(cloud);
    let n = u32::try_from(cloud.len()).ok()?;
    let data_len = n.checked_mul(step)?;
    let mut w = Cdr(vec![0, 1, 0, 0]);
    w.u32(u32::try_from(stamp_ns / 1_000_000_000).ok()?);
    w.u32((stamp_ns % 1_000_000_000) as u32);
    w.string(frame_id)?;
    w.u32(1); // height
    w.u32(n); // width
    w.u32(fields.len() as u32);
    for f in &fields {
        w.string(f.name)?;
        w.u32(f.offset);
        w.0.push(f.datatype);
        w.u32(1);
    }
    w.0.push(0); // is_bigendian
    w.u32(step);
    w.u32(data_len); // row_step
    w.u32(data_len);
    let start = w.0.len();
    w.0.resize(start + data_len as usize, 0);
    for (i, point) in w.0[start..].chunks_mut(step as usize).enumerate() {
        let Some(p) = cloud.get(i) else { break };
        for f in &fields {
            let at = f.offset as usize;
            let mut put = |bytes: &[u8]| point[at..at + bytes.len()].copy_from_slice(bytes);
            match (f.name, f.datatype) {
                ("x", FLOAT64) => put(&p.position[0].to_le_bytes()),
                ("y", FLOAT64) => put(&p.position[1].to_le_bytes()),
                ("z", FLOAT64) => put(&p.position[2].to_le_bytes()),
                ("x", _) => put(&(p.position[0] as f32).to_le_bytes()),
                ("y", _) => put(&(p.position[1] as f32).to_le_bytes()),
                ("z", _) => put(&(p.position[2] as f32).to_le_bytes()),
                ("intensity", _) => put(&p.intensity.to_le_bytes()),
                ("rgb", _) => {
                    let [r, g, b] = p.rgb;
                    // PCL's packing: 0x00RRGGBB in the bytes of a float.
                    put(&(u32::from(r) << 16 | u32::from(g) << 8 | u32::from(b)).to_le_bytes())
                }
                ("r", _) => put(&[p.rgb[0]]),
                ("g", _) => put(&[p.rgb[1]]),
                ("b", _) => put(&[p.rgb[2]]),
                ("label", _) => put(&[p.label]),
                ("raw_label", _) => put(&p.raw_label.to_le_bytes()),
                _ => put(&p.object.to_le_bytes()),
            }
        }
    }
    w.0.push(1); // is_dense
    Some(w.0)
}

/// Writes a ROS 2 bag (atomically) holding the cloud as one PointCloud2 message on `topic`
/// in frame `frame_id`, then the JSON messages, all logged at `stamp_ns`.
pub fn write_bag_cloud(
    path: &Path,
    topic: &str,
    frame_id: &str,
    cloud: &PointCloud,
    stamp_ns: u64,
    extra: &[JsonMessage],
) -> Result<()> {
    cloud.check_columns()?;
    let data =
        encode_point_cloud2(cloud, frame_id, stamp_ns).ok_or_else(|| CloudError::Unsupported {
            path: path.to_path_buf(),
            what: format!(
                "a PointCloud2 message of {} points (more than 4 GB)",
                cloud.len()
            ),
        })?;
    let mcap_err = |source: mcap::McapError| CloudError::Mcap {
        path: path.to_path_buf(),
        at: super::super::Location::Byte(0),
        source: Box::new(source),
    };
    let mut out = std::io::Cursor::new(Vec::new());
    {
        let mut w = mcap::WriteOptions::new()
            .profile("ros2")
            .create(&mut out)
            .map_err(mcap_err)?;
        let schema = w
            .add_schema(POINT_CLOUD2, "ros2msg", POINT_CLOUD2_DEFINITION.as_bytes())
            .map_err(mcap_err)?;
        let channel = w
            .add_channel(schema, topic, "cdr", &BTreeMap::new())
            .map_err(mcap_err)?;
        let header = |channel_id, sequence| mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: stamp_ns,
            publish_time: stamp_ns,
        };
        w.write_to_known_channel(&header(channel, 0), &data)
            .map_err(mcap_err)?;
        for (k, m) in extra.iter().enumerate() {
            let schema = w
                .add_schema(&m.schema_name, "jsonschema", m.schema.as_bytes())
                .map_err(mcap_err)?;
            let channel = w
                .add_channel(schema, &m.topic, "json", &BTreeMap::new())
                .map_err(mcap_err)?;
            let bytes = serde_json::to_vec(&m.message).map_err(|e| CloudError::Unsupported {
                path: path.to_path_buf(),
                what: format!("JSON message on {}: {e}", m.topic),
            })?;
            w.write_to_known_channel(&header(channel, k as u32 + 1), &bytes)
                .map_err(mcap_err)?;
        }
        w.finish().map_err(mcap_err)?;
    }
    crate::fsio::write_atomic(path, out.into_inner()).map_err(io_err(path))
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;
    use crate::cloud::{Columns, PointRecord, ReadOptions};

    fn cloud() -> PointCloud {
        let columns = Columns {
            rgb: true,
            label: true,
            object: true,
            intensity: true,
            ..Columns::default()
        };
        let mut c = PointCloud::with_columns(columns, Precision::F64, 0);
        for i in 0..500u32 {
            let f = f64::from(i);
            c.push(&PointRecord {
                position: [f * 0.1 + 1e-9, -f * 0.37, 1.0 / (1.0 + f)],
                intensity: f as f32 * 0.5,
                rgb: [(i % 256) as u8, (i * 7 % 256) as u8, 255 - (i % 256) as u8],
                label: (i % 10) as u8,
                object: i / 50,
                ..PointRecord::default()
            });
        }
        c
    }

    #[test]
    fn a_written_bag_reads_back_identically() {
        let dir = std::env::temp_dir().join(format!("geodata-bag-write-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("map.mcap");
        let c = cloud();
        let extra = JsonMessage {
            topic: "/extra".into(),
            schema_name: "foxglove.SceneUpdate".into(),
            schema: r#"{"type":"object"}"#.into(),
            message: serde_json::json!({"entities": []}),
        };
        write_bag_cloud(&path, "/map", "map", &c, 1_500_000_000_123, &[extra]).unwrap();

        // urbansem's reader: every column identical.
        let (back, _) =
            super::super::read_bag_cloud(&path, Some("/map"), 0, &ReadOptions::default()).unwrap();
        assert_eq!(back.positions, c.positions);
        assert_eq!(back.precision, Precision::F64);
        assert_eq!(back.rgb, c.rgb);
        assert_eq!(back.label, c.label);
        assert_eq!(back.object, c.object);
        assert_eq!(back.intensity, c.intensity);

        // The mcap crate's reader: schemas, encodings, the packed rgb of a point.
        let bytes = std::fs::read(&path).unwrap();
        let messages: Vec<_> = mcap::MessageStream::new(&bytes)
            .unwrap()
            .map(|m| m.unwrap())
            .collect();
        assert_eq!(messages.len(), 2);
        let m = &messages[0];
        assert_eq!(m.channel.topic, "/map");
        assert_eq!(m.channel.message_encoding, "cdr");
        let schema = m.channel.schema.as_ref().unwrap();
        assert_eq!(schema.name, POINT_CLOUD2);
        assert_eq!(schema.encoding, "ros2msg");
        assert_eq!(m.log_time, 1_500_000_000_123);
        let msg = point_cloud2_fields(&m.data);
        let rgb = msg.iter().find(|f| f.0 == "rgb").unwrap();
        assert_eq!(rgb.2, FLOAT32);
        let j = &messages[1];
        assert_eq!(j.channel.message_encoding, "json");
        assert_eq!(j.channel.schema.as_ref().unwrap().encoding, "jsonschema");
        let v: Value = serde_json::from_slice(&j.data).unwrap();
        assert_eq!(v["entities"], serde_json::json!([]));
        std::fs::remove_dir_all(&dir).ok();
    }

    /// The (name, offset, datatype) of a message's fields via the reader's decoder.
    fn point_cloud2_fields(data: &[u8]) -> Vec<(String, u32, u8)> {
        let m = super::super::point_cloud2::decode_point_cloud2(data).unwrap();
        m.layout
            .fields
            .iter()
            .map(|f| (f.name.clone(), f.offset, f.datatype))
            .collect()
    }
}
