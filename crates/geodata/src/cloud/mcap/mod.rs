//! ROS 2 bags (rosbag2 MCAP files) without ROS: list a bag's topics and read one
//! `sensor_msgs/msg/PointCloud2` message as a [`PointCloud`]; [`write_bag_cloud`] writes
//! one (with optional JSON messages beside it).
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
//! [`Precision::F32`](super::Precision::F32), anything else gives F64) fill the positions; `intensity` (or
//! `reflectance`), `label` (UINT8: urbansem's class id; wider: a dataset's id, kept in
//! `raw_label`), `raw_label` and `object` fill their columns, as in the PCD reader, and
//! `r g b` (or `red green blue`, all three) the colour column. Other
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

mod cdr;
mod point_cloud2;
mod poses;
mod write;

pub use point_cloud2::{CloudLayout, PointFieldInfo};
pub use poses::{interpolate, BagPose, ODOMETRY, POSE_SCHEMAS, POSE_STAMPED, TF_MESSAGE};
pub use write::{encode_point_cloud2, write_bag_cloud, JsonMessage, POINT_CLOUD2_DEFINITION};

use super::error::MessageProblem;
use super::{io_err, path_buf, CloudError, Location, PointCloud, ReadOptions, ReadReport, Result};
use point_cloud2::{decode_point_cloud2, points_of};
use serde::Serialize;
use std::collections::{BTreeMap, HashMap};
use std::fmt::Write as _;
use std::path::Path;

/// The schema name of ROS 2 point cloud messages.
pub const POINT_CLOUD2: &str = "sensor_msgs/msg/PointCloud2";

/// The message encoding of ROS 2 messages in a rosbag2 MCAP file.
pub const CDR: &str = "cdr";

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

/// What one pass over a bag saw of one topic.
struct TopicScan {
    schema: String,
    encoding: String,
    messages: usize,
    /// The bytes of the picked message, when the topic was wanted and has it.
    picked: Option<Vec<u8>>,
    /// The picked message's number in the topic (0-based, file order).
    picked_index: usize,
}

/// Largest record the MCAP reader may buffer: `RECORD_LIMIT_PER_BYTE` times the file's size,
/// at least [`RECORD_LIMIT_MIN`] (a compressed chunk may expand; a corrupt length must not
/// become an allocation).
const RECORD_LIMIT_PER_BYTE: u64 = 64;
/// See [`RECORD_LIMIT_PER_BYTE`].
const RECORD_LIMIT_MIN: u64 = 256 << 20;
/// Bytes handed to the MCAP reader at a time.
const READ_BLOCK: usize = 1 << 20;

/// What [`scan`] does with one message.
enum Visit {
    /// Count it and go on.
    Skip,
    /// Keep its bytes as the topic's picked message (replacing an earlier one) and go on.
    Keep,
    /// Keep its bytes and end the pass.
    KeepAndStop,
    /// End the pass.
    Stop,
}

/// One pass over a bag: per topic, its schema, encoding and message count; `visit(topic,
/// seen, log_time, bytes)` decides for each message (with `seen` its topic's state before
/// it) whether it becomes the topic's picked message or ends the pass.
fn scan(
    path: &Path,
    mut visit: impl FnMut(&str, &TopicScan, u64, &[u8]) -> Result<Visit>,
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
                            picked_index: 0,
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
                        let visit = visit(topic, t, header.log_time, &data[..])?;
                        if matches!(visit, Visit::Keep | Visit::KeepAndStop) {
                            t.picked = Some(data.into_owned());
                            t.picked_index = t.messages;
                        }
                        if matches!(visit, Visit::Stop) {
                            return Ok(topics);
                        }
                        if matches!(visit, Visit::KeepAndStop) {
                            t.messages += 1;
                            return Ok(topics);
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
        scan(path, |_, t, _, _| {
            Ok(if t.messages == 0 && t.schema == POINT_CLOUD2 {
                Visit::Keep
            } else {
                Visit::Skip
            })
        })
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

/// Which message of a topic to read.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Pick {
    /// Message number `n` (0-based, in file order).
    Index(usize),
    /// The message whose log time is nearest to this time (nanoseconds since the epoch; the
    /// earlier one on a tie).
    Time(u64),
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
    read_bag_cloud_at(path, topic, Pick::Index(index), options)
}

/// Reads one PointCloud2 message of a bag, chosen by number or by time, as a cloud (see
/// [`read_bag_cloud`]). A pick by time reads the whole topic once.
pub fn read_bag_cloud_at(
    path: &Path,
    topic: Option<&str>,
    pick: Pick,
    options: &ReadOptions,
) -> Result<(PointCloud, ReadReport)> {
    let mut best: HashMap<String, u64> = HashMap::new();
    let topics = guarded(path, || {
        scan(path, |name, t, log_time, _| {
            let wanted = match topic {
                Some(want) => name == want,
                None => t.schema == POINT_CLOUD2,
            };
            if !wanted {
                return Ok(Visit::Skip);
            }
            Ok(match pick {
                Pick::Index(n) if t.messages == n && topic.is_some() => Visit::KeepAndStop,
                Pick::Index(n) if t.messages == n => Visit::Keep,
                Pick::Index(_) => Visit::Skip,
                Pick::Time(at) => {
                    let d = log_time.abs_diff(at);
                    match best.get(name) {
                        Some(&b) if b <= d => Visit::Skip,
                        _ => {
                            best.insert(name.to_owned(), d);
                            Visit::Keep
                        }
                    }
                }
            })
        })
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
            index: match pick {
                Pick::Index(n) => n,
                Pick::Time(_) => 0,
            },
            messages: t.messages,
        });
    };
    let index = t.picked_index;
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

/// Every pose on a topic of a bag (Odometry, PoseStamped or TFMessage; see [`BagPose`]), in
/// file order. With `child_frame`, only transforms of that child frame are kept (for `/tf`).
pub fn read_bag_poses(path: &Path, topic: &str, child_frame: Option<&str>) -> Result<Vec<BagPose>> {
    let mut out = Vec::new();
    let topics = guarded(path, || {
        scan(path, |name, t, log_time, bytes| {
            if name != topic || t.encoding != CDR {
                return Ok(Visit::Skip);
            }
            let poses =
                poses::decode_poses(&t.schema, bytes, log_time).map_err(|(offset, problem)| {
                    CloudError::BadMessage {
                        path: path_buf(path),
                        topic: name.to_owned(),
                        index: t.messages,
                        offset,
                        problem: Box::new(problem),
                    }
                })?;
            if let Some(poses) = poses {
                out.extend(
                    poses
                        .into_iter()
                        .filter(|p| child_frame.is_none_or(|c| p.child_frame_id == c)),
                );
            }
            Ok(Visit::Skip)
        })
    })?;
    let pose_topics: Vec<String> = topics
        .iter()
        .filter(|(_, t)| POSE_SCHEMAS.contains(&t.schema.as_str()))
        .map(|(name, _)| name.clone())
        .collect();
    let problem = match topics.get(topic) {
        None => format!("no topic {topic:?}"),
        Some(t) if !POSE_SCHEMAS.contains(&t.schema.as_str()) || t.encoding != CDR => format!(
            "topic {topic}: schema {:?} with encoding {:?} holds no poses",
            t.schema, t.encoding
        ),
        Some(_) => return Ok(out),
    };
    Err(CloudError::PoseTopic {
        path: path_buf(path),
        problem,
        pose_topics,
    })
}

/// A bag's poses on one topic as a track: in time order, each pose's time its `header.stamp`
/// (its log time when unstamped), looked up at a scan's time by [`interpolate`].
#[derive(Debug, Clone, PartialEq)]
pub struct PoseTrack {
    /// The poses, `stamp_ns` the time they hold, sorted by it.
    pub poses: Vec<BagPose>,
    /// A time more than this from both poses around it has no pose.
    pub max_gap_ns: i64,
}

impl PoseTrack {
    /// Reads the poses of `topic` (see [`read_bag_poses`]); `max_gap_s` bounds interpolation.
    pub fn read(
        path: &Path,
        topic: &str,
        child_frame: Option<&str>,
        max_gap_s: f64,
    ) -> Result<PoseTrack> {
        let mut poses = read_bag_poses(path, topic, child_frame)?;
        for p in &mut poses {
            p.stamp_ns = message_time_ns(p.stamp_ns, p.log_time_ns);
        }
        poses.sort_by_key(|p| p.stamp_ns);
        Ok(PoseTrack {
            poses,
            max_gap_ns: (max_gap_s * 1e9).min(i64::MAX as f64) as i64,
        })
    }

    /// The pose at a scan's time, `None` outside the track or in a gap.
    pub fn at(&self, scan: &BagScan) -> Option<BagPose> {
        interpolate(
            &self.poses,
            message_time_ns(scan.stamp_ns, scan.log_time_ns),
            self.max_gap_ns,
        )
    }
}

/// A message's time: its `header.stamp`, or its log time when it is unstamped (0).
pub fn message_time_ns(stamp_ns: i64, log_time_ns: u64) -> i64 {
    if stamp_ns != 0 {
        stamp_ns
    } else {
        i64::try_from(log_time_ns).unwrap_or(i64::MAX)
    }
}

/// One point cloud message of a bag, decoded.
#[derive(Debug, Clone)]
pub struct BagScan {
    /// Its number in the topic (0-based, file order).
    pub index: usize,
    /// Its log time in the bag, nanoseconds since the epoch.
    pub log_time_ns: u64,
    /// Its `header.stamp`, nanoseconds since the epoch.
    pub stamp_ns: i64,
    /// Its `header.frame_id`.
    pub frame_id: String,
    /// The points.
    pub cloud: PointCloud,
}

/// Whether [`for_each_bag_cloud`] goes on after a scan.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Next {
    /// Read the next scan.
    Continue,
    /// End the pass.
    Stop,
}

/// Decodes every message of a PointCloud2 `topic` in one pass over the bag, in file order,
/// handing each to `f` (memory: one scan at a time). Returns the number of messages handed
/// over.
pub fn for_each_bag_cloud(
    path: &Path,
    topic: &str,
    options: &ReadOptions,
    mut f: impl FnMut(BagScan) -> Next,
) -> Result<usize> {
    let mut handed = 0;
    let topics = guarded(path, || {
        scan(path, |name, t, log_time, bytes| {
            if name != topic || t.schema != POINT_CLOUD2 || t.encoding != CDR {
                return Ok(Visit::Skip);
            }
            let bad = |(offset, problem): (u64, MessageProblem)| CloudError::BadMessage {
                path: path_buf(path),
                topic: name.to_owned(),
                index: t.messages,
                offset,
                problem: Box::new(problem),
            };
            let msg = decode_point_cloud2(bytes).map_err(bad)?;
            let (cloud, _) = points_of(path, &msg, options)
                .map_err(bad)?
                .map_err(|source| CloudError::InMessage {
                    topic: name.to_owned(),
                    index: t.messages,
                    source: Box::new(source),
                })?;
            handed += 1;
            let next = f(BagScan {
                index: t.messages,
                log_time_ns: log_time,
                stamp_ns: msg.stamp_ns,
                frame_id: msg.layout.frame_id.clone(),
                cloud,
            });
            Ok(match next {
                Next::Continue => Visit::Skip,
                Next::Stop => Visit::Stop,
            })
        })
    })?;
    match topics.get(topic) {
        Some(t) if t.schema == POINT_CLOUD2 && t.encoding == CDR => Ok(handed),
        Some(t) => Err(CloudError::WrongSchema {
            path: path_buf(path),
            topic: topic.to_owned(),
            schema: t.schema.clone(),
            encoding: t.encoding.clone(),
        }),
        None => Err(CloudError::Topic {
            path: path_buf(path),
            problem: format!("no topic {topic:?}"),
            point_cloud_topics: topics
                .iter()
                .filter(|(_, t)| t.schema == POINT_CLOUD2)
                .map(|(name, _)| name.clone())
                .collect(),
        }),
    }
}
