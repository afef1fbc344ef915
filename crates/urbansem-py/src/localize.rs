//! `Localizer`: global localization of gravity-levelled scans on OSM building outlines. The
//! map (distance-transform tensor, pyramid, feasible mask) is prepared once, from an `OsmMap`,
//! an `.osm`/`.osm.pbf` file or a `.uloc` index, and reused by every call; each call returns
//! the dicts `urbansem localize --json` / `localize track --json` print. Also the MCD
//! helpers that level a real scan as the evaluation does, and the odometry file reader.

use crate::arrays::{rows, to_rows};
use crate::error::raise;
use crate::osm::PyOsmMap;
use geodata::osm::OsmMap;
use localize::eval::{mcd_frames, mcd_scan};
use localize::index::{is_index, load_map_or_index};
use localize::jobs::track_rows;
use localize::pipeline::{LocalizeOptions, Localizer};
use localize::rank::CostKind;
use localize::report::LocalizeReport;
use localize::sensor::{ExtractOverrides, SensorChoice, SensorKind};
use localize::track::read_odometry;
use localize::{Pose2, WithContext};
use numpy::PyReadonlyArray2;
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::PyDict;
use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

/// Adds `_Localizer`, the MCD helpers and the odometry reader to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyLocalizer>()?;
    m.add_function(wrap_pyfunction!(localize_mcd_frames, m)?)?;
    m.add_function(wrap_pyfunction!(localize_mcd_scan, m)?)?;
    m.add_function(wrap_pyfunction!(localize_read_odometry, m)?)?;
    Ok(())
}

/// An odometry file read as `localize track --odometry` reads it (planar, TUM or KITTI lines)
/// for the scans `names`, in order: an (m, 3) array of x, y (metres) and yaw (radians).
#[pyfunction]
fn localize_read_odometry<'py>(
    py: Python<'py>,
    path: PathBuf,
    names: Vec<String>,
) -> PyResult<Bound<'py, numpy::PyArray2<f64>>> {
    let poses = py
        .detach(|| read_odometry(&path, &names))
        .map_err(raise!(LocalizeError))?;
    Ok(to_rows(
        py,
        poses.iter().map(|p| [p.x, p.y, p.yaw_rad]).collect(),
    ))
}

/// A localizer that owns its map.
///
/// `Localizer` borrows the map it was prepared on; here the map lives in an `Arc` that this
/// struct holds for as long as the localizer exists.
struct Owned {
    // Field order matters: fields drop in declaration order, so the localizer (which borrows
    // `*map`) is dropped before the map.
    localizer: Localizer<'static>,
    map: Arc<OsmMap>,
}

impl Owned {
    /// Prepares `map` (or takes the prepared map of an index).
    fn new(
        map: Arc<OsmMap>,
        prepared: Option<localize::index::PreparedMap>,
        options: LocalizeOptions,
        path: &std::path::Path,
    ) -> localize::Result<Owned> {
        // SAFETY: the `OsmMap` is on the heap behind `map`, which never moves it and which
        // this struct keeps alive (and drops after `localizer`, see the field order); the
        // `'static` reference never leaves the struct: methods hand out borrows of `self`.
        let borrowed: &'static OsmMap = unsafe { &*Arc::as_ptr(&map) };
        let localizer = Localizer::prepared_or_new(borrowed, prepared, options, path)?;
        Ok(Owned { localizer, map })
    }

    /// The localizer, borrowed for no longer than `self`.
    fn get(&self) -> &Localizer<'_> {
        &self.localizer
    }
}

/// A map prepared for localization (`urbansem.Localizer` wraps it).
#[pyclass(name = "_Localizer", module = "urbansem", frozen)]
pub struct PyLocalizer {
    owned: Owned,
    /// The map as the reports name it (its file).
    map_name: String,
    /// Seconds spent reading the map (or index).
    load_map_s: f64,
}

/// A report as `urbansem localize --json` prints it: a number without a JSON form (the
/// unknown d_DCM of a state carried by a track, ∞) becomes `None`, as the CLI writes `null`.
fn as_cli_json<'py, T: serde::Serialize>(
    py: Python<'py>,
    value: &T,
) -> PyResult<Bound<'py, PyAny>> {
    let json = serde_json::to_value(value).map_err(|e| PyValueError::new_err(e.to_string()))?;
    Ok(pythonize::pythonize(py, &json)?)
}

fn sensor_choice(sensor: &str) -> PyResult<SensorChoice> {
    if sensor == "auto" {
        return Ok(SensorChoice::Auto);
    }
    SensorKind::from_name(sensor)
        .map(SensorChoice::Named)
        .ok_or_else(|| {
            let names: Vec<&str> = SensorKind::ALL.iter().map(|k| k.name()).collect();
            PyValueError::new_err(format!(
                "unknown sensor {sensor:?}: use auto, {}",
                names.join(", ")
            ))
        })
}

fn cost_kind(cost: &str) -> PyResult<CostKind> {
    CostKind::ALL
        .into_iter()
        .find(|k| k.name() == cost)
        .ok_or_else(|| {
            PyValueError::new_err(format!(
                "unknown cost {cost:?}: use dcm, forward, reverse or symmetric"
            ))
        })
}

/// The extraction overrides, checked as the command line checks them.
#[allow(clippy::too_many_arguments)]
fn overrides(
    clearance_m: Option<f64>,
    voxel_m: Option<f64>,
    max_range_m: Option<f64>,
    min_range_m: Option<f64>,
    min_z_m: Option<f64>,
    max_z_m: Option<f64>,
    ground_cell_m: Option<f64>,
    column_radius_m: Option<f64>,
    max_flatness: Option<f64>,
    min_columns: Option<usize>,
    max_see_through: Option<f64>,
    min_cell_count: Option<u32>,
    min_segment_m: Option<f64>,
) -> PyResult<ExtractOverrides> {
    for (name, v) in [
        ("voxel_m", voxel_m),
        ("max_range_m", max_range_m),
        ("ground_cell_m", ground_cell_m),
        ("column_radius_m", column_radius_m),
        ("max_flatness", max_flatness),
        ("max_see_through", max_see_through),
        ("min_segment_m", min_segment_m),
    ] {
        if let Some(v) = v.filter(|v| !(v.is_finite() && *v > 0.0)) {
            return Err(PyValueError::new_err(format!(
                "{name} = {v}: expected a positive number"
            )));
        }
    }
    for (name, v) in [
        ("clearance_m", clearance_m),
        ("min_range_m", min_range_m),
        ("min_z_m", min_z_m),
        ("max_z_m", max_z_m),
    ] {
        if let Some(v) = v.filter(|v| !v.is_finite()) {
            return Err(PyValueError::new_err(format!(
                "{name} = {v}: expected a finite number"
            )));
        }
    }
    Ok(ExtractOverrides {
        voxel_m,
        max_range_m,
        min_range_m,
        min_z_m,
        max_z_m,
        clearance_m,
        ground_cell_m,
        column_radius_m,
        max_flatness,
        min_columns,
        max_see_through,
        min_cell_count,
        min_segment_m,
    })
}

/// A scan's points, checked: `(n, 3)` with n ≥ 1.
fn scan_points<'a>(
    points: &'a PyReadonlyArray2<'_, f64>,
    what: &str,
) -> PyResult<std::borrow::Cow<'a, [[f64; 3]]>> {
    let pts = rows::<f64, 3>(points, what)?;
    if pts.is_empty() {
        return Err(PyValueError::new_err(format!(
            "{what} is empty: expected an (n, 3) array of a gravity-levelled scan's points"
        )));
    }
    Ok(pts)
}

#[pymethods]
impl PyLocalizer {
    /// Prepares a map for localization: an `OsmMap`, an `.osm`/`.osm.pbf` path or a `.uloc`
    /// index path, with the command line's options.
    #[new]
    #[pyo3(signature = (map, *, sensor = "auto", cost = "symmetric", grid_m = 0.5,
        yaw_step_deg = 0.5, clearance_m = None, voxel_m = None, max_range_m = None,
        min_range_m = None, min_z_m = None, max_z_m = None, ground_cell_m = None,
        column_radius_m = None, max_flatness = None, min_columns = None,
        max_see_through = None, min_cell_count = None, min_segment_m = None, level = "off",
        vehicle = "auto", max_raw_poses = localize::candidates::MAX_RAW_POSES))]
    #[allow(clippy::too_many_arguments)]
    fn new(
        py: Python<'_>,
        map: &Bound<'_, PyAny>,
        sensor: &str,
        cost: &str,
        grid_m: f64,
        yaw_step_deg: f64,
        clearance_m: Option<f64>,
        voxel_m: Option<f64>,
        max_range_m: Option<f64>,
        min_range_m: Option<f64>,
        min_z_m: Option<f64>,
        max_z_m: Option<f64>,
        ground_cell_m: Option<f64>,
        column_radius_m: Option<f64>,
        max_flatness: Option<f64>,
        min_columns: Option<usize>,
        max_see_through: Option<f64>,
        min_cell_count: Option<u32>,
        min_segment_m: Option<f64>,
        level: &str,
        vehicle: &str,
        max_raw_poses: usize,
    ) -> PyResult<Self> {
        let vehicle = localize::sensor::Vehicle::from_name(vehicle).ok_or_else(|| {
            PyValueError::new_err(format!("vehicle = {vehicle:?}: use auto, car or free"))
        })?;
        let level = localize::level::options_named(level)
            .map_err(|_| PyValueError::new_err(format!("level = {level:?}: use auto or off")))?;
        if !(yaw_step_deg > 0.0 && yaw_step_deg <= 90.0) {
            return Err(PyValueError::new_err(format!(
                "yaw_step_deg = {yaw_step_deg}: expected a step in (0, 90] degrees"
            )));
        }
        if !(grid_m.is_finite() && grid_m > 0.0) {
            return Err(PyValueError::new_err(format!(
                "grid_m = {grid_m}: expected a positive number"
            )));
        }
        let mut options = LocalizeOptions {
            rank_by: cost_kind(cost)?,
            sensor: sensor_choice(sensor)?,
            overrides: overrides(
                clearance_m,
                voxel_m,
                max_range_m,
                min_range_m,
                min_z_m,
                max_z_m,
                ground_cell_m,
                column_radius_m,
                max_flatness,
                min_columns,
                max_see_through,
                min_cell_count,
                min_segment_m,
            )?,
            level,
            vehicle,
            ..LocalizeOptions::default()
        };
        options.chamfer.grid_m = grid_m;
        options.search.yaw_step_deg = yaw_step_deg;
        options.search.max_raw_poses = max_raw_poses;
        if let Ok(osm) = map.cast::<PyOsmMap>() {
            let osm = osm.get();
            let (shared, path) = (osm.map.clone(), osm.path.clone());
            let owned = py
                .detach(|| Owned::new(shared, None, options, &path))
                .map_err(raise!(LocalizeError))?;
            return Ok(PyLocalizer {
                owned,
                map_name: path.display().to_string(),
                load_map_s: 0.0,
            });
        }
        let path: PathBuf = map.extract().map_err(|_| {
            PyValueError::new_err(
                "map must be an urbansem.OsmMap, or the path of an .osm/.osm.pbf map or a .uloc index",
            )
        })?;
        let (owned, load_map_s) = py
            .detach(|| {
                let t = Instant::now();
                let (map, prepared) = load_map_or_index(&path)?;
                let load_s = t.elapsed().as_secs_f64();
                Owned::new(Arc::new(map), prepared, options, &path).map(|o| (o, load_s))
            })
            .map_err(raise!(LocalizeError))?;
        Ok(PyLocalizer {
            owned,
            map_name: path.display().to_string(),
            load_map_s,
        })
    }

    /// Localizes one gravity-levelled scan (`(n, 3)` float64, sensor frame): the dict
    /// `urbansem localize --json` prints, `top` candidates listed.
    #[pyo3(signature = (points, *, top = 10, name = "<array>"))]
    fn localize<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
        top: usize,
        name: &str,
    ) -> PyResult<Bound<'py, PyAny>> {
        let pts = scan_points(&points, "points")?;
        let localizer = self.owned.get();
        let report = py
            .detach(|| {
                let result = localizer
                    .localize_points(&pts)
                    .context_with(|| format!("localizing {name}"))?;
                Ok::<_, localize::LocalizeError>(LocalizeReport::new(
                    localizer,
                    &self.map_name,
                    name,
                    &result,
                    top,
                    self.load_map_s,
                    0.0,
                ))
            })
            .map_err(raise!(LocalizeError))?;
        as_cli_json(py, &report)
    }

    /// Localizes a track: scans (each `(n, 3)` float64) tied by odometry (`(m, 3)` poses
    /// `x, y, yaw` in any odometry frame, one per scan); one dict per scan as the rows of
    /// `urbansem localize track --json`.
    #[pyo3(signature = (scans, odometry, *, window = 5, top = 5, names = None, history_m = localize::track::TRACK_HISTORY_M, causal = false, pose_graph = true))]
    #[allow(clippy::too_many_arguments)]
    fn track<'py>(
        &self,
        py: Python<'py>,
        scans: Vec<PyReadonlyArray2<'py, f64>>,
        odometry: PyReadonlyArray2<'py, f64>,
        window: usize,
        top: usize,
        names: Option<Vec<String>>,
        history_m: f64,
        causal: bool,
        pose_graph: bool,
    ) -> PyResult<Bound<'py, PyAny>> {
        if window == 0 {
            return Err(PyValueError::new_err(
                "window = 0: expected at least 1 scan per window",
            ));
        }
        if history_m.is_nan() || history_m < 0.0 {
            return Err(PyValueError::new_err(format!(
                "history_m = {history_m}: expected 0 or more metres"
            )));
        }
        if scans.is_empty() {
            return Err(PyValueError::new_err(
                "scans is empty: expected at least one scan",
            ));
        }
        let odo = rows::<f64, 3>(&odometry, "odometry")?;
        if odo.len() != scans.len() {
            return Err(PyValueError::new_err(format!(
                "odometry has {} poses for {} scans: expected one pose (x, y, yaw) per scan",
                odo.len(),
                scans.len()
            )));
        }
        if let Some(i) = odo.iter().position(|p| p.iter().any(|v| !v.is_finite())) {
            return Err(PyValueError::new_err(format!(
                "odometry pose {i} is not finite ({:?})",
                odo[i]
            )));
        }
        let odo: Vec<Pose2> = odo
            .iter()
            .map(|&[x, y, yaw_rad]| Pose2 { x, y, yaw_rad })
            .collect();
        let names = match names {
            Some(n) if n.len() != scans.len() => {
                return Err(PyValueError::new_err(format!(
                    "{} names for {} scans",
                    n.len(),
                    scans.len()
                )))
            }
            Some(n) => n,
            None => (0..scans.len()).map(|i| i.to_string()).collect(),
        };
        let points = scans
            .iter()
            .enumerate()
            .map(|(i, s)| scan_points(s, &format!("scans[{i}]")))
            .collect::<PyResult<Vec<_>>>()?;
        let localizer = self.owned.get();
        let rows = py
            .detach(|| {
                let extracted = points
                    .iter()
                    .zip(&names)
                    .map(|(p, name)| {
                        localizer
                            .scan_segments(p)
                            .context_with(|| format!("extracting walls from {name}"))
                    })
                    .collect::<localize::Result<Vec<_>>>()?;
                let track = localize::track::TrackOptions {
                    window,
                    history_m,
                    smooth: !causal,
                    refine_poses: pose_graph,
                    ..Default::default()
                };
                track_rows(localizer, &names, &extracted, &odo, &track, top)
            })
            .map_err(raise!(LocalizeError))?;
        as_cli_json(py, &rows)
    }

    /// The wall segments of a scan (`(n, 3)` float64) in the sensor frame as an `(k, 4)`
    /// array `[ax, ay, bx, by]`, with the sensor the scan was processed as (a dict).
    fn scan_segments<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let pts = scan_points(&points, "points")?;
        let localizer = self.owned.get();
        let extracted = py
            .detach(|| localizer.scan_segments(&pts))
            .map_err(raise!(LocalizeError))?;
        let segs: Vec<[f64; 4]> = extracted
            .segments
            .iter()
            .map(|s| [s.a[0], s.a[1], s.b[0], s.b[1]])
            .collect();
        Ok((
            to_rows(py, segs).into_any(),
            pythonize::pythonize(py, &extracted.sensor)?,
        ))
    }

    /// The map the localizer was prepared on.
    #[getter]
    fn map(&self) -> PyOsmMap {
        PyOsmMap {
            map: self.owned.map.clone(),
            path: PathBuf::from(&self.map_name),
        }
    }

    /// The map (or index) file, as the reports name it.
    #[getter]
    fn map_path(&self) -> String {
        self.map_name.clone()
    }

    /// Whether the map was read from a `.uloc` index.
    #[getter]
    fn uses_index(&self) -> bool {
        is_index(std::path::Path::new(&self.map_name))
    }

    /// The cost that ranks the candidates.
    #[getter]
    fn cost(&self) -> &'static str {
        self.owned.get().options.rank_by.name()
    }

    /// Building outline edges of the map as an `(m, 4)` array `[ax, ay, bx, by]` (metres).
    #[getter]
    fn edges<'py>(&self, py: Python<'py>) -> Bound<'py, numpy::PyArray2<f64>> {
        let segs = self
            .owned
            .get()
            .edges
            .iter()
            .map(|s| [s.a[0], s.a[1], s.b[0], s.b[1]])
            .collect();
        to_rows(py, segs)
    }

    /// Seconds of the map's preparation (edges, distance transform, pyramid, feasible mask)
    /// and of reading it.
    #[getter]
    fn seconds<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let s = self.owned.get().seconds;
        let d = PyDict::new(py);
        d.set_item("load_map", self.load_map_s)?;
        d.set_item("map_edges", s.edges)?;
        d.set_item("distance_transform", s.distance_transform)?;
        d.set_item("pyramid", s.pyramid)?;
        d.set_item("feasible_mask", s.feasible)?;
        Ok(d)
    }

    fn __repr__(&self) -> String {
        let l = self.owned.get();
        format!(
            "Localizer({:?}: {} edges, tensor {}×{}×{} at {} m, ranked by {})",
            self.map_name,
            l.edges.len(),
            l.dt.width,
            l.dt.height,
            l.dt.channels,
            l.dt.grid_m,
            l.options.rank_by.name()
        )
    }
}

/// The frame numbers of an MCD sequence folder that have a scan, sorted.
#[pyfunction]
fn localize_mcd_frames(py: Python<'_>, folder: PathBuf) -> PyResult<Vec<u64>> {
    py.detach(|| mcd_frames(&folder))
        .map_err(raise!(LocalizeError))
}

/// One MCD scan levelled into the sensor frame as the evaluation does: a dict with `name`,
/// `frame`, `points` (n, 3), `truth` (x, y, yaw in the map's local frame) and `levelling`
/// (the 3 × 3 rotation from the raw sensor frame into the levelled one).
#[pyfunction]
fn localize_mcd_scan<'py>(
    py: Python<'py>,
    folder: PathBuf,
    map: PyRef<'py, PyOsmMap>,
    frame: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let osm = map.map.clone();
    let levelled = py
        .detach(|| mcd_scan(&folder, &osm, frame))
        .map_err(raise!(LocalizeError))?;
    let d = PyDict::new(py);
    let scan = levelled.scan;
    d.set_item("name", scan.name)?;
    d.set_item("frame", levelled.frame)?;
    d.set_item("points", to_rows(py, scan.points))?;
    d.set_item("truth", (scan.truth.x, scan.truth.y, scan.truth.yaw_rad))?;
    d.set_item("levelling", to_rows(py, levelled.levelling.to_vec()))?;
    Ok(d)
}
