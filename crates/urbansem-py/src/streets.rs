//! `streets_estimate`: street offset and width per OSM segment from a point cloud and a
//! trained model, as the GeoJSON `urbansem streets estimate` writes; `streets_transfer`: the
//! bin classifier trained on some labelled sequences and scored on another, as
//! `urbansem streets transfer --json` reports it.

use crate::cloud::cloud_from_arrays;
use crate::error::{chain, raise, StreetsError};
use crate::osm::PyOsmMap;
use geodata::cloud::{read_cloud, PointCloud};
use geodata::georef::CloudFrame;
use geodata::osm::OsmMap;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::Arc;
use streets::model::{StreetModel, Target};

/// Adds the streets functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(streets_estimate, m)?)?;
    m.add_function(wrap_pyfunction!(streets_transfer, m)?)?;
    Ok(())
}

/// An optional column of the cloud dict.
fn column<'py, T: numpy::Element>(
    d: &Bound<'py, PyDict>,
    key: &str,
) -> PyResult<Option<PyReadonlyArray1<'py, T>>> {
    d.get_item(key)?.map(|v| v.extract()).transpose()
}

/// The cloud of a dict as `urbansem.read_cloud` returns it.
fn cloud_of_dict(d: &Bound<'_, PyDict>) -> PyResult<PointCloud> {
    let xyz: PyReadonlyArray2<'_, f64> = d
        .get_item("xyz")?
        .ok_or_else(|| PyValueError::new_err("the cloud dict has no \"xyz\" array"))?
        .extract()?;
    let rgb: Option<PyReadonlyArray2<'_, u8>> =
        d.get_item("rgb")?.map(|v| v.extract()).transpose()?;
    cloud_from_arrays(
        &xyz,
        column::<f32>(d, "intensity")?.as_ref(),
        rgb.as_ref(),
        column::<u8>(d, "label")?.as_ref(),
        column::<u32>(d, "raw_label")?.as_ref(),
        column::<u32>(d, "object")?.as_ref(),
        true,
    )
}

/// A model given as a path or as JSON bytes (`what` names it in errors); neither: `None`.
fn model_of(
    path: Option<PathBuf>,
    json: Option<Vec<u8>>,
    what: &str,
) -> PyResult<Option<StreetModel>> {
    match (path, json) {
        (Some(p), None) => {
            let bytes = std::fs::read(&p).map_err(|e| {
                StreetsError::new_err(format!("reading the model {}: {e}", p.display()))
            })?;
            StreetModel::from_json(&bytes, &p).map(Some)
        }
        (None, Some(b)) => StreetModel::from_json(&b, std::path::Path::new(what)).map(Some),
        (None, None) => Ok(None),
        (Some(_), Some(_)) => {
            return Err(PyValueError::new_err(format!(
                "give the {what} as a path or as JSON, not both"
            )))
        }
    }
    .map_err(raise!(StreetsError))
}

/// Estimates offset and width per drivable OSM segment from a cloud (a path, or a dict of
/// arrays as `read_cloud` returns) and a model (`urbansem streets train`'s JSON, as a path or
/// as bytes; neither: the shipped model of `target`, "driving_area" by default): the RFC 7946
/// FeatureCollection `urbansem streets estimate` writes, as a dict. A with-sidewalk model
/// with sidewalk margins centres its priors on the driving area estimated first with the
/// driving model (path or bytes; neither: the shipped one), as `--driving-model` does.
#[pyfunction]
#[pyo3(name = "streets_estimate", signature = (map, cloud, *, model_path = None,
    model_json = None, cloud_frame = "local", target = None, driving_model_path = None,
    driving_model_json = None))]
#[allow(clippy::too_many_arguments)]
fn streets_estimate<'py>(
    py: Python<'py>,
    map: &Bound<'py, PyAny>,
    cloud: &Bound<'py, PyAny>,
    model_path: Option<PathBuf>,
    model_json: Option<Vec<u8>>,
    cloud_frame: &str,
    target: Option<&str>,
    driving_model_path: Option<PathBuf>,
    driving_model_json: Option<Vec<u8>>,
) -> PyResult<Bound<'py, PyAny>> {
    let frame: CloudFrame = cloud_frame
        .parse()
        .map_err(|e| PyValueError::new_err(chain(&e)))?;
    let target = match target {
        None => None,
        Some("driving_area") => Some(Target::DrivingArea),
        Some("with_sidewalk") => Some(Target::WithSidewalk),
        Some(t) => {
            return Err(PyValueError::new_err(format!(
                "target {t:?}: expected \"driving_area\" or \"with_sidewalk\""
            )))
        }
    };
    let model = match model_of(model_path, model_json, "<model>")? {
        Some(m) => {
            if let Some(t) = target.filter(|&t| t != m.target) {
                return Err(PyValueError::new_err(format!(
                    "target {:?} but the model is a {:?} model",
                    t.key(),
                    m.target.key()
                )));
            }
            m
        }
        None => StreetModel::shipped(target.unwrap_or(Target::DrivingArea))
            .map_err(raise!(StreetsError))?,
    };
    let driving = model_of(driving_model_path, driving_model_json, "<driving model>")?;
    let driving = match driving {
        Some(d) => {
            if let Some(message) = model.driving_model_mismatch(d.target) {
                return Err(PyValueError::new_err(message));
            }
            Some(d)
        }
        None if model.wants_driving_area() => {
            Some(StreetModel::shipped_default().map_err(raise!(StreetsError))?)
        }
        None => None,
    };
    let (osm, map_name): (Arc<OsmMap>, String) = match map.cast::<PyOsmMap>() {
        Ok(m) => {
            let m = m.get();
            (m.map.clone(), m.path.display().to_string())
        }
        Err(_) => {
            let path: PathBuf = map.extract().map_err(|_| {
                PyValueError::new_err("map must be an urbansem.OsmMap or an .osm/.osm.pbf path")
            })?;
            let loaded = py.detach(|| OsmMap::load(&path)).map_err(|e| {
                crate::error::OsmError::new_err(format!(
                    "loading {}: {}",
                    path.display(),
                    chain(&e)
                ))
            })?;
            (Arc::new(loaded), path.display().to_string())
        }
    };
    let (mut pc, cloud_name) = match cloud.cast::<PyDict>() {
        Ok(d) => (cloud_of_dict(d)?, "<arrays>".to_string()),
        Err(_) => {
            let path: PathBuf = cloud.extract().map_err(|_| {
                PyValueError::new_err(
                    "cloud must be a point cloud path or a dict of arrays as urbansem.read_cloud returns",
                )
            })?;
            let pc = py.detach(|| read_cloud(&path)).map_err(|e| {
                crate::error::CloudError::new_err(format!(
                    "reading {}: {}",
                    path.display(),
                    chain(&e)
                ))
            })?;
            (pc, path.display().to_string())
        }
    };
    let fc = py.detach(|| {
        frame
            .into_map_frame(&mut pc, &osm.frame)
            .map_err(|e| format!("moving {cloud_name} into the map's frame: {}", chain(&e)))?;
        let est = model
            .estimate_with_driving(driving.as_ref(), &osm, &pc, (&map_name, &cloud_name), 0)
            .map_err(|e| chain(&e))?;
        let fc = streets::geojson::feature_collection(&osm, &est.segments, model.target);
        streets::geojson::validate(&fc).map_err(|e| format!("internal: {e}"))?;
        Ok::<_, String>(fc)
    });
    let fc = fc.map_err(StreetsError::new_err)?;
    Ok(pythonize::pythonize(py, &fc)?)
}

/// Trains the bin classifier on the labelled scans of the `train` sequences (folders of any
/// labelled layout: simulated car LiDAR, MCD, KITTI-360) and scores it on the `test`
/// sequence: the report `urbansem streets transfer --json` prints, as a dict.
#[pyfunction]
#[pyo3(name = "streets_transfer", signature = (train, test, *, scans_per_source = 40,
    test_scans = 0, raw_features = false, max_train_bins = 3000, svm_c = 4.0, seed = 1))]
#[allow(clippy::too_many_arguments)]
fn streets_transfer<'py>(
    py: Python<'py>,
    train: Vec<PathBuf>,
    test: PathBuf,
    scans_per_source: usize,
    test_scans: usize,
    raw_features: bool,
    max_train_bins: usize,
    svm_c: f64,
    seed: u64,
) -> PyResult<Bound<'py, PyAny>> {
    if train.is_empty() {
        return Err(PyValueError::new_err(
            "train: give at least one sequence folder",
        ));
    }
    let options = streets::transfer::TransferOptions {
        scans_per_source,
        test_scans,
        normalise: !raw_features,
        classifier: streets::model::ClassifierOptions {
            svm: streets::svm::SvmOptions {
                c: svm_c,
                ..Default::default()
            },
            max_train_bins,
            seed,
            ..Default::default()
        },
    };
    let report = py.detach(|| {
        let open = |dir: &PathBuf| {
            geosim::sequence::open_sequence(dir)
                .map(|seq| (dir.display().to_string(), seq))
                .map_err(|e| format!("opening {}: {}", dir.display(), chain(&e)))
        };
        let sources = train.iter().map(open).collect::<Result<Vec<_>, String>>()?;
        let test = open(&test)?;
        streets::transfer::transfer(&sources, &test, &options).map_err(|e| chain(&e))
    });
    let report = report.map_err(StreetsError::new_err)?;
    Ok(pythonize::pythonize(py, &report)?)
}
