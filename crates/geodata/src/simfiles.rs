//! The files of the simulated datasets (`urbansem sim dataset`) that more than one crate
//! reads: serde types shared by the simulator that writes them (`geosim::dataset`) and the
//! readers (`srtree::dataset` reads the outlines), so writer and reader cannot drift apart.

use serde::{Deserialize, Serialize};

/// The true pose of one localization scan as written to `truth.json`: in the map's frame
/// (through the map-error field), and in the world.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct TruthPose {
    /// Sensor origin east, metres in the local frame.
    pub x: f64,
    /// Sensor origin north, metres in the local frame.
    pub y: f64,
    /// Sensor origin height above the street surface, metres.
    pub z: f64,
    /// Heading counter-clockwise from geographic east, radians.
    pub yaw: f64,
    /// WGS84 latitude, degrees.
    pub lat: f64,
    /// WGS84 longitude, degrees.
    pub lon: f64,
    /// Heading counter-clockwise from the local frame's x axis, radians.
    pub yaw_grid: f64,
    /// Sensor origin east in the simulated world (before the map error), metres.
    pub world_x: f64,
    /// Sensor origin north in the simulated world, metres.
    pub world_y: f64,
    /// Heading in the world, counter-clockwise from geographic east, radians.
    pub world_yaw: f64,
    /// Heading in the world, counter-clockwise from the local frame's x axis, radians.
    pub world_yaw_grid: f64,
}

/// File of a relations dataset holding the map's building outlines near its scenes.
pub const MAP_BUILDINGS_FILE: &str = "map_buildings.json";

/// The map's building outlines near a dataset's scenes, in the scenes' local frame: what a
/// robot that knows its OSM map knows about the buildings it sees (with map error on, the
/// map's outlines, not the simulated world's).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapBuildings {
    /// Frame of the outlines: `local`, the frame of the scenes' viewpoints and clouds.
    pub frame: String,
    /// The buildings within reach of a scene.
    pub buildings: Vec<MapBuilding>,
}

/// One map building of [`MapBuildings`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MapBuilding {
    /// Id of the OSM way or relation.
    pub osm_id: i64,
    /// Outer ring, counter-clockwise, last vertex not repeated, metres.
    pub outer: Vec<[f64; 2]>,
}
