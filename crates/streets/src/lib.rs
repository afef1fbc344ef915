//! Street geometry (offset and width per OSM street segment) from point clouds and OSM (thesis ch. 4).
//!
//! Where it sits in the pipeline: reads the OSM street network and a registered point cloud
//! through `geodata`, and returns per-segment width and offset estimates.
