//! Global localization of one gravity-levelled 3-D scan on OSM building outlines (thesis ch. 5).
//!
//! Where it sits in the pipeline: reads the OSM map and the scan through `geodata`, and
//! returns ranked candidate poses in the map's local frame (and WGS84).
