//! `read_cloud` / `write_cloud`: every point cloud format urbansem reads (PLY, PCD, LAS/LAZ,
//! KITTI `.bin`, ROS 2 bags) as a dict of NumPy arrays.

use crate::arrays::{rows, to_array, to_rows, values};
use crate::error::{raise, CloudError};
use geodata::cloud::kitti::read_label_file;
use geodata::cloud::mcap::{bag_info, read_bag_cloud_at, read_bag_poses, Pick};
use geodata::cloud::{
    read_cloud_with, write_cloud_with, Encoding, Format, PointCloud, Precision, ReadOptions,
    WriteOptions,
};
use geodata::datasets::LabelSet;
use numpy::{PyReadonlyArray1, PyReadonlyArray2};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;

/// Adds the cloud functions to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_function(wrap_pyfunction!(read_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(write_cloud, m)?)?;
    m.add_function(wrap_pyfunction!(bag_topics, m)?)?;
    m.add_function(wrap_pyfunction!(bag_poses, m)?)?;
    Ok(())
}

/// A cloud as a dict of arrays: `xyz` (n, 3) float64 and the columns the cloud has.
pub fn cloud_to_dict<'py>(py: Python<'py>, cloud: PointCloud) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("xyz", to_rows(py, cloud.positions))?;
    if let Some(v) = cloud.intensity {
        d.set_item("intensity", to_array(py, v))?;
    }
    if let Some(v) = cloud.rgb {
        d.set_item("rgb", to_rows(py, v))?;
    }
    if let Some(v) = cloud.label {
        d.set_item("label", to_array(py, v))?;
    }
    if let Some(v) = cloud.raw_label {
        d.set_item("raw_label", to_array(py, v))?;
    }
    if let Some(v) = cloud.object {
        d.set_item("object", to_array(py, v))?;
    }
    Ok(d)
}

/// Reads a point cloud file (format from the extension) into a dict of arrays; `labels` is a
/// per-point uint32 label file, its ids mapped to urbansem classes by `label_set`.
#[pyfunction]
#[pyo3(signature = (path, *, drop_non_finite = false, topic = None, index = None, time = None,
    labels = None, label_set = None))]
#[allow(clippy::too_many_arguments)]
fn read_cloud(
    py: Python<'_>,
    path: PathBuf,
    drop_non_finite: bool,
    topic: Option<String>,
    index: Option<usize>,
    time: Option<f64>,
    labels: Option<PathBuf>,
    label_set: Option<String>,
) -> PyResult<Bound<'_, PyDict>> {
    let label_set = label_set
        .map(|name| {
            LabelSet::from_name(&name).ok_or_else(|| {
                PyValueError::new_err(format!("unknown label_set {name:?}; use mcd or kitti360"))
            })
        })
        .transpose()?;
    if label_set.is_some() && labels.is_none() {
        return Err(PyValueError::new_err(
            "label_set names the ids of a label file: give labels too",
        ));
    }
    let options = ReadOptions { drop_non_finite };
    let is_bag = Format::from_path(&path).ok() == Some(Format::Mcap);
    if !is_bag && (topic.is_some() || index.is_some() || time.is_some()) {
        return Err(PyValueError::new_err(format!(
            "topic, index and time select a message of a ROS 2 bag (.mcap); {} is not one",
            path.display()
        )));
    }
    let pick = match (index, time) {
        (Some(_), Some(_)) => {
            return Err(PyValueError::new_err(
                "give index or time, not both: each picks one message",
            ))
        }
        (_, Some(t)) if !(t.is_finite() && t >= 0.0) => {
            return Err(PyValueError::new_err(format!(
                "time {t} is not a time in seconds since the epoch"
            )))
        }
        (_, Some(t)) => Pick::Time((t * 1e9).round() as u64),
        (index, None) => Pick::Index(index.unwrap_or(0)),
    };
    let (mut cloud, report) = py
        .detach(|| {
            if is_bag {
                read_bag_cloud_at(&path, topic.as_deref(), pick, &options)
            } else {
                read_cloud_with(&path, &options)
            }
        })
        .map_err(raise!(CloudError))?;
    if let Some(label_path) = labels {
        if report.dropped_non_finite > 0 {
            return Err(CloudError::new_err(format!(
                "cannot attach {} to {}: {} points were dropped, so labels no longer line up",
                label_path.display(),
                path.display(),
                report.dropped_non_finite
            )));
        }
        let raw = py
            .detach(|| read_label_file(&label_path, Some(cloud.len())))
            .map_err(raise!(CloudError))?;
        match label_set {
            Some(set) => set.attach(&mut cloud, raw),
            None => cloud.raw_label = Some(raw),
        }
    }
    cloud_to_dict(py, cloud)
}

/// Lists a ROS 2 bag's topics, message counts and point fields (as `urbansem cloud info`).
#[pyfunction]
fn bag_topics(py: Python<'_>, path: PathBuf) -> PyResult<Bound<'_, PyAny>> {
    let info = py.detach(|| bag_info(&path)).map_err(raise!(CloudError))?;
    Ok(pythonize::pythonize(py, &info)?)
}

/// Every pose on a bag's Odometry, PoseStamped or TF topic as a dict of arrays: `stamp_ns`
/// (n,) int64, `log_time_ns` (n,) uint64, `translation` (n, 3), `rotation` (n, 4) `[x, y, z,
/// w]`, `yaw` (n,), `frame_id` and `child_frame_id` lists.
#[pyfunction]
#[pyo3(signature = (path, topic, *, child_frame = None))]
fn bag_poses<'py>(
    py: Python<'py>,
    path: PathBuf,
    topic: String,
    child_frame: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let poses = py
        .detach(|| read_bag_poses(&path, &topic, child_frame.as_deref()))
        .map_err(raise!(CloudError))?;
    let d = PyDict::new(py);
    d.set_item(
        "stamp_ns",
        to_array(py, poses.iter().map(|p| p.stamp_ns).collect()),
    )?;
    d.set_item(
        "log_time_ns",
        to_array(py, poses.iter().map(|p| p.log_time_ns).collect()),
    )?;
    d.set_item(
        "translation",
        to_rows(py, poses.iter().map(|p| p.translation).collect()),
    )?;
    d.set_item(
        "rotation",
        to_rows(py, poses.iter().map(|p| p.rotation).collect()),
    )?;
    d.set_item("yaw", to_array(py, poses.iter().map(|p| p.yaw()).collect()))?;
    d.set_item(
        "frame_id",
        poses.iter().map(|p| p.frame_id.clone()).collect::<Vec<_>>(),
    )?;
    d.set_item(
        "child_frame_id",
        poses
            .into_iter()
            .map(|p| p.child_frame_id)
            .collect::<Vec<_>>(),
    )?;
    Ok(d)
}

/// A cloud from arrays: `xyz` (n, 3) float64 plus optional columns of n values each.
#[allow(clippy::too_many_arguments)]
pub fn cloud_from_arrays(
    xyz: &PyReadonlyArray2<'_, f64>,
    intensity: Option<&PyReadonlyArray1<'_, f32>>,
    rgb: Option<&PyReadonlyArray2<'_, u8>>,
    label: Option<&PyReadonlyArray1<'_, u8>>,
    raw_label: Option<&PyReadonlyArray1<'_, u32>>,
    object: Option<&PyReadonlyArray1<'_, u32>>,
    double: bool,
) -> PyResult<PointCloud> {
    let cloud = PointCloud {
        positions: rows::<f64, 3>(xyz, "xyz")?.into_owned(),
        precision: if double {
            Precision::F64
        } else {
            Precision::F32
        },
        intensity: intensity.map(|a| values(a).into_owned()),
        rgb: rgb
            .map(|a| rows::<u8, 3>(a, "rgb").map(|r| r.into_owned()))
            .transpose()?,
        label: label.map(|a| values(a).into_owned()),
        raw_label: raw_label.map(|a| values(a).into_owned()),
        object: object.map(|a| values(a).into_owned()),
    };
    cloud
        .check_columns()
        .map_err(|e| PyValueError::new_err(crate::error::chain(&e)))?;
    Ok(cloud)
}

/// Writes arrays as a point cloud file (format from the extension).
#[pyfunction]
#[pyo3(signature = (path, xyz, *, intensity = None, rgb = None, label = None, raw_label = None,
    object = None, encoding = "binary", double = false))]
#[allow(clippy::too_many_arguments)]
fn write_cloud(
    py: Python<'_>,
    path: PathBuf,
    xyz: PyReadonlyArray2<'_, f64>,
    intensity: Option<PyReadonlyArray1<'_, f32>>,
    rgb: Option<PyReadonlyArray2<'_, u8>>,
    label: Option<PyReadonlyArray1<'_, u8>>,
    raw_label: Option<PyReadonlyArray1<'_, u32>>,
    object: Option<PyReadonlyArray1<'_, u32>>,
    encoding: &str,
    double: bool,
) -> PyResult<()> {
    let encoding = match encoding {
        "ascii" => Encoding::Ascii,
        "binary" | "binary_little_endian" => Encoding::BinaryLittleEndian,
        "binary_big_endian" => Encoding::BinaryBigEndian,
        "binary_compressed" => Encoding::BinaryCompressed,
        other => {
            return Err(PyValueError::new_err(format!(
            "unknown encoding {other:?}: use ascii, binary, binary_big_endian or binary_compressed"
        )))
        }
    };
    let cloud = cloud_from_arrays(
        &xyz,
        intensity.as_ref(),
        rgb.as_ref(),
        label.as_ref(),
        raw_label.as_ref(),
        object.as_ref(),
        double,
    )?;
    py.detach(|| write_cloud_with(&path, &cloud, &WriteOptions { encoding }))
        .map_err(raise!(CloudError))
}
