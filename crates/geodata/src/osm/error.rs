//! Errors of OSM ingestion: each names the file and where in it reading failed.

use std::path::PathBuf;
use thiserror::Error;

/// Why an OSM file or string could not be read into an [`super::OsmMap`].
#[derive(Debug, Error)]
pub enum OsmError {
    /// The file could not be opened or read.
    #[error("{path}: cannot read OSM file: {source}")]
    Io {
        /// File that failed.
        path: PathBuf,
        /// Underlying I/O error.
        source: std::io::Error,
    },
    /// The extension is neither `.osm` nor `.osm.pbf` (nor `.pbf`).
    #[error("{path}: unknown OSM file extension; expected .osm (XML) or .osm.pbf (PBF)")]
    UnknownExtension {
        /// File that was given.
        path: PathBuf,
    },
    /// Malformed XML: quick-xml rejected the document at this byte offset.
    #[error("{source_name}: malformed OSM XML at byte {byte_offset}: {message}")]
    Xml {
        /// File name (or `<string>` for in-memory input).
        source_name: String,
        /// Byte offset where the parser stopped.
        byte_offset: u64,
        /// What the parser reported.
        message: String,
    },
    /// The XML ended before its elements were closed (a truncated file).
    #[error("{source_name}: OSM XML ends at byte {byte_offset} with {open_elements} element(s) still open (truncated file?)")]
    XmlTruncated {
        /// File name (or `<string>`).
        source_name: String,
        /// Byte offset of the end of input.
        byte_offset: u64,
        /// Number of elements not closed.
        open_elements: usize,
    },
    /// A required attribute is missing, not a number, out of range, or given twice.
    #[error("{source_name}: bad attribute `{attribute}` = {value:?} on <{element}> at byte {byte_offset}; expected {expected}")]
    BadAttribute {
        /// File name (or `<string>`).
        source_name: String,
        /// Byte offset of the element.
        byte_offset: u64,
        /// Element name.
        element: String,
        /// Attribute name.
        attribute: String,
        /// Value found (empty when missing).
        value: String,
        /// What the attribute must be (`a number`, `a latitude in [-90, 90]`, …).
        expected: &'static str,
    },
    /// The document root is not `<osm>` or the document is empty.
    #[error("{source_name}: not an OSM XML document (no <osm> root element)")]
    NotOsm {
        /// File name (or `<string>`).
        source_name: String,
    },
    /// A PBF blob could not be read or decoded (truncated or garbled file).
    #[error("{path}: bad PBF data in blob #{blob_index} (byte offset {byte_offset}): {message}")]
    Pbf {
        /// File that failed.
        path: PathBuf,
        /// Index of the blob (0 = header blob) where reading failed.
        blob_index: usize,
        /// Byte offset of the blob header in the file, when known.
        byte_offset: u64,
        /// What osmpbf reported.
        message: String,
    },
    /// The file contains no node with coordinates, so no frame can be placed.
    #[error("{source_name}: the map has no nodes; cannot place a local frame")]
    EmptyMap {
        /// File name (or `<string>`).
        source_name: String,
    },
    /// The frame origin derived from the bounds is invalid.
    #[error("{source_name}: {source}")]
    Frame {
        /// File name (or `<string>`).
        source_name: String,
        /// Projection error.
        source: crate::projection::ProjectionError,
    },
}
