//! Global localization of one gravity-levelled 3-D scan on OSM building outlines (thesis ch. 5).
//!
//! Where it sits in the pipeline: reads the OSM map and the scan through `geodata`, and
//! returns ranked candidate poses in the map's local frame (and WGS84).
//!
//! Stages, one module each, in data-flow order:
//!
//! - [`sensor`]: the LiDAR's mount height, vertical field of view and beams (named profile or
//!   detected from the scan) and the extraction options that follow.
//! - [`level`]: the up direction of a tilted scan from its walls, and the scan levelled by it.
//! - [`surfaces`]: voxel downsampling, normals per occupied cell, cells with a horizontal
//!   normal (vertical surfaces) projected to the ground plane (§5.3.2).
//! - [`segments`]: one 2-D histogram per normal-yaw bin, the progressive probabilistic Hough
//!   transform (Matas et al. 2000) per histogram, merging of near-coincident segments.
//! - [`chamfer`]: map edges from the outlines and the directional distance-transform tensor
//!   of FDCM (Liu et al., CVPR 2010) with integral DTs and a lower-bound pyramid.
//! - [`feasible`]: the feasible poses (outside buildings, near streets) as a mask with an
//!   any-feasible pyramid, so that the search runs over them only (§5.3.4).
//! - [`candidates`]: exact branch-and-bound search of d_DCM (eq. 5.3) over rotation ×
//!   translation, every pose within a factor of the minimum, non-maximum suppression,
//!   filtering by buildings and streets (§5.3.4).
//! - [`visibility`]: the map edges visible from a position (angular sweep with occlusion).
//! - [`rank`]: forward, reverse and symmetric costs (eqs. 5.4, 5.5) per candidate, ranking,
//!   confidence.
//! - [`refine`]: continuous 2-D alignment of the best candidates.
//! - [`hashing`]: the geometric-hashing baseline of Cham et al. (2010).
//! - [`distractors`]: a map embedded among distractor buildings of another real map;
//!   [`facade_map`]: a building map drawn from the labelled scans of a real sequence.
//! - [`track`]: a window of scans tied by odometry, searched as one (localization along a
//!   track), odometry files and simulated drift.
//! - [`pipeline`]: the whole chain on one scan; [`eval`]: datasets and accuracy tables;
//!   [`extract_eval`]: extraction precision/recall on labelled real scans; [`report`]: the
//!   answers in WGS84 as the command line prints them; [`geojson`]: candidates and tracks as
//!   RFC 7946 GeoJSON; [`poses`]: track poses as TUM and KITTI trajectory files;
//!   [`figure`]: pictures of results;
//!   [`tiles`]: a map cut into tiles searched exactly as the whole map, [`crop`]: a tile's
//!   buildings and streets as a file;
//!   [`jobs`]: the command-line jobs (index, one scan file, a track folder, extraction
//!   scores) as library calls.

pub mod candidates;
pub mod chamfer;
mod codec;
pub mod crop;
pub mod distractors;
pub mod eval;
pub mod extract_eval;
pub mod facade_map;
pub mod feasible;
pub mod figure;
pub mod geojson;
pub mod graph;
pub mod hashing;
pub mod heading;
pub mod index;
pub mod jobs;
pub mod level;
pub mod pipeline;
pub mod poses;
pub mod rank;
pub mod refine;
pub mod report;
pub mod segments;
pub mod sensor;
pub mod surfaces;
pub mod tiles;
pub mod track;
pub mod visibility;

use geodata::osm::geometry::point_segment_distance;
use serde::Serialize;
use std::path::PathBuf;
use thiserror::Error;

/// A 2-D line segment, metres, in whatever frame its owner says.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Segment {
    /// Start point.
    pub a: [f64; 2],
    /// End point.
    pub b: [f64; 2],
}

impl Segment {
    /// A segment from `a` to `b`.
    pub fn new(a: [f64; 2], b: [f64; 2]) -> Segment {
        Segment { a, b }
    }

    /// Length in metres.
    pub fn length(&self) -> f64 {
        (self.b[0] - self.a[0]).hypot(self.b[1] - self.a[1])
    }

    /// Orientation of the line in [0, π) radians (direction sign ignored).
    pub fn orientation_rad(&self) -> f64 {
        wrap_pi(f64::atan2(self.b[1] - self.a[1], self.b[0] - self.a[0]))
    }

    /// The segment moved by a 2-D pose (rotation by `yaw_rad`, then translation).
    pub fn transformed(&self, pose: &Pose2) -> Segment {
        Segment {
            a: pose.apply(self.a),
            b: pose.apply(self.b),
        }
    }

    /// Euclidean distance from a point to the segment.
    pub fn distance_to(&self, p: [f64; 2]) -> f64 {
        point_segment_distance(p, self.a, self.b)
    }
}

/// The rotation that levels a sensor frame whose orientation is `rotation` (sensor → a
/// gravity-aligned frame) with heading `yaw`: Rz(−yaw)·R, roll and pitch removed, x forward.
pub fn levelling_rotation(rotation: &[[f64; 3]; 3], yaw: f64) -> [[f64; 3]; 3] {
    let (s, c) = yaw.sin_cos();
    std::array::from_fn(|i| {
        std::array::from_fn(|j| match i {
            0 => c * rotation[0][j] + s * rotation[1][j],
            1 => -s * rotation[0][j] + c * rotation[1][j],
            _ => rotation[2][j],
        })
    })
}

/// A planar pose: the sensor's position and heading in the map's local frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Pose2 {
    /// East, metres.
    pub x: f64,
    /// North, metres.
    pub y: f64,
    /// Heading counter-clockwise from the local frame's x axis (grid east), radians.
    pub yaw_rad: f64,
}

impl Pose2 {
    /// Maps a point from the sensor frame into the map frame.
    pub fn apply(&self, p: [f64; 2]) -> [f64; 2] {
        let (s, c) = self.yaw_rad.sin_cos();
        [c * p[0] - s * p[1] + self.x, s * p[0] + c * p[1] + self.y]
    }

    /// Distance between the positions, metres.
    pub fn distance_to(&self, other: &Pose2) -> f64 {
        (self.x - other.x).hypot(self.y - other.y)
    }

    /// Absolute heading difference in [0, π], radians.
    pub fn yaw_error_to(&self, other: &Pose2) -> f64 {
        angle_diff(self.yaw_rad, other.yaw_rad)
    }

    /// This pose followed by `other` (other given in this pose's frame).
    pub fn compose(&self, other: &Pose2) -> Pose2 {
        let [x, y] = self.apply([other.x, other.y]);
        Pose2 {
            x,
            y,
            yaw_rad: self.yaw_rad + other.yaw_rad,
        }
    }

    /// The inverse transform: `p.inverse().compose(&p)` is the identity.
    pub fn inverse(&self) -> Pose2 {
        let (s, c) = self.yaw_rad.sin_cos();
        Pose2 {
            x: -(c * self.x + s * self.y),
            y: -(-s * self.x + c * self.y),
            yaw_rad: -self.yaw_rad,
        }
    }
}

/// Thresholds of an accurate pose.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Accuracy {
    /// Largest position error, metres.
    pub max_m: f64,
    /// Largest heading error, radians.
    pub max_rad: f64,
}

impl Accuracy {
    /// The thesis' thresholds for the chamfer methods: 4 m, 0.2 rad.
    pub const THESIS: Accuracy = Accuracy {
        max_m: 4.0,
        max_rad: 0.2,
    };
    /// The car-mounted targets' thresholds (issue 15): 2 m, 3°.
    pub const STRICT: Accuracy = Accuracy {
        max_m: 2.0,
        max_rad: 3.0 * (std::f64::consts::PI / 180.0),
    };
    /// The thesis' thresholds for the hashing baseline: 5 m, π/6.
    pub const HASHING: Accuracy = Accuracy {
        max_m: 5.0,
        max_rad: std::f64::consts::FRAC_PI_6,
    };

    /// Whether `pose` is accurate with respect to `truth`.
    pub fn accepts(&self, pose: &Pose2, truth: &Pose2) -> bool {
        pose.distance_to(truth) <= self.max_m && pose.yaw_error_to(truth) <= self.max_rad
    }
}

/// The odometry drift the track targets assume: 2 % of the distance travelled.
pub const ODOMETRY_SCALE_DRIFT: f64 = 0.02;
/// The odometry heading drift the track targets assume, degrees per 50 m travelled.
pub const ODOMETRY_YAW_DRIFT_DEG_PER_50M: f64 = 1.0;

/// Absolute difference of two angles in [0, π].
pub fn angle_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::TAU);
    d.min(std::f64::consts::TAU - d)
}

/// Absolute difference of two line orientations (period π) in [0, π/2].
pub fn orientation_diff(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(std::f64::consts::PI);
    d.min(std::f64::consts::PI - d)
}

/// An angle wrapped into [0, π).
pub fn wrap_pi(a: f64) -> f64 {
    let w = a.rem_euclid(std::f64::consts::PI);
    if w >= std::f64::consts::PI {
        0.0
    } else {
        w
    }
}

/// Why localization could not run.
#[derive(Debug, Error)]
pub enum LocalizeError {
    /// A scan point is NaN or infinite.
    #[error(
        "scan point {index} is not finite ({value:?}); check the scan file for NaN coordinates"
    )]
    NonFinitePoint {
        /// Index of the point in the scan.
        index: usize,
        /// Its coordinates.
        value: [f64; 3],
    },
    /// An option is out of range.
    #[error("invalid localization option {name} = {value}: {expected}")]
    InvalidOption {
        /// Option name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is accepted.
        expected: &'static str,
    },
    /// The map's distance-transform grid would be too large.
    #[error("the map spans {width_m:.0} m × {height_m:.0} m, more than {max_cells} grid cells at {grid_m} m; use a coarser grid or a smaller extract")]
    MapTooLarge {
        /// Width of the edge bounding box, metres.
        width_m: f64,
        /// Height of the edge bounding box, metres.
        height_m: f64,
        /// Grid resolution, metres.
        grid_m: f64,
        /// Cell limit.
        max_cells: usize,
    },
    /// A map that must have buildings has none.
    #[error("{what} has no building outlines; check that the extract covers built-up land")]
    NoBuildings {
        /// Which map.
        what: &'static str,
    },
    /// A dataset file is malformed or missing.
    #[error("{path}: {message}")]
    Dataset {
        /// File.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// An odometry file has a malformed line, or does not match the scans.
    #[error("{path}:{line}: {message}")]
    Odometry {
        /// File.
        path: PathBuf,
        /// 1-based line (the last line for a count mismatch).
        line: usize,
        /// What is wrong and what was expected.
        message: String,
    },
    /// A map index is unreadable, corrupt or stale.
    #[error("map index {path}: {message}")]
    Index {
        /// The index file.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
    /// A prepared map (index) was built with other options than the search asks for.
    #[error("the map index was prepared with other options ({differences}); pass the index's options or rebuild it with `urbansem localize index`")]
    PrepMismatch {
        /// The differing options.
        differences: String,
    },
    /// `--distractors` was combined with a map index: distractors change the map, so they
    /// need the OSM map itself.
    #[error("--distractors changes the map, so it needs the OSM map, not the index {path}")]
    DistractorsNeedOsmMap {
        /// The index given as the map.
        path: PathBuf,
    },
    /// Reading or writing a file failed.
    #[error("{action} {path}")]
    Io {
        /// What was being done (`writing`, `creating`, `listing`).
        action: &'static str,
        /// The file or folder.
        path: PathBuf,
        /// The cause.
        #[source]
        source: std::io::Error,
    },
    /// A step failed; `context` says which step and on what.
    #[error("{context}")]
    Context {
        /// The step, e.g. `loading the map M`.
        context: String,
        /// The cause.
        #[source]
        source: Box<LocalizeError>,
    },
    /// Reading a point cloud failed.
    #[error(transparent)]
    Cloud(#[from] geodata::cloud::CloudError),
    /// Reading an OSM map failed.
    #[error(transparent)]
    Osm(#[from] geodata::osm::OsmError),
    /// Reading a real dataset failed.
    #[error(transparent)]
    RealDataset(#[from] geodata::datasets::DatasetError),
}

/// Result type of this crate.
pub type Result<T> = std::result::Result<T, LocalizeError>;

/// Adds the step that failed to an error, as the command line reports it (`step: cause`).
pub trait WithContext<T> {
    /// Wraps the error of `self` in [`LocalizeError::Context`] with the message `context()`.
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T>;
}

impl<T, E: Into<LocalizeError>> WithContext<T> for std::result::Result<T, E> {
    fn context_with(self, context: impl FnOnce() -> String) -> Result<T> {
        self.map_err(|e| LocalizeError::Context {
            context: context(),
            source: Box::new(e.into()),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pose_applies_rotation_then_translation() {
        let pose = Pose2 {
            x: 10.0,
            y: -2.0,
            yaw_rad: std::f64::consts::FRAC_PI_2,
        };
        let p = pose.apply([1.0, 0.0]);
        assert!((p[0] - 10.0).abs() < 1e-12 && (p[1] + 1.0).abs() < 1e-12);
    }

    #[test]
    fn angle_helpers() {
        assert!((angle_diff(0.1, std::f64::consts::TAU - 0.1) - 0.2).abs() < 1e-12);
        assert!((orientation_diff(0.05, std::f64::consts::PI - 0.05) - 0.1).abs() < 1e-12);
        let s = Segment::new([1.0, 1.0], [0.0, 0.0]);
        assert!((s.orientation_rad() - std::f64::consts::FRAC_PI_4).abs() < 1e-12);
    }
}
