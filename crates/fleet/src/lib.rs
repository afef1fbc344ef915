//! Fleet jobs as engine-neutral shards: `plan` splits a job into shards, `run` runs one shard
//! anywhere (a Ray task, a Slurm array index, a Kubernetes indexed job, a laptop loop) and
//! writes its checksummed result file, `merge` combines the results.
//!
//! Where it sits: on top of the library crates (`localize` over a tiled map, `streets`); the
//! binary's `urbansem shard plan|run|merge` and the Python package's
//! `urbansem.distributed.run_plan` call it.
//!
//! Modules in data-flow order: [`plan`] (the plan file and how a job is cut), [`run`] (one
//! shard, idempotent), [`merge`] (the combined result); [`streets`] and [`map`] hold the
//! street and map jobs' own steps, which `run` and `merge` dispatch to.
//!
//! **Localization over a tiled map** runs in stages; a shard of a stage reads only files the
//! shards of earlier stages wrote, so the stages run as waves of independent tasks:
//! 1. `extract`: per batch of scans, each scan's wall segments (the map plays no part);
//! 2. `minimum-0.3m`, `minimum-0.5m`, `minimum`: rounds per batch × tile, each scan's least
//!    search cost in the tile's core if it is below the round's cap (d_DCM 0.3 m, 0.5 m, none),
//!    only for the scans no earlier round found a pose for. A shard knows nothing of the other
//!    tiles; the cap stands in for the best cost found elsewhere, which the single-process search
//!    uses to prune, so that a tile far from the truth is not searched to its own (poor)
//!    minimum. Exact: the round whose cap first reaches the least cost over all tiles reports it
//!    from the tile that has it;
//! 3. `poses`: per batch × tile, each scan's poses within the factor of that least cost.
//!
//! The merge then runs suppression, filters, costs, refinement and ranking per scan on the
//! union, exactly as [`localize::tiles::localize_tiled`] does in one process (tested equal).
//!
//! **Street geometry** runs in one stage, `tiles`: a shard per street tile estimates the
//! segments the tile owns, reading their whole coupling components as a halo, and the merge
//! equals `StreetModel::estimate` on the whole map bit for bit (see [`streets`]).
//!
//! **Map building** runs in one stage, `map-tiles`: a shard per tile builds the semantic map
//! (`.srt`) of its core and of the objects it owns from the labelled clouds; the cores
//! partition the whole map's cells and the owned objects are the whole map's (see [`map`]).

pub mod map;
pub mod merge;
pub mod plan;
pub mod run;
pub mod streets;

use std::path::PathBuf;
use thiserror::Error;

/// Why a fleet step failed.
#[derive(Debug, Error)]
pub enum FleetError {
    /// A file could not be read or written.
    #[error("{path}: {message}")]
    Io {
        /// The file.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// A plan or result file is not what it should be.
    #[error("{path}: {message}")]
    Invalid {
        /// The file.
        path: PathBuf,
        /// What is wrong and what to do.
        message: String,
    },
    /// A shard needs results of an earlier stage that are not there yet.
    #[error("{plan}: {needed_by} needs the results of shards {missing:?} (stage {stage}) first; run them with `urbansem shard run PLAN --shard I`")]
    NotReady {
        /// The plan.
        plan: PathBuf,
        /// Which step needs them (`shard 7`, `the merge`).
        needed_by: String,
        /// Its stage's name.
        stage: String,
        /// The earlier shards without a finished result.
        missing: Vec<usize>,
    },
    /// The localization library failed.
    #[error(transparent)]
    Localize(#[from] localize::LocalizeError),
    /// The street geometry library failed (boxed: its errors are large).
    #[error(transparent)]
    Streets(Box<::streets::StreetsError>),
    /// An OSM map could not be loaded (boxed: its errors are large).
    #[error(transparent)]
    Osm(Box<geodata::osm::OsmError>),
}

impl From<::streets::StreetsError> for FleetError {
    fn from(e: ::streets::StreetsError) -> Self {
        FleetError::Streets(Box::new(e))
    }
}

impl From<geodata::osm::OsmError> for FleetError {
    fn from(e: geodata::osm::OsmError) -> Self {
        FleetError::Osm(Box::new(e))
    }
}

/// Result of the fleet crate.
pub type Result<T> = std::result::Result<T, FleetError>;

pub(crate) fn io_err(path: &std::path::Path, e: impl std::fmt::Display) -> FleetError {
    FleetError::Io {
        path: path.to_path_buf(),
        message: e.to_string(),
    }
}

pub(crate) fn invalid(path: &std::path::Path, message: String) -> FleetError {
    FleetError::Invalid {
        path: path.to_path_buf(),
        message,
    }
}
