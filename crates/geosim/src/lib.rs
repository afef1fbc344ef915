//! The urban scan simulator: a procedural city, a labelled 3-D world built from an OSM map,
//! a LiDAR ray-cast into it, and datasets with exact ground truth.
//!
//! Where it sits in the pipeline: beside the real data, below nothing but `geodata` (maps,
//! clouds, the dataset file types of `geodata::simfiles`). The estimators (`srtree`,
//! `streets`, `localize`) never depend on it; their tests and benches, the binary's `sim`
//! command and the demo do.
//!
//! The thesis' Munich and Bremen scans are not available, so every accuracy number of
//! `streets`, `localize` and `srtree` on simulated data comes from here. Modules, in
//! data-flow order:
//!
//! - [`city`]: a seeded procedural city written as OSM XML (the embedded default map).
//! - [`truth`]: the true street geometry per OSM segment (offset dₛ, width wₛ, sidewalk
//!   width), tagged where OSM says so, else seeded and smoothly varying along each way.
//! - [`scene`]: the world: extruded buildings (with an optional OSM map-error model),
//!   ground (street at z = 0, 0.15 m kerbs, sidewalks, plazas, grass) and clutter a map
//!   does not have (parked cars, trees, poles, bicycles, pedestrians, fences).
//! - [`ground`]: the ground's materials per surface, markings, wet patches and lowered kerbs.
//! - [`raycast`]: ray casting against the scene with a uniform 2-D grid (Amanatides–Woo
//!   traversal) and an analytic ground.
//! - [`sensor`]: a panoramic terrestrial scanner (angular steps, range limit, range noise,
//!   dropouts) returning a labelled [`geodata::cloud::PointCloud`].
//! - [`figure`]: a picture of the world around a point (streets, buildings vs map, clutter).
//! - [`dataset`]: `localization`, `streets` and `relations` datasets written as PLY + JSON.
//! - [`job`]: `sim dataset` as one call ([`job::write_dataset`]): kind, map, overrides.
//! - [`sequence`]: a `localization` dataset read back as a `geodata` `LidarSequence`.
//!
//! Every random step takes a seed and draws from its own stream ([`stream_rng`]), so a
//! result does not depend on thread scheduling: same seed, byte-identical output.
//!
//! ```
//! use geosim::city::{generate_city, CityOptions};
//! use geodata::osm::OsmMap;
//! use geosim::{scene::{Scene, SceneOptions}, sensor::{scan, Pose, SensorOptions}};
//! let xml = generate_city(&CityOptions { size_m: 300.0, ..CityOptions::default() }, 2).unwrap();
//! let map = OsmMap::from_xml_str(&xml).unwrap();
//! let scene = Scene::build(&map, &SceneOptions::default(), 7).unwrap();
//! let pose = scene.sample_sidewalk_poses(1, 7).unwrap()[0];
//! let sensor = SensorOptions { h_step_deg: 2.0, v_step_deg: 2.0, ..SensorOptions::default() };
//! let cloud = scan(&scene, &pose, &sensor, 7).unwrap();
//! assert!(cloud.len() > 1000);
//! ```

pub mod city;
pub mod dataset;
pub mod figure;
pub mod ground;
pub mod job;
pub mod raycast;
pub mod scene;
pub mod sensor;
pub mod sequence;
pub mod truth;

use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use std::path::PathBuf;
use thiserror::Error;

/// Why a simulation could not run.
#[derive(Debug, Error)]
pub enum SimError {
    /// An option is out of range.
    #[error("invalid simulator option {name} = {value}: {expected}")]
    InvalidOption {
        /// Option name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is accepted.
        expected: &'static str,
    },
    /// The map has nothing to simulate.
    #[error(
        "the map has no buildings and no streets to simulate (check that the file covers a town)"
    )]
    EmptyMap,
    /// No pose could be placed.
    #[error("could not place {wanted} sensor poses on sidewalks after {tries} tries (found {found}); the map may have no streets with sidewalks")]
    NoPoses {
        /// Poses asked for.
        wanted: usize,
        /// Poses found.
        found: usize,
        /// Attempts made.
        tries: usize,
    },
    /// A drive did not pass enough places for car-mounted scans.
    #[error("could not place {wanted} car-mounted scans with buildings in view along a {route_m:.0} m drive (found {found}); the map may have few drivable streets among buildings")]
    NoCarPoses {
        /// Scans asked for.
        wanted: usize,
        /// Scans found.
        found: usize,
        /// Length of the drive, metres.
        route_m: f64,
    },
    /// A route for the streets dataset could not be found.
    #[error("no drivable street in the map to drive a route along")]
    NoRoute,
    /// Writing a dataset file failed.
    #[error("writing {path}: {source}")]
    Io {
        /// File being written.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Writing a point cloud failed.
    #[error(transparent)]
    Cloud(#[from] geodata::cloud::CloudError),
    /// Serialising JSON failed.
    #[error("serialising {path}: {source}")]
    Json {
        /// File being written.
        path: PathBuf,
        /// Cause.
        source: serde_json::Error,
    },
}

/// SplitMix64 finaliser: a well-mixed 64-bit hash of one word.
pub fn mix64(mut z: u64) -> u64 {
    z = z.wrapping_add(0x9E37_79B9_7F4A_7C15);
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// The random stream `(seed, purpose, index)`: independent of every other stream and of order.
pub fn stream_rng(seed: u64, purpose: u64, index: u64) -> ChaCha8Rng {
    ChaCha8Rng::seed_from_u64(mix64(mix64(seed ^ mix64(purpose)) ^ index))
}

/// Stream purposes (the `purpose` argument of [`stream_rng`]).
pub(crate) mod purpose {
    pub const STREET_WAY: u64 = 1;
    pub const STREET_SEGMENT: u64 = 2;
    pub const MAP_ERROR: u64 = 3;
    pub const EXTRA_BUILDINGS: u64 = 4;
    pub const HEIGHT: u64 = 5;
    pub const CLUTTER: u64 = 6;
    pub const POSES: u64 = 7;
    pub const SENSOR_COLUMN: u64 = 8;
    pub const ROUTE: u64 = 9;
    pub const ANNOTATOR: u64 = 10;
}

/// Standard normal sample (Box–Muller; one draw per call, deterministic for the stream).
pub(crate) fn normal(rng: &mut impl rand::Rng) -> f64 {
    let u1: f64 = rng.gen_range(f64::EPSILON..1.0);
    let u2: f64 = rng.gen::<f64>();
    (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::Rng;

    #[test]
    fn streams_are_reproducible_and_distinct() {
        let a: u64 = stream_rng(1, 2, 3).gen();
        let b: u64 = stream_rng(1, 2, 3).gen();
        let c: u64 = stream_rng(1, 2, 4).gen();
        let d: u64 = stream_rng(1, 3, 3).gen();
        assert_eq!(a, b);
        assert_ne!(a, c);
        assert_ne!(a, d);
    }

    #[test]
    fn normal_has_unit_variance() {
        let mut rng = stream_rng(5, 0, 0);
        let n = 20_000;
        let xs: Vec<f64> = (0..n).map(|_| normal(&mut rng)).collect();
        let mean = xs.iter().sum::<f64>() / n as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / n as f64;
        assert!(mean.abs() < 0.03, "mean {mean}");
        assert!((var - 1.0).abs() < 0.05, "variance {var}");
    }
}
