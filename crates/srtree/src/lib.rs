//! The semantic R-tree map (SRTree) and spatial relations with MLN consistency (thesis §3.3).
//!
//! Where it sits in the pipeline: it reads labelled point clouds and relations datasets
//! through `geodata` and runs its consistency inference on `mln` (which minimises on `pbo`).
//! The `urbansem map …` and `urbansem relations …` commands are thin wrappers around it.
//! Modules, in data-flow order:
//!
//! - [`dirichlet`]: per-class Dirichlet over cell class histograms, moment matching, label choice.
//! - [`map`]: occupancy cells kept where occupied, R-tree index, queries, ray casting.
//! - [`scans`]: the real labelled scans of `../shared/data/lidar/`, registered with their poses.
//! - [`label_eval`]: Dirichlet label choice against majority vote on the real scans.
//! - [`objects`]: per object cells, centroid, class, oriented box (normal-histogram yaw).
//! - [`boxes`]: annotated boxes, how a box looks from a viewpoint, the map's building outlines.
//! - [`view`]: an object seen from a viewpoint (cells, azimuths, hulls, contact), occlusion.
//! - [`amodal`]: class priors for what a scan does not show of an object (learnt on annotated boxes).
//! - [`features`]: pairwise features of two objects in a viewpoint frame.
//! - [`svm`]: linear SVM by dual coordinate descent (liblinear), cross-validation.
//! - [`consistency`]: the relation MLN (thesis knowledge base), MAP by `mln`, weight learning.
//! - [`rules`]: conjunctive threshold rules learnt per relation, one more SVM feature.
//! - [`relations`]: training, inference, relation graph and Table 3.6 evaluation.
//! - [`dataset`]: reader of simulated `relations` datasets.
//! - [`graph`]: the spatial relation graph and its queries.
//! - [`semantic`]: the semantic map: the cells of [`map`] and the relation graph over their objects.
//! - [`io`]: the documented binary `.srt` file of a semantic map.
//! - [`export`]: the map as files other tools open (PLY and ROS 2 bags with class and object).
//! - [`report`]: what `map build` and `map query` print, as typed values.
//! - [`jobs`]: `relations train` and `relations eval` as library calls returning their results.
//!
//! ```
//! use srtree::map::{MapOptions, SrMap};
//! let map = SrMap::new(MapOptions { resolution_m: 0.2, ..MapOptions::default() })?;
//! assert!(map.is_empty());
//! # Ok::<(), srtree::SrtreeError>(())
//! ```

pub mod amodal;
pub mod boxes;
pub mod consistency;
pub mod dataset;
pub mod dirichlet;
pub mod error;
pub mod export;
pub mod features;
pub mod graph;
pub mod io;
pub mod jobs;
pub mod label_eval;
pub mod map;
pub mod objects;
pub mod relations;
pub mod report;
pub mod rules;
pub mod scans;
pub mod semantic;
pub mod svm;
pub mod view;

pub use error::{Result, SrtreeError};
