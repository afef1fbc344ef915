//! The error type of the `srtree` crate.

use std::path::PathBuf;
use thiserror::Error;

/// Why a map, model or dataset could not be built, read or used.
#[derive(Debug, Error)]
pub enum SrtreeError {
    /// A file could not be read or written.
    #[error("{path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        source: std::io::Error,
    },
    /// A map file does not start with the SRTree magic bytes.
    #[error("{path}: not an SRTree map file (magic bytes {found:?}, expected {expected:?})")]
    BadMagic {
        /// The file.
        path: PathBuf,
        /// The first bytes found.
        found: Vec<u8>,
        /// The magic expected.
        expected: &'static [u8],
    },
    /// A map file of a format version this build cannot read.
    #[error("{path}: SRTree format version {version}, this build reads version {supported}")]
    UnsupportedVersion {
        /// The file.
        path: PathBuf,
        /// The version in the file.
        version: u32,
        /// The version this build reads.
        supported: u32,
    },
    /// A map file ends before a section is complete.
    #[error("{path}: truncated at byte {offset} while reading {what} (file is {len} bytes)")]
    Truncated {
        /// The file.
        path: PathBuf,
        /// Byte offset where more data was needed.
        offset: usize,
        /// The field or section being read.
        what: &'static str,
        /// File length in bytes.
        len: usize,
    },
    /// A map file holds a value that cannot be right.
    #[error("{path}: byte {offset}: {message}")]
    Malformed {
        /// The file.
        path: PathBuf,
        /// Byte offset of the bad value.
        offset: usize,
        /// What is wrong and what was expected.
        message: String,
    },
    /// The checksum at the end of a map file does not match its contents.
    #[error("{path}: checksum mismatch (stored {stored:#018x}, computed {computed:#018x}): the file is corrupted")]
    Checksum {
        /// The file.
        path: PathBuf,
        /// Checksum stored in the file.
        stored: u64,
        /// Checksum of the bytes read.
        computed: u64,
    },
    /// A point with a NaN or infinite coordinate.
    #[error("point {index} has a non-finite coordinate {position:?}")]
    NonFinite {
        /// Index of the point in its cloud.
        index: usize,
        /// Its position.
        position: [f64; 3],
    },
    /// A point too far from the origin for the cell grid (keys are 32-bit).
    #[error(
        "point {index} at {position:?} is outside the grid of ±{limit_m:.0} m at this resolution"
    )]
    OutOfGrid {
        /// Index of the point in its cloud.
        index: usize,
        /// Its position.
        position: [f64; 3],
        /// The largest coordinate magnitude the grid holds, metres.
        limit_m: f64,
    },
    /// An option outside its valid range.
    #[error("invalid option {name} = {value}: expected {expected}")]
    InvalidOption {
        /// Option name.
        name: &'static str,
        /// The value given.
        value: f64,
        /// What is valid.
        expected: &'static str,
    },
    /// Dirichlet fitting got too little data.
    #[error("cannot fit the Dirichlet of class {class}: {message}")]
    Fit {
        /// Class name.
        class: String,
        /// What was missing.
        message: String,
    },
    /// A cloud without the columns a step needs.
    #[error("{what} needs a cloud with a `{column}` column")]
    MissingColumn {
        /// The step.
        what: &'static str,
        /// The column name.
        column: &'static str,
    },
    /// A relations dataset file is malformed.
    #[error("{path}: {message}")]
    Dataset {
        /// The file.
        path: PathBuf,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A relation model file that does not fit this build (other feature count, wrong
    /// dimensions, non-finite values).
    #[error("{path}: not a usable relation model: {message}")]
    Model {
        /// The file.
        path: PathBuf,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A cross-dataset split whose test dataset is among its training datasets.
    #[error("{path} is the test dataset; a cross-dataset split trains on other datasets")]
    TestAmongTraining {
        /// The training folder that is the test folder.
        path: PathBuf,
    },
    /// A point cloud could not be read.
    #[error(transparent)]
    Cloud(#[from] geodata::cloud::CloudError),
    /// Training data without both classes or without samples.
    #[error("cannot train the {relation} classifier: {message}")]
    Training {
        /// The relation.
        relation: String,
        /// What was missing.
        message: String,
    },
    /// The consistency MLN could not be built or grounded.
    #[error("relation MLN: {0}")]
    Mln(String),
    /// A step of a job failed (loading, training, writing …).
    #[error(transparent)]
    Context(#[from] geodata::context::ContextError),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, SrtreeError>;

/// A closure turning an I/O error into [`SrtreeError::Io`] naming `path`.
pub(crate) fn io_err(path: &std::path::Path) -> impl FnOnce(std::io::Error) -> SrtreeError + '_ {
    move |source| SrtreeError::Io {
        path: path.to_path_buf(),
        source,
    }
}
