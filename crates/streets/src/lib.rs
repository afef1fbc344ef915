//! Street geometry (offset and width per OSM street segment) from point clouds and OSM (thesis ch. 4).
//!
//! Where it sits in the pipeline: reads the OSM street network and a registered point cloud
//! through `geodata`, and returns per-segment width and offset estimates. Modules, in
//! data-flow order:
//!
//! - [`grid`]: square bins with their points (a generic raster used by corridors and scans).
//! - [`corridor`]: the 40 m corridor of a segment, masked near intersections, in 0.2 m bins.
//! - [`features`]: the per-bin features of §4.4.2 (z, normal, intensity, RGB/HSV histograms).
//! - [`svm`]: an RBF-kernel SVM trained by SMO with a kernel cache (libsvm's algorithm).
//! - [`potentials`]: segment geometry potentials of eq. 4.2 by the column-count DP of eq. 4.4,
//!   priors and the intersegment potentials.
//! - [`prior`]: geometry priors per OSM tag group (`width`, `lanes`, `highway` class).
//! - [`inference`]: exact max-product on trees, loopy max-product, and parallel MCMC.
//! - [`model`]: the trained model (bin classifier and prior) and the per-segment estimate.
//! - [`tiles`]: the estimate tile by tile, each tile reading its segments' coupling components (exact).
//! - [`dataset`]: the simulator's `streets` dataset format.
//! - [`real`]: real labelled sequences (KITTI-360, MCD) as datasets, truth from their labels.
//! - [`eval`]: the 5-fold round robin evaluation of Table 4.1.
//! - [`geojson`]: WGS84 polygons per segment.
//! - [`kitti`]: the bin classifier on real KITTI-360 scans.
//! - [`jobs`]: `streets eval`, `eval-real` and `kitti` as library calls returning reports.
//! - [`synthetic`]: labelled ground clouds with known geometry (test fixtures).

pub mod corridor;
pub mod dataset;
pub mod eval;
pub mod features;
pub mod geojson;
pub mod grid;
pub mod inference;
pub mod jobs;
pub mod kitti;
pub mod model;
pub mod potentials;
pub mod prior;
pub mod real;
pub mod svm;
pub mod synthetic;
pub mod tiles;
pub mod transfer;

use std::path::PathBuf;
use thiserror::Error;

/// Why a street-geometry step failed.
#[derive(Debug, Error)]
pub enum StreetsError {
    /// The map has no street segments.
    #[error("the map {path} has no street segments (no highway=* ways); check that the extract covers streets")]
    NoStreets {
        /// Map file.
        path: String,
    },
    /// No point of the cloud lies in any segment corridor.
    #[error("the cloud {cloud} does not overlap the map's streets: cloud x {cx0:.1}..{cx1:.1}, y {cy0:.1}..{cy1:.1} m, streets x {sx0:.1}..{sx1:.1}, y {sy0:.1}..{sy1:.1} m in the map's local frame; check that both are in the same frame")]
    NoOverlap {
        /// Cloud file.
        cloud: String,
        /// Cloud min x.
        cx0: f64,
        /// Cloud max x.
        cx1: f64,
        /// Cloud min y.
        cy0: f64,
        /// Cloud max y.
        cy1: f64,
        /// Streets min x.
        sx0: f64,
        /// Streets max x.
        sx1: f64,
        /// Streets min y.
        sy0: f64,
        /// Streets max y.
        sy1: f64,
    },
    /// Every segment is shorter than one bin (or masked entirely).
    #[error("all {segments} street segments are shorter than one {bin_m} m bin outside the intersection masks; nothing to estimate")]
    SegmentsTooShort {
        /// Number of segments.
        segments: usize,
        /// Bin size.
        bin_m: f64,
    },
    /// The cloud has no label column where one is needed.
    #[error("the cloud {path} has no label column; training and evaluation need labelled points")]
    NoLabels {
        /// Cloud file.
        path: String,
    },
    /// Not enough labelled bins of both classes to train.
    #[error(
        "cannot train: {positives} street and {negatives} non-street bins (need both classes)"
    )]
    OneClass {
        /// Positive bins.
        positives: usize,
        /// Negative bins.
        negatives: usize,
    },
    /// A feature vector has the wrong length.
    #[error("feature vectors have {got} values, the model expects {expected}")]
    FeatureLength {
        /// Values given.
        got: usize,
        /// Values expected.
        expected: usize,
    },
    /// An option is out of range.
    #[error("invalid option {name} = {value}: {expected}")]
    InvalidOption {
        /// Option name.
        name: &'static str,
        /// Value given.
        value: f64,
        /// What is accepted.
        expected: &'static str,
    },
    /// A tile of a plan owns a segment the map does not have.
    #[error("tile {tile:?} owns segment {segment} but the map has {segments} street segments; check that the plan was made from this map")]
    TilePlan {
        /// The tile's key.
        tile: (i64, i64),
        /// The segment index.
        segment: usize,
        /// Segments in the map.
        segments: usize,
    },
    /// Two tiles report the same segment.
    #[error("segment {segment} is reported by tiles {first:?} and {second:?}; merge the results of one plan, each tile once")]
    TileOverlap {
        /// The segment index.
        segment: usize,
        /// The first tile reporting it.
        first: (i64, i64),
        /// The second tile reporting it.
        second: (i64, i64),
    },
    /// A dataset file is malformed.
    #[error("{path}: {message}")]
    Dataset {
        /// File.
        path: PathBuf,
        /// What is wrong.
        message: String,
    },
    /// A model file is not valid JSON of a [`model::StreetModel`] or holds a value out of range.
    #[error("the model {path}: {message}")]
    Model {
        /// Model file.
        path: PathBuf,
        /// What is wrong (JSON line and column, or the field and its accepted range).
        message: String,
    },
    /// A labelled sequence whose drive has too few segments with a derived truth for the
    /// round-robin evaluation.
    #[error("{dataset}: the drive passes {passed} drivable segments of {map} but only {with_truth} have a derived truth (street-labelled points on both sides of the centre line, bounded by sidewalk, terrain or buildings, in at least {min_slices} slices); the {folds}-fold evaluation needs {folds}")]
    TooFewTruths {
        /// The sequence folder.
        dataset: PathBuf,
        /// The map.
        map: PathBuf,
        /// Drivable segments the drive passes.
        passed: usize,
        /// Of them, with a derived truth.
        with_truth: usize,
        /// Slices a truth needs.
        min_slices: usize,
        /// Folds of the evaluation.
        folds: usize,
    },
    /// Reading or writing a file failed.
    #[error("{path}: {cause}")]
    Io {
        /// File.
        path: PathBuf,
        /// Cause.
        cause: std::io::Error,
    },
    /// A cloud could not be read.
    #[error(transparent)]
    Cloud(#[from] geodata::cloud::CloudError),
    /// A map could not be read.
    #[error(transparent)]
    Osm(#[from] geodata::osm::OsmError),
    /// A step of a job failed (loading, evaluating, writing …).
    #[error(transparent)]
    Context(#[from] geodata::context::ContextError),
}

/// Shorthand for results of this crate.
pub type Result<T> = std::result::Result<T, StreetsError>;
