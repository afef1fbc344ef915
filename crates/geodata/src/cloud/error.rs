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
    #[error("{path}: unknown point cloud format {extension:?}; use .ply, .pcd, .las, .laz or .bin (KITTI)")]
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

/// Shorthand for results of this module.
pub type Result<T> = std::result::Result<T, CloudError>;
