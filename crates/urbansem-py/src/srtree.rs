//! `SemanticMap`: the semantic R-tree map of `srtree` (occupancy cells with class
//! histograms, an R-tree over them, the objects of the cells and the spatial relation graph
//! between them) built from NumPy arrays or cloud files, queried into NumPy arrays, saved and
//! loaded as `.srt` files.
//!
//! Every query returns the same dict of cell columns ([`CellColumns`]). The map sits behind
//! a read–write lock that is only taken with the GIL released, so queries from several
//! Python threads run in parallel and an insertion waits for them.

use crate::arrays::{rows, to_array, to_rows, values};
use crate::cloud::cloud_from_arrays;
use crate::error::{chain, raise, MapError};
use crate::osm::PyOsmMap;
use geodata::classes::Class;
use geodata::cloud::kitti::read_label_file;
use geodata::cloud::{read_cloud_with, PointCloud, ReadOptions};
use geodata::datasets::LabelSet;
use geodata::georef::CloudFrame;
use numpy::{PyReadonlyArray1, PyReadonlyArray2, PyUntypedArrayMethods};
use pyo3::exceptions::PyValueError;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};
use srtree::amodal::MapOutlines;
use srtree::dirichlet::DirichletModel;
use srtree::graph::{Relation, RelationGraph, Viewpoint};
use srtree::io::{read_map, write_map};
use srtree::map::{InsertStats, MapOptions, SrMap};
use srtree::objects::{extract_objects, ObjectOptions};
use srtree::semantic::SemanticMap;
use std::path::PathBuf;
use std::sync::{RwLock, RwLockReadGuard, RwLockWriteGuard};

/// Adds `SemanticMap` to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PySemanticMap>()
}

/// Eye height of the observer of [`PySemanticMap::infer_relations`], metres (as the CLI's
/// `relations infer`).
const EYE_HEIGHT_M: f64 = 1.8;

/// A semantic R-tree map: occupied cells, their objects and the relations between them.
#[pyclass(name = "SemanticMap", module = "urbansem", frozen)]
pub struct PySemanticMap {
    /// The map; locked only while the GIL is released.
    map: RwLock<SemanticMap>,
}

/// The columns of a set of cells, in the query's order.
struct CellColumns {
    centre: Vec<[f64; 3]>,
    label: Vec<u8>,
    object: Vec<u32>,
    hits: Vec<u32>,
    occupancy: Vec<f64>,
    rgb: Vec<[u8; 3]>,
    counts: Vec<[u16; Class::COUNT]>,
}

impl CellColumns {
    /// The columns of the cells `ids` of `map`.
    fn new(map: &SrMap, ids: &[u32]) -> Self {
        let n = ids.len();
        let mut out = CellColumns {
            centre: Vec::with_capacity(n),
            label: Vec::with_capacity(n),
            object: Vec::with_capacity(n),
            hits: Vec::with_capacity(n),
            occupancy: Vec::with_capacity(n),
            rgb: Vec::with_capacity(n),
            counts: Vec::with_capacity(n),
        };
        for &i in ids {
            let Some(c) = map.cells().get(i as usize) else {
                continue;
            };
            out.centre.push(map.centre(c.key));
            out.label.push(c.label);
            out.object
                .push(if c.object_votes > 0 { c.object } else { 0 });
            out.hits.push(c.hits);
            out.occupancy.push(c.occupancy());
            out.rgb.push(map.mean_rgb(i));
            out.counts.push(map.histogram(c));
        }
        out
    }

    /// The columns as a dict of arrays.
    fn into_dict(self, py: Python<'_>) -> PyResult<Bound<'_, PyDict>> {
        let d = PyDict::new(py);
        d.set_item("centre", to_rows(py, self.centre))?;
        d.set_item("label", to_array(py, self.label))?;
        d.set_item("object", to_array(py, self.object))?;
        d.set_item("hits", to_array(py, self.hits))?;
        d.set_item("occupancy", to_array(py, self.occupancy))?;
        d.set_item("rgb", to_rows(py, self.rgb))?;
        d.set_item("counts", to_rows(py, self.counts))?;
        Ok(d)
    }
}

/// `obj` as a float64 array of shape (n, 3) (converted by NumPy when it is not one).
fn xyz_array<'py>(obj: &Bound<'py, PyAny>, what: &str) -> PyResult<PyReadonlyArray2<'py, f64>> {
    if let Ok(a) = obj.extract::<PyReadonlyArray2<'py, f64>>() {
        return Ok(a);
    }
    let np = obj.py().import("numpy")?;
    let a = np.call_method1("asarray", (obj, "float64"))?;
    let ndim: usize = a.getattr("ndim")?.extract()?;
    if ndim != 2 {
        return Err(PyValueError::new_err(format!(
            "{what} must have shape (n, 3); got an array of {ndim} dimension(s)"
        )));
    }
    a.extract::<PyReadonlyArray2<'py, f64>>()
}

/// `obj` as a 1-D array of `dtype` (an unsigned NumPy type name) holding integers in
/// `0..=max` (converted when it is another integer array); anything else is a `ValueError`.
fn int_array<'py, T: numpy::Element + Copy + Into<u64>>(
    obj: &Bound<'py, PyAny>,
    what: &str,
    dtype: &str,
    max: u64,
) -> PyResult<PyReadonlyArray1<'py, T>> {
    let out_of_range = |lo: i128, hi: i128| {
        PyValueError::new_err(format!(
            "{what} must hold integers in 0..={max}; got values in {lo}..={hi}"
        ))
    };
    if let Ok(a) = obj.extract::<PyReadonlyArray1<'py, T>>() {
        let v = values(&a);
        let (lo, hi) = v.iter().fold((u64::MAX, 0), |(lo, hi), &x| {
            let x: u64 = x.into();
            (lo.min(x), hi.max(x))
        });
        if hi > max {
            return Err(out_of_range(i128::from(lo), i128::from(hi)));
        }
        return Ok(a);
    }
    let np = obj.py().import("numpy")?;
    let a = np.call_method1("asarray", (obj,))?;
    let ndim: usize = a.getattr("ndim")?.extract()?;
    let kind: String = a.getattr("dtype")?.getattr("kind")?.extract()?;
    if ndim != 1 || !(kind == "i" || kind == "u") {
        return Err(PyValueError::new_err(format!(
            "{what} must be a 1-D array of integers; got ndim {ndim}, dtype kind {kind:?}"
        )));
    }
    let size: usize = a.getattr("size")?.extract()?;
    if size > 0 {
        let lo: i128 = a.call_method0("min")?.call_method0("__int__")?.extract()?;
        let hi: i128 = a.call_method0("max")?.call_method0("__int__")?.extract()?;
        if lo < 0 || hi > i128::from(max) {
            return Err(out_of_range(lo, hi));
        }
    }
    a.call_method1("astype", (dtype,))?
        .extract::<PyReadonlyArray1<'py, T>>()
}

/// A cloud of `xyz` with optional `label`, `rgb` and `object` columns given as Python
/// objects (arrays or sequences).
fn cloud_from_objects(
    xyz: &Bound<'_, PyAny>,
    label: Option<&Bound<'_, PyAny>>,
    rgb: Option<&Bound<'_, PyAny>>,
    object: Option<&Bound<'_, PyAny>>,
) -> PyResult<PointCloud> {
    let xyz = xyz_array(xyz, "xyz")?;
    if xyz.shape()[1] != 3 {
        // The same message as `rows` gives.
        rows::<f64, 3>(&xyz, "xyz")?;
    }
    let label = label
        .map(|l| int_array::<u8>(l, "label", "uint8", (Class::COUNT - 1) as u64))
        .transpose()?;
    let object = object
        .map(|o| int_array::<u32>(o, "object", "uint32", u64::from(u32::MAX)))
        .transpose()?;
    let rgb = rgb
        .map(|c| -> PyResult<PyReadonlyArray2<'_, u8>> {
            if let Ok(a) = c.extract::<PyReadonlyArray2<'_, u8>>() {
                return Ok(a);
            }
            let np = c.py().import("numpy")?;
            np.call_method1("asarray", (c, "uint8"))?
                .extract::<PyReadonlyArray2<'_, u8>>()
        })
        .transpose()?;
    cloud_from_arrays(
        &xyz,
        None,
        rgb.as_ref(),
        label.as_ref(),
        None,
        object.as_ref(),
        true,
    )
}

/// Checks that a query point is finite.
fn finite(p: [f64; 3], what: &str) -> PyResult<[f64; 3]> {
    if p.iter().all(|v| v.is_finite()) {
        Ok(p)
    } else {
        Err(PyValueError::new_err(format!(
            "{what} must be three finite numbers; got {p:?}"
        )))
    }
}

/// A class given by name (case-insensitive) or id.
fn class_of(class: &Bound<'_, PyAny>) -> PyResult<Class> {
    let names = || {
        Class::ALL
            .iter()
            .map(|c| c.name())
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Ok(name) = class.extract::<String>() {
        return Class::from_name(&name.to_lowercase()).ok_or_else(|| {
            PyValueError::new_err(format!(
                "unknown class {name:?}: expected one of {}",
                names()
            ))
        });
    }
    let id: i64 = class.extract().map_err(|_| {
        PyValueError::new_err("class must be a class name (str) or a class id (int)")
    })?;
    u8::try_from(id)
        .ok()
        .and_then(Class::from_id)
        .ok_or_else(|| {
            PyValueError::new_err(format!(
                "unknown class id {id}: expected 0..={} ({})",
                Class::COUNT - 1,
                names()
            ))
        })
}

/// The statistics of an insertion as a dict.
fn stats_dict<'py>(py: Python<'py>, s: &InsertStats) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("points", s.points)?;
    d.set_item("new_cells", s.new_cells)?;
    d.set_item("touched_cells", s.touched_cells)?;
    d.set_item("rays", s.rays)?;
    d.set_item("misses", s.misses)?;
    d.set_item("bulk_loaded", s.bulk_loaded)?;
    Ok(d)
}

/// A Dirichlet label model from a dict (as `urbansem map eval-labels --model-out` writes it,
/// loaded by `json.load`) or the path of that JSON file.
fn dirichlet_model(obj: &Bound<'_, PyAny>) -> PyResult<DirichletModel> {
    let py = obj.py();
    let value = if obj.is_instance_of::<PyDict>() {
        obj.clone()
    } else {
        let path: PathBuf = obj.extract().map_err(|_| {
            PyValueError::new_err("dirichlet must be a dict or the path of a JSON model file")
        })?;
        let text = py
            .detach(|| std::fs::read_to_string(&path))
            .map_err(|e| MapError::new_err(format!("reading {}: {e}", path.display())))?;
        py.import("json")?.call_method1("loads", (text,))?
    };
    pythonize::depythonize(&value)
        .map_err(|e| PyValueError::new_err(format!("dirichlet: not a Dirichlet model: {e}")))
}

/// The map options of the constructor's arguments.
#[allow(clippy::too_many_arguments)]
fn map_options(
    resolution: f64,
    ray_casting: bool,
    log_odds_hit: f32,
    log_odds_miss: f32,
    log_odds_min: f32,
    log_odds_max: f32,
    max_ray: f64,
) -> MapOptions {
    MapOptions {
        resolution_m: resolution,
        ray_casting,
        log_odds_hit,
        log_odds_miss,
        log_odds_min,
        log_odds_max,
        max_ray_m: max_ray,
    }
}

/// An empty cell store with these options and Dirichlet model.
fn new_cells(options: MapOptions, dirichlet: Option<&Bound<'_, PyAny>>) -> PyResult<SrMap> {
    let mut cells = SrMap::new(options).map_err(|e| PyValueError::new_err(chain(&e)))?;
    if let Some(d) = dirichlet {
        cells.set_dirichlet(Some(dirichlet_model(d)?));
    }
    Ok(cells)
}

/// The sensor origin to insert with: `None` without one; an error when the map does not
/// cast rays (the origin would be ignored).
fn origin_for(cells: &SrMap, origin: Option<[f64; 3]>) -> PyResult<Option<[f64; 3]>> {
    match origin {
        Some(_) if !cells.options().ray_casting => Err(PyValueError::new_err(
            "a sensor origin is only used for ray casting: this map was made with ray_casting=False",
        )),
        Some(o) => Ok(Some(finite(o, "origin")?)),
        None => Ok(None),
    }
}

/// Options of the object extraction, checked.
fn object_options(
    min_cells: usize,
    normal_radius: f64,
    yaw_bins: usize,
    shrink_percentile: f64,
) -> PyResult<ObjectOptions> {
    if !(normal_radius.is_finite() && normal_radius > 0.0) {
        return Err(PyValueError::new_err(format!(
            "normal_radius must be a positive distance in metres; got {normal_radius}"
        )));
    }
    if yaw_bins == 0 {
        return Err(PyValueError::new_err("yaw_bins must be at least 1"));
    }
    if !(0.0..50.0).contains(&shrink_percentile) {
        return Err(PyValueError::new_err(format!(
            "shrink_percentile must be in [0, 50); got {shrink_percentile}"
        )));
    }
    Ok(ObjectOptions {
        min_cells,
        normal_radius_m: normal_radius,
        yaw_bins,
        shrink_percentile,
    })
}

/// A new semantic map of `cells` after inserting `cloud`: with its objects when `objects`.
fn build_map(
    mut cells: SrMap,
    cloud: &PointCloud,
    origin: Option<[f64; 3]>,
    objects: bool,
) -> srtree::Result<(SemanticMap, InsertStats)> {
    let stats = cells.insert_cloud(cloud, origin)?;
    let map = if objects {
        SemanticMap::with_objects(cells, &ObjectOptions::default())
    } else {
        SemanticMap::new(cells)
    };
    Ok((map, stats))
}

/// The relation triples of a graph: `(subject id, relation name, object id)` per relation
/// of every edge, in edge order (sorted by subject, object) and [`Relation::ALL`] order.
fn triples(graph: &RelationGraph, base_only: bool) -> Vec<(u32, &'static str, u32)> {
    graph
        .edges
        .iter()
        .flat_map(|e| {
            e.relations()
                .into_iter()
                .filter(|r| !base_only || Relation::BASE.contains(r))
                .map(move |r| (e.a, r.name(), e.b))
        })
        .collect()
}

impl PySemanticMap {
    /// A Python map holding `map`.
    fn wrap(map: SemanticMap) -> Self {
        PySemanticMap {
            map: RwLock::new(map),
        }
    }

    /// The map for reading (call with the GIL released).
    fn read(&self) -> PyResult<RwLockReadGuard<'_, SemanticMap>> {
        self.map
            .read()
            .map_err(|_| MapError::new_err("the map is unusable: an insertion panicked"))
    }

    /// The map for writing (call with the GIL released).
    fn write(&self) -> PyResult<RwLockWriteGuard<'_, SemanticMap>> {
        self.map
            .write()
            .map_err(|_| MapError::new_err("the map is unusable: an insertion panicked"))
    }

    /// The cells a query on the cell store finds, as a dict of arrays.
    fn query<'py>(
        &self,
        py: Python<'py>,
        ids_of: impl FnOnce(&SrMap) -> Vec<u32> + Send,
    ) -> PyResult<Bound<'py, PyDict>> {
        let columns = py.detach(|| -> PyResult<CellColumns> {
            let map = self.read()?;
            let ids = ids_of(&map.cells);
            Ok(CellColumns::new(&map.cells, &ids))
        })?;
        columns.into_dict(py)
    }
}

#[pymethods]
impl PySemanticMap {
    /// An empty map with these options (`resolution`: cell edge length in metres).
    #[new]
    #[pyo3(signature = (resolution = 0.1, *, ray_casting = false, log_odds_hit = 0.85,
        log_odds_miss = -0.4, log_odds_min = -2.0, log_odds_max = 3.5, max_ray = 100.0,
        dirichlet = None))]
    #[allow(clippy::too_many_arguments)]
    fn py_new(
        resolution: f64,
        ray_casting: bool,
        log_odds_hit: f32,
        log_odds_miss: f32,
        log_odds_min: f32,
        log_odds_max: f32,
        max_ray: f64,
        dirichlet: Option<&Bound<'_, PyAny>>,
    ) -> PyResult<Self> {
        let options = map_options(
            resolution,
            ray_casting,
            log_odds_hit,
            log_odds_miss,
            log_odds_min,
            log_odds_max,
            max_ray,
        );
        Ok(Self::wrap(SemanticMap::new(new_cells(options, dirichlet)?)))
    }

    /// A map of one cloud given as arrays, with its objects (as `urbansem map build`).
    #[staticmethod]
    #[pyo3(signature = (xyz, label = None, *, rgb = None, object = None, sensor_origin = None,
        resolution = 0.1, ray_casting = None, dirichlet = None, objects = true))]
    #[allow(clippy::too_many_arguments)]
    fn build(
        py: Python<'_>,
        xyz: &Bound<'_, PyAny>,
        label: Option<&Bound<'_, PyAny>>,
        rgb: Option<&Bound<'_, PyAny>>,
        object: Option<&Bound<'_, PyAny>>,
        sensor_origin: Option<[f64; 3]>,
        resolution: f64,
        ray_casting: Option<bool>,
        dirichlet: Option<&Bound<'_, PyAny>>,
        objects: bool,
    ) -> PyResult<Self> {
        let cloud = cloud_from_objects(xyz, label, rgb, object)?;
        let options = MapOptions {
            resolution_m: resolution,
            ray_casting: ray_casting.unwrap_or(sensor_origin.is_some()),
            ..MapOptions::default()
        };
        let cells = new_cells(options, dirichlet)?;
        let origin = origin_for(&cells, sensor_origin)?;
        let (map, _) = py
            .detach(|| build_map(cells, &cloud, origin, objects))
            .map_err(raise!(MapError))?;
        Ok(Self::wrap(map))
    }

    /// A map of a cloud file (.ply, .pcd, .las, .laz, KITTI .bin), with its objects, as
    /// `urbansem map build --cloud` writes it; `labels` attaches a per-point uint32 label
    /// file whose ids `label_set` (`kitti360`, `mcd`) maps onto the classes.
    #[staticmethod]
    #[pyo3(signature = (path, *, labels = None, label_set = None, sensor_origin = None,
        resolution = 0.1, ray_casting = None, dirichlet = None, objects = true))]
    #[allow(clippy::too_many_arguments)]
    fn from_cloud(
        py: Python<'_>,
        path: PathBuf,
        labels: Option<PathBuf>,
        label_set: Option<&str>,
        sensor_origin: Option<[f64; 3]>,
        resolution: f64,
        ray_casting: Option<bool>,
        dirichlet: Option<&Bound<'_, PyAny>>,
        objects: bool,
    ) -> PyResult<Self> {
        let set = match (&labels, label_set) {
            (None, Some(_)) => {
                return Err(PyValueError::new_err(
                    "label_set names the ids of a label file: give labels too",
                ))
            }
            (Some(_), None) => {
                return Err(PyValueError::new_err(
                    "labels needs label_set (kitti360 or mcd) to map its ids onto the classes",
                ))
            }
            (Some(_), Some(name)) => Some(LabelSet::from_name(name).ok_or_else(|| {
                PyValueError::new_err(format!("unknown label_set {name:?}: use kitti360 or mcd"))
            })?),
            (None, None) => None,
        };
        let options = MapOptions {
            resolution_m: resolution,
            ray_casting: ray_casting.unwrap_or(sensor_origin.is_some()),
            ..MapOptions::default()
        };
        let cells = new_cells(options, dirichlet)?;
        let origin = origin_for(&cells, sensor_origin)?;
        let (map, _) = py.detach(|| -> PyResult<_> {
            let (mut cloud, _) = read_cloud_with(&path, &ReadOptions::default()).map_err(|e| {
                MapError::new_err(format!("reading {}: {}", path.display(), chain(&e)))
            })?;
            if let (Some(file), Some(set)) = (&labels, set) {
                let raw = read_label_file(file, Some(cloud.len())).map_err(|e| {
                    MapError::new_err(format!("reading labels {}: {}", file.display(), chain(&e)))
                })?;
                set.attach(&mut cloud, raw);
            }
            build_map(cells, &cloud, origin, objects).map_err(|e| {
                MapError::new_err(format!("inserting {}: {}", path.display(), chain(&e)))
            })
        })?;
        Ok(Self::wrap(map))
    }

    /// Reads a `.srt` map file (cells, objects and relations).
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let map = py.detach(|| read_map(&path)).map_err(raise!(MapError))?;
        Ok(Self::wrap(map))
    }

    /// Writes the map (cells, objects and relations) as a `.srt` file.
    fn save(&self, py: Python<'_>, path: PathBuf) -> PyResult<()> {
        py.detach(|| -> PyResult<()> {
            let map = self.read()?;
            write_map(&path, &map).map_err(raise!(MapError))
        })
    }

    /// Inserts a batch of points (with ray casting from `origin` when the map casts rays);
    /// the objects are extracted anew and the relation edges dropped (they described the
    /// old cells). Returns the insertion's statistics.
    #[pyo3(signature = (xyz, label = None, *, rgb = None, object = None, origin = None))]
    fn insert<'py>(
        &self,
        py: Python<'py>,
        xyz: &Bound<'py, PyAny>,
        label: Option<&Bound<'py, PyAny>>,
        rgb: Option<&Bound<'py, PyAny>>,
        object: Option<&Bound<'py, PyAny>>,
        origin: Option<[f64; 3]>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let cloud = cloud_from_objects(xyz, label, rgb, object)?;
        let stats = py.detach(|| -> PyResult<InsertStats> {
            let mut map = self.write()?;
            let origin = origin_for(&map.cells, origin)?;
            let stats = map
                .cells
                .insert_cloud(&cloud, origin)
                .map_err(raise!(MapError))?;
            let objects = extract_objects(&map.cells, &ObjectOptions::default());
            map.relations = RelationGraph {
                viewpoint: None,
                objects: objects.iter().map(|o| o.node()).collect(),
                edges: Vec::new(),
            };
            Ok(stats)
        })?;
        stats_dict(py, &stats)
    }

    /// Extracts the objects of the cells anew with these options (dropping the relation
    /// edges); returns how many there are.
    #[pyo3(signature = (*, min_cells = 5, normal_radius = 0.3, yaw_bins = 45,
        shrink_percentile = 2.0))]
    fn extract_objects(
        &self,
        py: Python<'_>,
        min_cells: usize,
        normal_radius: f64,
        yaw_bins: usize,
        shrink_percentile: f64,
    ) -> PyResult<usize> {
        let options = object_options(min_cells, normal_radius, yaw_bins, shrink_percentile)?;
        py.detach(|| -> PyResult<usize> {
            let mut map = self.write()?;
            let objects = extract_objects(&map.cells, &options);
            map.relations = RelationGraph {
                viewpoint: None,
                objects: objects.iter().map(|o| o.node()).collect(),
                edges: Vec::new(),
            };
            Ok(objects.len())
        })
    }

    /// Occupied cells intersecting the box `[min, max]` (metres), sorted by cell.
    fn query_box<'py>(
        &self,
        py: Python<'py>,
        min: [f64; 3],
        max: [f64; 3],
    ) -> PyResult<Bound<'py, PyDict>> {
        let (min, max) = (finite(min, "min")?, finite(max, "max")?);
        self.query(py, |m| {
            let mut ids = m.cells_in_box(min, max);
            ids.sort_unstable();
            ids
        })
    }

    /// Occupied cells whose centre lies within `radius` metres of `centre`, sorted by cell.
    fn query_radius<'py>(
        &self,
        py: Python<'py>,
        centre: [f64; 3],
        radius: f64,
    ) -> PyResult<Bound<'py, PyDict>> {
        let centre = finite(centre, "centre")?;
        if !(radius.is_finite() && radius >= 0.0) {
            return Err(PyValueError::new_err(format!(
                "radius must be a finite distance ≥ 0; got {radius}"
            )));
        }
        self.query(py, |m| {
            let mut ids = m.cells_within_radius(centre, radius);
            ids.sort_unstable();
            ids
        })
    }

    /// The `k` occupied cells with centres nearest to `point`, nearest first.
    fn knn<'py>(&self, py: Python<'py>, point: [f64; 3], k: usize) -> PyResult<Bound<'py, PyDict>> {
        let point = finite(point, "point")?;
        self.query(py, |m| m.nearest_cells(point, k))
    }

    /// Occupied cells of a class (name such as `"car"`, or id), in cell order.
    fn cells_of_class<'py>(
        &self,
        py: Python<'py>,
        cls: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let class = class_of(cls)?;
        self.query(py, |m| m.cells_of_class(class))
    }

    /// Occupied cells whose majority object is `object`, in cell order.
    fn cells_of_object<'py>(&self, py: Python<'py>, object: u32) -> PyResult<Bound<'py, PyDict>> {
        self.query(py, |m| m.cells_of_object(object))
    }

    /// Every stored cell (with `occupied_only`, the occupied ones), in cell order.
    #[pyo3(signature = (*, occupied_only = true))]
    fn cells<'py>(&self, py: Python<'py>, occupied_only: bool) -> PyResult<Bound<'py, PyDict>> {
        self.query(py, |m| {
            (0..m.len() as u32)
                .filter(|&i| !occupied_only || m.cells()[i as usize].occupied())
                .collect()
        })
    }

    /// The class names, indexed by class id.
    #[staticmethod]
    fn class_names() -> Vec<&'static str> {
        Class::ALL.iter().map(|c| c.name()).collect()
    }

    /// Number of stored cells (free cells kept by ray casting included).
    fn __len__(&self, py: Python<'_>) -> PyResult<usize> {
        py.detach(|| Ok(self.read()?.cells.len()))
    }

    /// Cell edge length, metres.
    #[getter]
    fn resolution(&self, py: Python<'_>) -> PyResult<f64> {
        py.detach(|| Ok(self.read()?.cells.resolution_m()))
    }

    /// The map's options as a dict (resolution, ray casting, log-odds, longest ray).
    #[getter]
    fn options<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let o = py.detach(|| Ok::<_, PyErr>(self.read()?.cells.options().clone()))?;
        let d = PyDict::new(py);
        d.set_item("resolution", o.resolution_m)?;
        d.set_item("ray_casting", o.ray_casting)?;
        d.set_item("log_odds_hit", o.log_odds_hit)?;
        d.set_item("log_odds_miss", o.log_odds_miss)?;
        d.set_item("log_odds_min", o.log_odds_min)?;
        d.set_item("log_odds_max", o.log_odds_max)?;
        d.set_item("max_ray", o.max_ray_m)?;
        Ok(d)
    }

    /// Height of the R-tree (its tallest run).
    #[getter]
    fn tree_height(&self, py: Python<'_>) -> PyResult<usize> {
        py.detach(|| Ok(self.read()?.cells.tree_height()))
    }

    /// Bytes held by the map, by part (the `memory` dict of `urbansem map build --json`).
    fn memory<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let report = py.detach(|| Ok::<_, PyErr>(self.read()?.cells.memory()))?;
        Ok(pythonize::pythonize(py, &report)?)
    }

    /// The objects as a dict of arrays: `id`, `label`, `cells`, `centroid` (m, 3), and the
    /// oriented box's `box_centre` (m, 3), `half_extents` (m, 3) and `yaw` (radians).
    fn objects<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let nodes = py.detach(|| Ok::<_, PyErr>(self.read()?.relations.objects.clone()))?;
        let d = PyDict::new(py);
        d.set_item("id", to_array(py, nodes.iter().map(|o| o.id).collect()))?;
        d.set_item(
            "label",
            to_array(py, nodes.iter().map(|o| o.class.id()).collect()),
        )?;
        d.set_item(
            "cells",
            to_array(py, nodes.iter().map(|o| o.cells as u64).collect()),
        )?;
        d.set_item(
            "centroid",
            to_rows(py, nodes.iter().map(|o| o.centroid).collect()),
        )?;
        d.set_item(
            "box_centre",
            to_rows(py, nodes.iter().map(|o| o.bbox.centre).collect()),
        )?;
        d.set_item(
            "half_extents",
            to_rows(py, nodes.iter().map(|o| o.bbox.half_extents).collect()),
        )?;
        d.set_item(
            "yaw",
            to_array(py, nodes.iter().map(|o| o.bbox.yaw_rad).collect()),
        )?;
        Ok(d)
    }

    /// The relations between the objects as `(subject_id, relation, object_id)` triples
    /// (relations `On`, `LeftOf`, `Behind` and, unless `base_only`, their converses
    /// `RightOf`, `InFrontOf`), sorted by subject, object.
    #[pyo3(signature = (*, base_only = false))]
    fn relations<'py>(&self, py: Python<'py>, base_only: bool) -> PyResult<Bound<'py, PyList>> {
        let t = py.detach(|| Ok::<_, PyErr>(triples(&self.read()?.relations, base_only)))?;
        PyList::new(py, t)
    }

    /// The relation graph as the dict `urbansem relations infer --json` prints (viewpoint,
    /// objects, edges with relation bits).
    fn relation_graph<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let g = py.detach(|| Ok::<_, PyErr>(self.read()?.relations.clone()))?;
        Ok(pythonize::pythonize(py, &g)?)
    }

    /// The relation graph in Graphviz DOT (as `urbansem relations infer --dot`).
    fn to_dot(&self, py: Python<'_>) -> PyResult<String> {
        py.detach(|| Ok(self.read()?.relations.to_dot()))
    }

    /// Infers the relations between the map's objects seen from `viewpoint` `(x, y, yaw)`
    /// (eye 1.8 m up; yaw radians counter-clockwise from x) with a relation model written
    /// by `urbansem relations train` (SVMs + MLN); `osm` completes the buildings with their
    /// outlines (`cloud_frame`: the map's frame, `local`, `utm:ZONE[N|S]` or
    /// `enu:LAT,LON`). Replaces the map's objects and relations; returns the triples.
    #[pyo3(signature = (model, viewpoint, *, osm = None, cloud_frame = "local", seed = 1))]
    fn infer_relations<'py>(
        &self,
        py: Python<'py>,
        model: PathBuf,
        viewpoint: (f64, f64, f64),
        osm: Option<PyRef<'py, PyOsmMap>>,
        cloud_frame: &str,
        seed: u64,
    ) -> PyResult<Bound<'py, PyList>> {
        let (x, y, yaw) = viewpoint;
        finite([x, y, yaw], "viewpoint")?;
        let frame: CloudFrame = cloud_frame
            .parse()
            .map_err(|e: geodata::georef::GeorefError| PyValueError::new_err(chain(&e)))?;
        let osm = osm.map(|o| o.map.clone());
        let triples = py.detach(|| -> PyResult<_> {
            let outlines = match &osm {
                None => MapOutlines::default(),
                Some(osm) => MapOutlines::from_osm(osm, &frame).map_err(|e| {
                    MapError::new_err(format!(
                        "moving the OSM outlines into the map's frame: {}",
                        chain(&e)
                    ))
                })?,
            };
            let model = srtree::jobs::read_model(&model).map_err(raise!(MapError))?;
            let vp = Viewpoint {
                position: [x, y, EYE_HEIGHT_M],
                yaw_rad: yaw,
            };
            let mut infer = mln::infer::InferOptions::default();
            infer.walksat.seed = seed;
            let mut map = self.write()?;
            let graph = model
                .infer_map_graph(&map.cells, vp, &outlines, &infer)
                .map_err(|e| MapError::new_err(format!("inferring relations: {}", chain(&e))))?;
            map.relations = graph;
            Ok(triples(&map.relations, false))
        })?;
        PyList::new(py, triples)
    }

    /// The viewpoint `(x, y, z, yaw)` the relations were inferred for, or None.
    #[getter]
    fn viewpoint(&self, py: Python<'_>) -> PyResult<Option<(f64, f64, f64, f64)>> {
        py.detach(|| {
            Ok(self
                .read()?
                .relations
                .viewpoint
                .map(|v| (v.position[0], v.position[1], v.position[2], v.yaw_rad)))
        })
    }

    /// Cells, resolution, objects and relation edges in one line.
    fn __repr__(&self, py: Python<'_>) -> PyResult<String> {
        py.detach(|| {
            let map = self.read()?;
            Ok(format!(
                "SemanticMap({} cells at {} m, {} objects, {} relation edges)",
                map.cells.len(),
                map.cells.resolution_m(),
                map.relations.objects.len(),
                map.relations.edges.len()
            ))
        })
    }
}
