//! `OsmMap`: an OpenStreetMap file's buildings and street network as NumPy arrays in the
//! map's local metric frame (east, north in metres), and as GeoJSON.

use crate::arrays::{to_array, to_rows};
use crate::error::raise;
use geodata::osm::OsmMap;
use numpy::{PyArray1, PyArray2};
use pyo3::prelude::*;
use pyo3::types::PyList;
use std::path::PathBuf;
use std::sync::Arc;

/// Adds `OsmMap` to the module.
pub fn register(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<PyOsmMap>()
}

/// An OpenStreetMap map (`.osm` XML or `.osm.pbf`) in its local metric frame.
#[pyclass(name = "OsmMap", module = "urbansem", frozen)]
pub struct PyOsmMap {
    /// The parsed map, shared with the objects built from it.
    pub map: Arc<OsmMap>,
    /// The file it was read from.
    pub path: PathBuf,
}

#[pymethods]
impl PyOsmMap {
    /// Reads a map file.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let map = py
            .detach(|| OsmMap::load(&path))
            .map_err(raise!(OsmError))?;
        Ok(PyOsmMap {
            map: Arc::new(map),
            path,
        })
    }

    /// The file the map was read from.
    #[getter]
    fn path(&self) -> PathBuf {
        self.path.clone()
    }

    /// `(lat, lon)` of the local frame's origin.
    #[getter]
    fn origin(&self) -> (f64, f64) {
        self.map.frame.origin()
    }

    /// `(min_lon, min_lat, max_lon, max_lat)` of the file.
    #[getter]
    fn bbox_lonlat(&self) -> (f64, f64, f64, f64) {
        let b = self.map.bbox_lonlat;
        (b[0], b[1], b[2], b[3])
    }

    /// Number of building outlines.
    #[getter]
    fn building_count(&self) -> usize {
        self.map.buildings.len()
    }

    /// Each building's outer ring as an `(k, 2)` array (counter-clockwise, not closed).
    #[getter]
    fn buildings<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(
            py,
            self.map
                .buildings
                .iter()
                .map(|b| to_rows(py, b.outer.clone())),
        )
    }

    /// Each building's holes: a list (per building) of `(k, 2)` arrays (clockwise).
    #[getter]
    fn building_holes<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        let lists: PyResult<Vec<Bound<'py, PyList>>> = self
            .map
            .buildings
            .iter()
            .map(|b| PyList::new(py, b.inners.iter().map(|h| to_rows(py, h.clone()))))
            .collect();
        PyList::new(py, lists?)
    }

    /// The OSM id of each building (ids repeat when an element has several outer rings).
    #[getter]
    fn building_ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        to_array(py, self.map.buildings.iter().map(|b| b.osm_id).collect())
    }

    /// Street segments as an `(m, 4)` array of `[ax, ay, bx, by]` (metres).
    #[getter]
    fn segments<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let rows: Vec<[f64; 4]> = self
            .map
            .streets
            .segments
            .iter()
            .map(|s| [s.a[0], s.a[1], s.b[0], s.b[1]])
            .collect();
        to_rows(py, rows)
    }

    /// The `highway` value of each street segment.
    #[getter]
    fn segment_highways(&self) -> Vec<String> {
        self.map
            .streets
            .segments
            .iter()
            .map(|s| s.highway.clone())
            .collect()
    }

    /// The OSM way id of each street segment.
    #[getter]
    fn segment_ways<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        let ids = self
            .map
            .streets
            .segments
            .iter()
            .map(|s| self.map.highways.get(s.way_index).map_or(-1, |w| w.osm_id))
            .collect();
        to_array(py, ids)
    }

    /// Each highway way's centre line as an `(k, 2)` array (metres).
    #[getter]
    fn streets<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyList>> {
        PyList::new(
            py,
            self.map
                .highways
                .iter()
                .map(|w| to_rows(py, w.points.clone())),
        )
    }

    /// The `highway` value of each way in `streets`.
    #[getter]
    fn street_highways(&self) -> Vec<String> {
        self.map
            .highways
            .iter()
            .map(|w| w.highway.clone())
            .collect()
    }

    /// Street intersections as an `(k, 2)` array (metres).
    #[getter]
    fn intersections<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray2<f64>> {
        let rows = self
            .map
            .streets
            .intersections
            .iter()
            .map(|i| i.position)
            .collect();
        to_rows(py, rows)
    }

    /// Local-frame points `(n, 2)` as `(n, 2)` `[lat, lon]` degrees.
    fn to_wgs84<'py>(
        &self,
        py: Python<'py>,
        xy: numpy::PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let pts = crate::arrays::rows::<f64, 2>(&xy, "xy")?;
        let out = pts
            .iter()
            .map(|&p| {
                let (lat, lon) = self.map.frame.to_wgs84(p);
                [lat, lon]
            })
            .collect();
        Ok(to_rows(py, out))
    }

    /// `[lat, lon]` degrees `(n, 2)` as local-frame points `(n, 2)`.
    fn to_local<'py>(
        &self,
        py: Python<'py>,
        latlon: numpy::PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let pts = crate::arrays::rows::<f64, 2>(&latlon, "latlon")?;
        let out = pts
            .iter()
            .map(|&[lat, lon]| self.map.frame.to_local(lat, lon))
            .collect();
        Ok(to_rows(py, out))
    }

    /// The buildings and highways as an RFC 7946 FeatureCollection (a dict).
    fn to_geojson<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        let value = py.detach(|| geodata::geojson::osm_map(&self.map));
        Ok(pythonize::pythonize(py, &value)?)
    }

    fn __repr__(&self) -> String {
        format!(
            "OsmMap({:?}: {} buildings, {} highway ways, {} street segments)",
            self.path.display().to_string(),
            self.map.buildings.len(),
            self.map.highways.len(),
            self.map.streets.segments.len()
        )
    }
}
