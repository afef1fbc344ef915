//! Geographic ground truth for urbansem: OSM maps, point clouds, real scans, dataset files.
//!
//! Where it sits in the pipeline: every map capability (`srtree`, `streets`, `localize`)
//! reads its building outlines, street network and point clouds through this crate, all in
//! one local metric frame ([`projection::LocalFrame`]). Modules, in data-flow order:
//!
//! - [`projection`]: WGS84 ↔ local transverse-Mercator frame (east, north in metres).
//! - [`osm`]: `.osm` XML and `.osm.pbf` ingestion → buildings, street segments, intersections.
//! - [`classes`]: urbansem's semantic classes and the mapping from dataset ids.
//! - [`cloud`]: the column-wise [`cloud::PointCloud`] and its PLY/PCD/LAS/LAZ/KITTI IO.
//! - [`georef`]: the frame of a user's registered cloud (local, UTM, ENU) into the map's frame.
//! - [`mercator`]: scaled-Mercator georeferencing used by the KITTI and MCD datasets.
//! - [`datasets`]: readers for the real labelled scans in `../shared/data/lidar/`.
//! - [`sensors`]: named LiDAR models (beam elevations, azimuth step, range, mount height).
//! - [`simfiles`]: serde types of the simulated datasets' files (truth poses, map outlines).
//! - [`geojson`]: RFC 7946 output with the OSM attribution, and its validator.
//! - [`topview`]: a top-view raster of coloured points (highest point per pixel).
//! - [`svg`]: an SVG canvas in the local frame for pictures of maps and results.
//! - [`fsio`]: atomic output files (written beside the target, renamed into place).
//! - [`context`]: an error naming the step that failed, with its cause, for jobs.

pub mod classes;
pub mod cloud;
pub mod context;
pub mod datasets;
pub mod fsio;
pub mod geojson;
pub mod georef;
pub mod mercator;
pub mod osm;
pub mod projection;
pub mod sensors;
pub mod simfiles;
pub mod svg;
pub mod topview;
