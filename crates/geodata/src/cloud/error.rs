//! Errors of point cloud reading and writing: each names the file and where in it.

use std::fmt;
use std::path::PathBuf;
use thiserror::Error;

/// Where in a file an error was found.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Location {
    /// 1-based line of a text header or ASCII body.
    Line(usize),
    /// 0-based byte offset in a binary file.
    Byte(u64),
    /// 0-based point index (formats read through a library that hides offsets).
    Point(usize),
}

impl fmt::Display for Location {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Location::Line(l) => write!(f, "line {l}"),
            Location::Byte(b) => write!(f, "byte {b}"),
            Location::Point(p) => write!(f, "point {p}"),
        }
    }
}

/// An error while reading, writing or combining point clouds.
#[derive(Debug, Error)]
pub enum CloudError {
    /// The file could not be opened, read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// The extension names no supported format.
    #[error("{path}: unknown point cloud format {extension:?}; use .ply, .pcd, .las, .laz, .bin (KITTI) or .mcap (ROS 2 bag, read only)")]
    UnknownFormat {
        /// The file.
        path: PathBuf,
        /// Its extension (empty if none).
        extension: String,
    },
    /// The header is malformed or lacks a required entry.
    #[error("{path}: {at}: bad header: {message}")]
    Header {
        /// The file.
        path: PathBuf,
        /// Where.
        at: Location,
        /// What is wrong and what was expected.
        message: String,
    },
    /// The file ends before all points announced by its header (or a whole record) were read.
    #[error("{path}: {at}: file ends inside point {point} of {expected}; the file is truncated or its header count is wrong")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Where the data ran out.
        at: Location,
        /// Index of the incomplete point.
        point: usize,
        /// Points the header announced.
        expected: usize,
    },
    /// A value could not be parsed or is out of range for its field.
    #[error("{path}: {at}: bad value {value:?} for {field}")]
    BadValue {
        /// The file.
        path: PathBuf,
        /// Where.
        at: Location,
        /// The field (property) name.
        field: String,
        /// The offending text or number.
        value: String,
    },
    /// A point has a NaN or infinite coordinate.
    #[error("{path}: point {point} has a non-finite position {position:?} (PCL marks the invalid points of organized clouds so); skip and count such points with ReadOptions {{ drop_non_finite: true }} (`--drop-non-finite` on the command line)")]
    NonFinite {
        /// The file.
        path: PathBuf,
        /// Index of the point in the file.
        point: usize,
        /// Its coordinates.
        position: [f64; 3],
    },
    /// A `label` value is not one of urbansem's class ids.
    #[error("{path}: point {point}: label {value} is not an urbansem class id (0..=9); dataset ids belong in a raw_label column")]
    BadLabel {
        /// The file.
        path: PathBuf,
        /// Index of the point.
        point: usize,
        /// The value found.
        value: u64,
    },
    /// Data after the last announced point (PLY; PCD ignores it, as PCL does).
    #[error("{path}: {at}: {extra} bytes after the last point; the header count is wrong or the file is not this format")]
    TrailingData {
        /// The file.
        path: PathBuf,
        /// Where the extra data starts.
        at: Location,
        /// Number of extra bytes.
        extra: u64,
    },
    /// A valid file uses a feature this reader does not implement.
    #[error("{path}: unsupported: {what}")]
    Unsupported {
        /// The file.
        path: PathBuf,
        /// The feature.
        what: String,
    },
    /// Compressed data that its decoder cannot decode.
    #[error("{path}: {at}: corrupt compressed data: {message}")]
    Corrupt {
        /// The file.
        path: PathBuf,
        /// Where (point index when known, else byte 0).
        at: Location,
        /// What failed.
        message: String,
    },
    /// The `las` crate reported an error.
    #[error("{path}: {at}: LAS/LAZ: {source}")]
    Las {
        /// The file.
        path: PathBuf,
        /// Where (point index when known, else byte 0).
        at: Location,
        /// The crate's error.
        source: las::Error,
    },
    /// The MCAP container of a ROS 2 bag is malformed or ends early (the `mcap` crate's error).
    #[error("{path}: {at}: MCAP: {source}; the bag is truncated (a recording that did not finish?) or not an MCAP file")]
    Mcap {
        /// The bag.
        path: PathBuf,
        /// The byte offset in the bag where reading stopped.
        at: Location,
        /// The crate's error.
        source: Box<::mcap::McapError>,
    },
    /// A bag has no topic of the name asked for, or the choice of topic is ambiguous.
    #[error("{path}: {problem}; point cloud topics in this bag: {}", list_or_none(.point_cloud_topics))]
    Topic {
        /// The bag.
        path: PathBuf,
        /// What is wrong with the choice.
        problem: String,
        /// The bag's `sensor_msgs/msg/PointCloud2` topics.
        point_cloud_topics: Vec<String>,
    },
    /// A topic read as point clouds is not `sensor_msgs/msg/PointCloud2` in CDR.
    #[error("{path}: topic {topic}: schema {schema:?} with encoding {encoding:?}; expected \"sensor_msgs/msg/PointCloud2\" in \"cdr\"")]
    WrongSchema {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// Its schema name (empty without a schema).
        schema: String,
        /// Its message encoding.
        encoding: String,
    },
    /// A topic read as poses is missing or is not Odometry, PoseStamped or TFMessage in CDR.
    #[error("{path}: {problem}; pose topics (nav_msgs/msg/Odometry, geometry_msgs/msg/PoseStamped, tf2_msgs/msg/TFMessage) in this bag: {}", list_or_none(.pose_topics))]
    PoseTopic {
        /// The bag.
        path: PathBuf,
        /// What is wrong with the topic.
        problem: String,
        /// The bag's pose topics.
        pose_topics: Vec<String>,
    },
    /// A topic has fewer messages than the index asked for.
    #[error("{path}: topic {topic} has {messages} messages, so there is no message {index} (indices start at 0)")]
    NoMessage {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// The index asked for.
        index: usize,
        /// Messages on the topic.
        messages: usize,
    },
    /// A message's CDR bytes do not decode as the schema says.
    #[error("{path}: topic {topic} message {index}: byte {offset} of the message: {problem}")]
    BadMessage {
        /// The bag.
        path: PathBuf,
        /// The topic.
        topic: String,
        /// 0-based index of the message on its topic.
        index: usize,
        /// Byte offset within the message's CDR data (encapsulation header included).
        offset: u64,
        /// What is wrong.
        problem: Box<MessageProblem>,
    },
    /// A point of a decoded message is invalid (non-finite position, bad label, …).
    #[error("topic {topic} message {index}: {source}")]
    InMessage {
        /// The topic.
        topic: String,
        /// 0-based index of the message on its topic.
        index: usize,
        /// The point's error, naming the bag and the point.
        source: Box<CloudError>,
    },
    /// Two columns of one cloud disagree in length.
    #[error("column {column} has {len} values but the cloud has {points} points")]
    ColumnLength {
        /// The column.
        column: &'static str,
        /// Its length.
        len: usize,
        /// Number of positions.
        points: usize,
    },
}

/// What is wrong inside one ROS 2 message (see [`CloudError::BadMessage`]).
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum MessageProblem {
    /// The message ends inside a field.
    #[error("the message ends inside {field}: {need} bytes needed, {left} left")]
    Truncated {
        /// The field being read.
        field: &'static str,
        /// Bytes the field needs.
        need: u64,
        /// Bytes left in the message.
        left: u64,
    },
    /// The 4-byte encapsulation header names no plain CDR representation.
    #[error(
        "encapsulation {id:#06x} is not plain CDR (0x0000 big-endian or 0x0001 little-endian)"
    )]
    Encapsulation {
        /// The representation id.
        id: u16,
    },
    /// A string is not NUL-terminated UTF-8.
    #[error("{field} is not a NUL-terminated UTF-8 string")]
    BadString {
        /// The field.
        field: &'static str,
    },
    /// A coordinate field is missing.
    #[error("no point field {name:?} (fields: {fields}); a point cloud needs x, y and z")]
    MissingField {
        /// The missing field.
        name: &'static str,
        /// The fields the message has.
        fields: String,
    },
    /// A field's datatype is not one of `sensor_msgs/msg/PointField`'s eight.
    #[error(
        "point field {name:?} has datatype {datatype}; PointField defines 1 (INT8) to 8 (FLOAT64)"
    )]
    BadDatatype {
        /// The field.
        name: String,
        /// Its datatype.
        datatype: u8,
    },
    /// A coordinate field is an array.
    #[error("point field {name:?} has count {count}; a coordinate needs count 1")]
    CoordinateCount {
        /// The field.
        name: String,
        /// Its count.
        count: u32,
    },
    /// A field does not fit inside one point.
    #[error("point field {name:?} spans bytes {offset}..{end} but point_step is {point_step}")]
    FieldOutsidePoint {
        /// The field.
        name: String,
        /// Its offset in the point.
        offset: u32,
        /// One past its last byte.
        end: u64,
        /// Bytes per point.
        point_step: u32,
    },
    /// The point data does not hold width × height points of point_step bytes.
    #[error("width {width} × height {height} points of point_step {point_step} (row_step {row_step}) need {need} bytes of data, but data has {data}; the header or the data is wrong")]
    DataLength {
        /// Points per row.
        width: u32,
        /// Rows.
        height: u32,
        /// Bytes per point.
        point_step: u32,
        /// Bytes per row.
        row_step: u32,
        /// Bytes the header calls for: height × max(row_step, width × point_step).
        need: u128,
        /// Bytes of data present.
        data: u64,
    },
}

fn list_or_none(topics: &[String]) -> String {
    if topics.is_empty() {
        "none".to_owned()
    } else {
        topics.join(", ")
    }
}

/// Shorthand for results of this module.
pub type Result<T> = std::result::Result<T, CloudError>;
