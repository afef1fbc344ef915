//! `shard_plan`, `shard_run`, `shard_merge`: the fleet crate's engine-neutral shards, for
//! `urbansem.distributed` (Ray) and any other engine driving them from Python.

use crate::error::raise;
use fleet::plan::{plan_localize, JobOptions};
use localize::tiles::LoadedTile;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use std::collections::HashMap;
use std::path::{Path, PathBuf};

/// Tiles handed to a shard: manifest position → (index bytes, crop bytes).
type TileBytes = HashMap<usize, (Vec<u8>, Vec<u8>)>;

/// Adds the shard functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(shard_plan, m)?)?;
    m.add_function(wrap_pyfunction!(shard_run, m)?)?;
    m.add_function(wrap_pyfunction!(shard_merge, m)?)?;
    Ok(())
}

/// Plans a localization job over a tiled map and writes the plan (`urbansem shard plan`).
#[pyfunction]
#[pyo3(signature = (map, inputs, out, *, results = None, batch = 8, top = 5, cost = "symmetric", level = "off", vehicle = "auto"))]
#[allow(clippy::too_many_arguments)]
fn shard_plan<'py>(
    py: Python<'py>,
    map: PathBuf,
    inputs: PathBuf,
    out: PathBuf,
    results: Option<PathBuf>,
    batch: usize,
    top: usize,
    cost: &str,
    level: &str,
    vehicle: &str,
) -> PyResult<Bound<'py, PyAny>> {
    if batch == 0 {
        return Err(PyValueError::new_err(
            "batch 0: expected at least 1 scan per shard",
        ));
    }
    localize::level::options_named(level)
        .map_err(|e| PyValueError::new_err(format!("level {level:?}: {e}")))?;
    if localize::sensor::Vehicle::from_name(vehicle).is_none() {
        return Err(PyValueError::new_err(format!(
            "vehicle {vehicle:?}: use auto, car or free"
        )));
    }
    let results = results.unwrap_or_else(|| out.with_extension("d"));
    let options = JobOptions {
        top,
        cost: cost.to_owned(),
        level: level.to_owned(),
        vehicle: vehicle.to_owned(),
        ..JobOptions::default()
    };
    let plan = py
        .detach(|| {
            let plan = plan_localize(&map, &inputs, &results, batch, options)?;
            plan.write(&out)?;
            Ok::<_, fleet::FleetError>(plan)
        })
        .map_err(raise!(FleetError))?;
    Ok(pythonize::pythonize(py, &plan)?)
}

/// Runs one shard of a plan (a no-op when complete) with `threads` worker threads (default:
/// every core); `tiles` maps a manifest tile position to its index and crop bytes (e.g. from
/// a distributed object store) instead of reading them from the manifest's folder.
#[pyfunction]
#[pyo3(signature = (plan, shard, *, tiles = None, threads = None))]
fn shard_run<'py>(
    py: Python<'py>,
    plan: PathBuf,
    shard: usize,
    tiles: Option<TileBytes>,
    threads: Option<usize>,
) -> PyResult<Bound<'py, PyAny>> {
    let outcome = py
        .detach(|| {
            let source = |k: usize| -> fleet::Result<LoadedTile> {
                let Some((index, crop)) = tiles.as_ref().and_then(|t| t.get(&k)) else {
                    return Err(fleet::FleetError::Invalid {
                        path: plan.clone(),
                        message: format!("tile {k} was not given to the shard"),
                    });
                };
                let name = Path::new("tile").join(k.to_string());
                Ok(LoadedTile::from_bytes(index, crop, &name)?)
            };
            let run = || {
                let from: fleet::run::TileSource<'_> = match tiles {
                    Some(_) => Some(&source),
                    None => None,
                };
                fleet::run::run_shard(&plan, shard, from)
            };
            match threads {
                None => run(),
                Some(n) => match rayon::ThreadPoolBuilder::new()
                    .num_threads(n.max(1))
                    .build()
                {
                    Ok(pool) => pool.install(run),
                    Err(_) => run(),
                },
            }
        })
        .map_err(raise!(FleetError))?;
    Ok(pythonize::pythonize(py, &outcome)?)
}

/// Merges every shard's result of a plan (`urbansem shard merge`): for localization
/// `{"scans": [...], ...}`, for streets the GeoJSON FeatureCollection.
#[pyfunction]
#[pyo3(signature = (plan,))]
fn shard_merge<'py>(py: Python<'py>, plan: PathBuf) -> PyResult<Bound<'py, PyAny>> {
    let merged = py
        .detach(|| fleet::merge::merge_job(&plan))
        .map_err(raise!(FleetError))?;
    Ok(match merged {
        fleet::merge::Merged::Localize(m) => pythonize::pythonize(py, &m)?,
        fleet::merge::Merged::Streets(m) => pythonize::pythonize(py, &m.geojson)?,
        fleet::merge::Merged::Map(m) => pythonize::pythonize(py, &m.geojson)?,
    })
}
