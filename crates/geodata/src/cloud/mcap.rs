//! ROS 2 bags (rosbag2 MCAP files) without ROS: list a bag's topics and read one
//! `sensor_msgs/msg/PointCloud2` message as a [`PointCloud`].
//!
//! The MCAP container (chunks, zstd or lz4 compression, schemas, channels) is read by the
//! `mcap` crate's streaming reader; the PointCloud2 message is decoded from its CDR bytes
//! here (OMG CDR, DDS-XTypes 1.3 §7.4.3.5: a 4-byte encapsulation header, then each
//! primitive aligned to its own size counted from after that header):
//!
//! ```text
//! std_msgs/Header header        stamp.sec i32, stamp.nanosec u32, frame_id string
//! uint32 height, uint32 width
//! PointField[] fields           name string, offset u32, datatype u8, count u32
//! bool is_bigendian
//! uint32 point_step, uint32 row_step
//! uint8[] data                  height rows of row_step bytes, point_step bytes a point
//! bool is_dense
//! ```
//!
//! Any field layout is read: `x y z` of any numeric datatype (FLOAT32 keeps
//! [`Precision::F32`], anything else gives F64) fill the positions; `intensity` (or
//! `reflectance`), `label` (UINT8: urbansem's class id; wider: a dataset's id, kept in
//! `raw_label`), `raw_label` and `object` fill their columns, as in the PCD reader. Other
//! fields (`ring`, `t`/`time`/`timestamp`, normals, padding) are listed by [`bag_info`] but not
//! stored: [`PointCloud`] has no column for them. Big-endian point data (`is_bigendian`) and
//! big-endian CDR are honoured. Points with a non-finite coordinate follow
//! [`ReadOptions::drop_non_finite`], as in every reader.
//!
//! # Cost and bounds
//!
//! One pass over the bag, stopping at the message asked for: time linear in the file, memory
//! one decompressed chunk plus the cloud. Every length and count in a message is checked
//! against the bytes left before anything is sized by it; `width × height × point_step` must
//! match the data's length, so a header claiming 4 G points is a [`MessageProblem::DataLength`]
//! error, not an allocation.

use super::error::MessageProblem;
use super::ply::{assign, Role, Scalar};
use super::{io_err, path_buf, CloudError, Columns, Location, PointCloud, PointRecord};
use super::{Precision, ReadOptions, ReadReport, Result, Sink};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::Path;

/// The schema name of ROS 2 point cloud messages.
pub const POINT_CLOUD2: &str = "sensor_msgs/msg/PointCloud2";

/// The message encoding of ROS 2 messages in a rosbag2 MCAP file.
pub const CDR: &str = "cdr";

/// One `sensor_msgs/msg/PointField` of a PointCloud2 message.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct PointFieldInfo {
    /// Field name (`x`, `intensity`, `ring`, …).
    pub name: String,
    /// Byte offset inside a point.
    pub offset: u32,
    /// PointField datatype: 1 INT8, 2 UINT8, 3 INT16, 4 UINT16, 5 INT32, 6 UINT32, 7 FLOAT32, 8 FLOAT64.
    pub datatype: u8,
    /// Number of values of this datatype.
    pub count: u32,
}

impl PointFieldInfo {
    /// The datatype's name in PointField's words (`FLOAT32`, …), `?` for an unknown one.
    pub fn datatype_name(&self) -> &'static str {
        match self.datatype {
            1 => "INT8",
            2 => "UINT8",
            3 => "INT16",
            4 => "UINT16",
            5 => "INT32",
            6 => "UINT32",
            7 => "FLOAT32",
            8 => "FLOAT64",
            _ => "?",
        }
    }
}

/// The layout of a PointCloud2 message: its size and point fields.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct CloudLayout {
    /// Points per row.
    pub width: u32,
    /// Rows (1 for an unorganized cloud).
    pub height: u32,
    /// Bytes per point.
    pub point_step: u32,
    /// True when the point data is big-endian.
    pub is_bigendian: bool,
    /// The frame of the points (`header.frame_id`).
    pub frame_id: String,
    /// The point fields.
    pub fields: Vec<PointFieldInfo>,
}

/// One topic of a bag.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct TopicInfo {
    /// Topic name (`/points`).
    pub topic: String,
    /// Messages on the topic.
    pub messages: usize,
    /// Schema name (`sensor_msgs/msg/PointCloud2`; empty without a schema).
    pub schema: String,
    /// Message encoding (`cdr` in rosbag2).
    pub message_encoding: String,
    /// For a PointCloud2 topic, the layout of its first message.
    pub cloud: Option<CloudLayout>,
}

/// What a ROS 2 bag holds (`urbansem cloud info BAG.mcap`).
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct BagInfo {
    /// The bag.
    pub file: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Topics in name order.
    pub topics: Vec<TopicInfo>,
}

impl BagInfo {
    /// The PointCloud2 topics, in name order.
    pub fn point_cloud_topics(&self) -> Vec<String> {
        self.topics
            .iter()
            .filter(|t| t.schema == POINT_CLOUD2)
            .map(|t| t.topic.clone())
            .collect()
    }

    /// A readable listing: one line per topic, then the point fields of point cloud topics.
    pub fn text(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "{}", self.file);
        let _ = writeln!(
            out,
            "  format     ROS 2 bag, MCAP ({} bytes), {} topics",
            self.bytes,
            self.topics.len()
        );
        for t in &self.topics {
            let schema = if t.schema.is_empty() {
                "(no schema)"
            } else {
                t.schema.as_str()
            };
            let _ = writeln!(
                out,
                "  topic      {}  {} messages  {} ({})",
                t.topic, t.messages, schema, t.message_encoding
            );
            if let Some(c) = &t.cloud {
                let _ = writeln!(
                    out,
                    "    points   {} × {} in frame {:?}, {} bytes a point{}",
                    c.width,
                    c.height,
                    c.frame_id,
                    c.point_step,
                    if c.is_bigendian { ", big-endian" } else { "" }
                );
                let fields: Vec<String> = c
                    .fields
                    .iter()
                    .map(|f| {
                        let count = if f.count == 1 {
                            String::new()
                        } else {
                            format!("×{}", f.count)
                        };
                        format!("{}:{}{count}@{}", f.name, f.datatype_name(), f.offset)
                    })
                    .collect();
                let _ = writeln!(out, "    fields   {}", fields.join(" "));
            }
        }
        out
    }
}

/// A decoded PointCloud2 message, its point data borrowed from the message bytes.
#[derive(Debug, Clone, PartialEq)]
struct PointCloud2<'a> {
    /// Size, fields and frame.
    layout: CloudLayout,
    /// Bytes per row.
    row_step: u32,
    /// The point data, `height × row_step` bytes.
    data: &'a [u8],
    /// Byte offset of `data` within the message.
    data_offset: u64,
}

/// A cursor over CDR bytes; offsets count from the start of the message.
struct Cdr<'a> {
    /// The bytes after the 4-byte encapsulation header.
    body: &'a [u8],
    pos: usize,
    big_endian: bool,
}

/// A decoding problem and the byte of the message where it was found.
type CdrResult<T> = std::result::Result<T, (u64, MessageProblem)>;

impl<'a> Cdr<'a> {
    /// Reads the encapsulation header of `message`.
    fn new(message: &'a [u8]) -> CdrResult<Self> {
        let Some((head, body)) = message.split_first_chunk::<4>() else {
            return Err((
                0,
                MessageProblem::Truncated {
                    field: "the encapsulation header",
                    need: 4,
                    left: message.len() as u64,
                },
            ));
        };
        let id = u16::from_be_bytes([head[0], head[1]]);
        let big_endian = match id {
            0 => true,
            1 => false,
            _ => return Err((0, MessageProblem::Encapsulation { id })),
        };
        Ok(Self {
            body,
            pos: 0,
            big_endian,
        })
    }

    /// Byte offset within the message of the cursor.
    fn offset(&self) -> u64 {
        self.pos as u64 + 4
    }

    /// `n` bytes aligned to `align`, advancing past them.
    fn take(&mut self, n: usize, align: usize, field: &'static str) -> CdrResult<&'a [u8]> {
        let start = self.pos.next_multiple_of(align);
        let left = self.body.len().saturating_sub(start);
        match self.body.get(start..).and_then(|b| b.get(..n)) {
            Some(bytes) => {
                self.pos = start + n;
                Ok(bytes)
            }
            None => Err((
                self.offset(),
                MessageProblem::Truncated {
                    field,
                    need: n as u64,
                    left: left as u64,
                },
            )),
        }
    }

    fn u8(&mut self, field: &'static str) -> CdrResult<u8> {
        Ok(self.take(1, 1, field)?.first().copied().unwrap_or(0))
    }

    fn u32(&mut self, field: &'static str) -> CdrResult<u32> {
        let b = self.take(4, 4, field)?;
        let a = [b[0], b[1], b[2], b[3]];
        Ok(if self.big_endian {
            u32::from_be_bytes(a)
        } else {
            u32::from_le_bytes(a)
        })
    }

    /// A CDR string: u32 length including the NUL, the bytes, the NUL.
    fn string(&mut self, field: &'static str) -> CdrResult<String> {
        let len = self.u32(field)?;
        let at = self.offset();
        let bytes = self.take(len as usize, 1, field)?;
        let text = match bytes.split_last() {
            Some((0, text)) => std::str::from_utf8(text).ok(),
            // A zero length is not CDR, but some writers emit it for the empty string.
            None => Some(""),
            Some(_) => None,
        };
        text.map(str::to_owned)
            .ok_or((at, MessageProblem::BadString { field }))
    }
}

/// Decodes the CDR bytes of a `sensor_msgs/msg/PointCloud2` message and checks that its
/// fields fit its points and its data holds `width × height` points.
fn decode_point_cloud2(message: &[u8]) -> CdrResult<PointCloud2<'_>> {
    let mut c = Cdr::new(message)?;
    c.u32("header.stamp.sec")?;
    c.u32("header.stamp.nanosec")?;
    let frame_id = c.string("header.frame_id")?;
    let height = c.u32("height")?;
    let width = c.u32("width")?;
    let n_fields = c.u32("the field count")?;
    let mut fields = Vec::new();
    // Each field takes at least 13 bytes, so this loop ends within the message's length.
    for _ in 0..n_fields {
        let name = c.string("a field name")?;
        let offset = c.u32("a field offset")?;
        let datatype = c.u8("a field datatype")?;
        let count = c.u32("a field count")?;
        fields.push(PointFieldInfo {
            name,
            offset,
            datatype,
            count,
        });
    }
    let is_bigendian = c.u8("is_bigendian")? != 0;
    let point_step = c.u32("point_step")?;
    let row_step = c.u32("row_step")?;
    let data_len = c.u32("the data length")?;
    let data_offset = c.offset();
    let data = c.take(data_len as usize, 1, "data")?;
    c.u8("is_dense")?;
    for f in &fields {
        let size = match scalar_of(f.datatype) {
            Some(s) => s.size() as u64,
            // An unknown datatype is an error only for a field the reader uses.
            None if role_of(f) == Role::Skip => continue,
            None => {
                return Err((
                    data_offset,
                    MessageProblem::BadDatatype {
                        name: f.name.clone(),
                        datatype: f.datatype,
                    },
                ))
            }
        };
        let end = u64::from(f.offset) + size * u64::from(f.count);
        if end > u64::from(point_step) {
            return Err((
                data_offset,
                MessageProblem::FieldOutsidePoint {
                    name: f.name.clone(),
                    offset: f.offset,
                    end,
                    point_step,
                },
            ));
        }
    }
    let packed_row = u128::from(width) * u128::from(point_step);
    let need = u128::from(height) * packed_row.max(u128::from(row_step));
    if u128::from(row_step) < packed_row || need != data.len() as u128 {
        return Err((
            data_offset,
            MessageProblem::DataLength {
                width,
                height,
                point_step,
                row_step,
                need,
                data: data.len() as u64,
            },
        ));
    }
    Ok(PointCloud2 {
        layout: CloudLayout {
            width,
            height,
            point_step,
            is_bigendian,
            frame_id,
            fields,
        },
        row_step,
        data,
        data_offset,
    })
}

/// The scalar type of a PointField datatype.
fn scalar_of(datatype: u8) -> Option<Scalar> {
    Some(match datatype {
        1 => Scalar::I8,
        2 => Scalar::U8,
        3 => Scalar::I16,
        4 => Scalar::U16,
        5 => Scalar::I32,
        6 => Scalar::U32,
        7 => Scalar::F32,
        8 => Scalar::F64,
        _ => return None,
    })
}

/// Which column a field fills: the PCD reader's rule (a UINT8 `label` is urbansem's class
/// id, a wider one a dataset's id); arrays other than coordinates are skipped.
fn role_of(f: &PointFieldInfo) -> Role {
    match (f.name.as_str(), f.count) {
        ("label", 1) if f.datatype != 2 => Role::RawLabel,
        ("x" | "y" | "z", _) => Role::from_name(&f.name),
        (name, 1) => Role::from_name(name),
        _ => Role::Skip,
    }
}

/// A field the reader fills, resolved for fast decoding.
struct Used {
    role: Role,
    scalar: Scalar,
    offset: usize,
    name: String,
}

/// Decodes the points of a checked message into a cloud; errors are `(byte, problem)` for
/// the layout and [`CloudError`]s naming the point for the values.
fn points_of(
    path: &Path,
    msg: &PointCloud2<'_>,
    options: &ReadOptions,
) -> CdrResult<Result<(PointCloud, ReadReport)>> {
    let layout = &msg.layout;
    let mut used = Vec::new();
    for f in &layout.fields {
        let role = role_of(f);
        if role == Role::Skip || f.count == 0 {
            continue;
        }
        if matches!(role, Role::X | Role::Y | Role::Z) && f.count != 1 {
            return Err((
                msg.data_offset,
                MessageProblem::CoordinateCount {
                    name: f.name.clone(),
                    count: f.count,
                },
            ));
        }
        // Checked by decode_point_cloud2: a used field has a known datatype.
        if let Some(scalar) = scalar_of(f.datatype) {
            used.push(Used {
                role,
                scalar,
                offset: f.offset as usize,
                name: f.name.clone(),
            });
        }
    }
    for (role, name) in [(Role::X, "x"), (Role::Y, "y"), (Role::Z, "z")] {
        if !used.iter().any(|u| u.role == role) {
            let names: Vec<&str> = layout.fields.iter().map(|f| f.name.as_str()).collect();
            return Err((
                msg.data_offset,
                MessageProblem::MissingField {
                    name,
                    fields: names.join(" "),
                },
            ));
        }
    }
    let has = |role: Role| used.iter().any(|u| u.role == role);
    let columns = Columns {
        intensity: has(Role::Intensity),
        rgb: false,
        label: has(Role::Label),
        raw_label: has(Role::RawLabel),
        object: has(Role::Object),
    };
    let double = used
        .iter()
        .any(|u| matches!(u.role, Role::X | Role::Y | Role::Z) && u.scalar != Scalar::F32);
    let precision = if double {
        Precision::F64
    } else {
        Precision::F32
    };
    // Checked by decode_point_cloud2: data holds height × width points.
    let points = layout.width as usize * layout.height as usize;
    let mut sink = Sink::new(
        path,
        PointCloud::with_columns(columns, precision, points),
        options,
    );
    let point_step = layout.point_step as usize;
    let rows = msg
        .data
        .chunks(msg.row_step.max(1) as usize)
        .take(layout.height as usize);
    let mut i = 0usize;
    for row in rows {
        for point in row.chunks(point_step.max(1)).take(layout.width as usize) {
            let mut rec = PointRecord::default();
            for u in &used {
                let bytes = point.get(u.offset..).unwrap_or(&[]);
                let v = u.scalar.decode(bytes, layout.is_bigendian);
                if let Err(e) = assign(&mut rec, u.role, v, path, Location::Point(i), &u.name) {
                    return Ok(Err(e));
                }
            }
            if let Err(e) = sink.push(&rec) {
                return Ok(Err(e));
            }
            i += 1;
        }
    }
    Ok(Ok(sink.finish()))
}

/// What one pass over a bag saw of one topic.
struct TopicScan {
    schema: String,
    encoding: String,
    messages: usize,
    /// The bytes of the picked message, when the topic was wanted and has it.
    picked: Option<Vec<u8>>,
}

/// Largest record the MCAP reader may buffer: `RECORD_LIMIT_PER_BYTE` times the file's size,
/// at least [`RECORD_LIMIT_MIN`] (a compressed chunk may expand; a corrupt length must not
/// become an allocation).
const RECORD_LIMIT_PER_BYTE: u64 = 64;
/// See [`RECORD_LIMIT_PER_BYTE`].
const RECORD_LIMIT_MIN: u64 = 256 << 20;
/// Bytes handed to the MCAP reader at a time.
const READ_BLOCK: usize = 1 << 20;

/// One pass over a bag: per topic, its schema, encoding and message count, and for each topic
/// that `wanted(topic, schema)` accepts, the bytes of its message number `index`. With
/// `stop_early` the pass ends as soon as one wanted message is picked.
fn scan(
    path: &Path,
    wanted: impl Fn(&str, &str) -> bool,
    index: usize,
    stop_early: bool,
) -> Result<BTreeMap<String, TopicScan>> {
    use ::mcap::records::Record;
    use ::mcap::sans_io::linear_reader::{LinearReadEvent, LinearReader, LinearReaderOptions};
    use std::io::Read;

    let mut file = std::fs::File::open(path).map_err(io_err(path))?;
    let len = file.metadata().map_err(io_err(path))?.len();
    let limit = len
        .saturating_mul(RECORD_LIMIT_PER_BYTE)
        .max(RECORD_LIMIT_MIN);
    let options = LinearReaderOptions::default()
        .with_validate_chunk_crcs(true)
        .with_record_length_limit(usize::try_from(limit).unwrap_or(usize::MAX));
    let mut reader = LinearReader::new_with_options(options);
    let mut schemas: HashMap<u16, (String, String)> = HashMap::new();
    // Channel id → topic; several channels may share a topic.
    let mut channels: HashMap<u16, String> = HashMap::new();
    let mut topics: BTreeMap<String, TopicScan> = BTreeMap::new();
    let mut fed: u64 = 0;
    let mcap_err = |fed: u64, source: ::mcap::McapError| CloudError::Mcap {
        path: path_buf(path),
        at: Location::Byte(fed),
        source: Box::new(source),
    };
    while let Some(event) = reader.next_event() {
        match event.map_err(|e| mcap_err(fed, e))? {
            LinearReadEvent::ReadRequest(need) => {
                let buf = reader.insert(need.clamp(1, READ_BLOCK));
                let n = loop {
                    match file.read(buf) {
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        other => break other.map_err(io_err(path))?,
                    }
                };
                reader.notify_read(n);
                fed += n as u64;
            }
            LinearReadEvent::Record { opcode, data } => {
                match ::mcap::parse_record(opcode, data).map_err(|e| mcap_err(fed, e))? {
                    Record::Schema { header, .. } => {
                        schemas.insert(header.id, (header.name, header.encoding));
                    }
                    Record::Channel(c) => {
                        let (schema, _) = schemas.get(&c.schema_id).cloned().unwrap_or_default();
                        topics.entry(c.topic.clone()).or_insert_with(|| TopicScan {
                            schema,
                            encoding: c.message_encoding.clone(),
                            messages: 0,
                            picked: None,
                        });
                        channels.insert(c.id, c.topic);
                    }
                    Record::Message { header, data } => {
                        let Some(topic) = channels.get(&header.channel_id) else {
                            continue;
                        };
                        let Some(t) = topics.get_mut(topic) else {
                            continue;
                        };
                        if t.messages == index && wanted(topic, &t.schema) {
                            t.picked = Some(data.into_owned());
                            if stop_early {
                                t.messages += 1;
                                return Ok(topics);
                            }
                        }
                        t.messages += 1;
                    }
                    _ => {}
                }
            }
        }
    }
    Ok(topics)
}

/// Lists a bag's topics: message counts, schemas, and the point fields of the first message
/// of each PointCloud2 topic. Reads the whole bag once.
pub fn bag_info(path: &Path) -> Result<BagInfo> {
    let bytes = std::fs::metadata(path).map_err(io_err(path))?.len();
    let topics = guarded(path, || {
        scan(path, |_, schema| schema == POINT_CLOUD2, 0, false)
    })?;
    let mut out = Vec::new();
    for (topic, t) in topics {
        let cloud = match &t.picked {
            Some(message) if t.encoding == CDR => Some(
                decode_point_cloud2(message)
                    .map_err(|(offset, problem)| CloudError::BadMessage {
                        path: path_buf(path),
                        topic: topic.clone(),
                        index: 0,
                        offset,
                        problem: Box::new(problem),
                    })?
                    .layout,
            ),
            _ => None,
        };
        out.push(TopicInfo {
            topic,
            messages: t.messages,
            schema: t.schema,
            message_encoding: t.encoding,
            cloud,
        });
    }
    Ok(BagInfo {
        file: path.display().to_string(),
        bytes,
        topics: out,
    })
}

/// Reads message `index` (0-based, in file order) of a PointCloud2 `topic` of a bag as a
/// cloud. Without a topic the bag must have exactly one PointCloud2 topic.
///
/// Stops reading at the message when the topic is named; without one the whole bag is read
/// once (to be sure no second point cloud topic follows).
pub fn read_bag_cloud(
    path: &Path,
    topic: Option<&str>,
    index: usize,
    options: &ReadOptions,
) -> Result<(PointCloud, ReadReport)> {
    let topics = guarded(path, || match topic {
        Some(name) => scan(path, |t, _| t == name, index, true),
        None => scan(path, |_, schema| schema == POINT_CLOUD2, index, false),
    })?;
    let cloud_topics: Vec<String> = topics
        .iter()
        .filter(|(_, t)| t.schema == POINT_CLOUD2)
        .map(|(name, _)| name.clone())
        .collect();
    let topic_err = |problem: String| CloudError::Topic {
        path: path_buf(path),
        problem,
        point_cloud_topics: cloud_topics.clone(),
    };
    let name = match topic {
        Some(name) => name.to_owned(),
        None => match cloud_topics.as_slice() {
            [one] => one.clone(),
            [] => return Err(topic_err(format!("no {POINT_CLOUD2} topic"))),
            _ => {
                return Err(topic_err(format!(
                    "{} {POINT_CLOUD2} topics; name one (--topic)",
                    cloud_topics.len()
                )))
            }
        },
    };
    let Some(t) = topics.get(&name) else {
        return Err(topic_err(format!("no topic {name:?}")));
    };
    if t.schema != POINT_CLOUD2 || t.encoding != CDR {
        return Err(CloudError::WrongSchema {
            path: path_buf(path),
            topic: name,
            schema: t.schema.clone(),
            encoding: t.encoding.clone(),
        });
    }
    let Some(message) = &t.picked else {
        return Err(CloudError::NoMessage {
            path: path_buf(path),
            topic: name,
            index,
            messages: t.messages,
        });
    };
    let bad = |(offset, problem): (u64, MessageProblem)| CloudError::BadMessage {
        path: path_buf(path),
        topic: name.clone(),
        index,
        offset,
        problem: Box::new(problem),
    };
    let msg = decode_point_cloud2(message).map_err(bad)?;
    points_of(path, &msg, options)
        .map_err(bad)?
        .map_err(|source| CloudError::InMessage {
            topic: name.clone(),
            index,
            source: Box::new(source),
        })
}

/// Runs a pass of the `mcap` crate's reader; a panic inside it on corrupt input becomes an
/// error (see [`super::guard`]).
fn guarded<T>(path: &Path, f: impl FnOnce() -> Result<T>) -> Result<T> {
    super::guard::catch_silently(f).unwrap_or_else(|| {
        Err(CloudError::Corrupt {
            path: path_buf(path),
            at: Location::Byte(0),
            message: "the MCAP reader failed on this bag's records".into(),
        })
    })
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]
    use super::*;

    /// A one-point little-endian message with x y z FLOAT32 and an empty frame id, written
    /// out by hand: the offsets in the comments count from after the 4-byte header.
    fn one_point() -> Vec<u8> {
        let mut m = vec![0, 1, 0, 0];
        let u32s = |m: &mut Vec<u8>, values: &[u32]| {
            for v in values {
                m.extend_from_slice(&v.to_le_bytes());
            }
        };
        u32s(&mut m, &[7, 8, 1]); // 0: stamp, 8: frame_id length (NUL only)
        m.extend_from_slice(&[0, 0, 0, 0]); // 12: NUL, 13..16: padding to 4
        u32s(&mut m, &[1, 1, 3]); // 16: height, 20: width, 24: field count
        for (name, offset) in [(b'x', 0u32), (b'y', 4), (b'z', 8)] {
            u32s(&mut m, &[2]); // name length
            m.extend_from_slice(&[name, 0, 0, 0]); // name, NUL, padding to 4
            u32s(&mut m, &[offset]);
            m.extend_from_slice(&[7, 0, 0, 0]); // FLOAT32, padding to 4
            u32s(&mut m, &[1]); // count
        }
        m.extend_from_slice(&[0, 0, 0, 0]); // 88: is_bigendian, padding to 4
        u32s(&mut m, &[12, 12, 12]); // 92: point_step, 96: row_step, 100: data length
        for v in [1.5f32, -2.0, 0.25] {
            m.extend_from_slice(&v.to_le_bytes()); // 104: data
        }
        m.push(1); // 116: is_dense
        m
    }

    #[test]
    fn a_hand_written_message_decodes_and_its_offsets_are_exact() {
        let m = one_point();
        let msg = decode_point_cloud2(&m).unwrap();
        assert_eq!((msg.layout.width, msg.layout.height), (1, 1));
        assert_eq!(msg.data_offset, 4 + 104);
        assert_eq!(msg.layout.fields[2].name, "z");
        let (cloud, report) = points_of(Path::new("a.mcap"), &msg, &ReadOptions::default())
            .unwrap()
            .unwrap();
        assert_eq!(cloud.positions, vec![[1.5, -2.0, 0.25]]);
        assert_eq!(
            (cloud.precision, report.points_in_file),
            (Precision::F32, 1)
        );
        // Cut before is_dense: the error is at the byte where is_dense starts.
        let (offset, problem) = decode_point_cloud2(&m[..m.len() - 1]).unwrap_err();
        assert_eq!(offset, 4 + 116);
        assert_eq!(
            problem,
            MessageProblem::Truncated {
                field: "is_dense",
                need: 1,
                left: 0
            }
        );
    }
}
