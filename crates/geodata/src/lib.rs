//! Geographic ground truth for urbansem: OSM maps, point clouds, real scans, simulated scans.
//!
//! Where it sits in the pipeline: every map capability (`srtree`, `streets`, `localize`)
//! reads its building outlines, street network and point clouds through this crate, all in
//! one local metric frame ([`projection::LocalFrame`]). Modules, in data-flow order:
//!
//! - [`projection`]: WGS84 ↔ local transverse-Mercator frame (east, north in metres).
//! - [`osm`]: `.osm` XML and `.osm.pbf` ingestion → buildings, street segments, intersections.
//! - [`city`]: a seeded procedural city written as OSM XML (the embedded default map).
//! - [`classes`]: urbansem's semantic classes and the mapping from dataset ids.
//! - [`cloud`]: the column-wise [`cloud::PointCloud`] and its PLY/PCD/LAS/LAZ/KITTI IO.
//! - [`georef`]: the frame of a user's registered cloud (local, UTM, ENU) into the map's frame.
//! - [`mercator`]: scaled-Mercator georeferencing used by the KITTI and MCD datasets.
//! - [`datasets`]: readers for the real labelled scans in `../shared/data/lidar/`.
//! - [`sensors`]: named LiDAR models (beam elevations, azimuth step, range, mount height).
//! - [`fsio`]: atomic output files (written beside the target, renamed into place).
//! - [`sim`]: the urban scan simulator (scene from a map, ray-cast scanner, datasets with truth).

pub mod city;
pub mod classes;
pub mod cloud;
pub mod datasets;
pub mod fsio;
pub mod georef;
pub mod mercator;
pub mod osm;
pub mod projection;
pub mod sensors;
pub mod sim;
