"""Type stubs of the native module ``urbansem._urbansem`` (the Rust bindings).

Users import from ``urbansem`` and its submodules; this file types the layer beneath.
"""

import os
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np
import numpy.typing as npt

__version__: str
_Path = Union[str, os.PathLike]

# --- errors -----------------------------------------------------------------------------

class UrbansemError(Exception):
    """Base class of every error urbansem raises."""

class CloudError(UrbansemError):
    """A point cloud (or bag) could not be read or written."""

class OsmError(UrbansemError):
    """An OpenStreetMap file could not be read."""

class PboError(UrbansemError):
    """A pseudo-Boolean problem is malformed."""

class MlnError(UrbansemError):
    """A Markov logic program, its evidence or its query could not be read or grounded."""

class MapError(UrbansemError):
    """A semantic map could not be built, queried, read or written."""

class LocalizeError(UrbansemError):
    """Localization failed: no usable map, index or scan."""

class StreetsError(UrbansemError):
    """Street geometry could not be estimated."""

class FleetError(UrbansemError):
    """A shard plan could not be made, a shard run or the results merged."""

# --- point clouds -----------------------------------------------------------------------

def read_cloud(
    path: _Path,
    *,
    drop_non_finite: bool = False,
    topic: Optional[str] = None,
    index: Optional[int] = None,
    time: Optional[float] = None,
    labels: Optional[_Path] = None,
    label_set: Optional[str] = None,
) -> Dict[str, np.ndarray]:
    """Reads a point cloud (.ply, .pcd, .las, .laz, KITTI .bin, or one PointCloud2 message of a
    ROS 2 .mcap bag, chosen by ``topic`` and ``index`` or by ``time`` in seconds since the
    epoch) as a dict: ``xyz`` (n, 3) float64 and the columns the file has (``intensity``
    float32, ``rgb`` (n, 3) uint8, ``label`` uint8, ``raw_label`` uint32, ``object`` uint32).
    ``labels`` attaches a per-point uint32 label file; ``label_set`` (``mcd``, ``kitti360``)
    maps its ids to urbansem classes in ``label``."""

def write_cloud(
    path: _Path,
    xyz: npt.ArrayLike,
    *,
    intensity: Optional[npt.ArrayLike] = None,
    rgb: Optional[npt.ArrayLike] = None,
    label: Optional[npt.ArrayLike] = None,
    raw_label: Optional[npt.ArrayLike] = None,
    object: Optional[npt.ArrayLike] = None,
    encoding: str = "binary",
    double: bool = False,
) -> None:
    """Writes arrays as a point cloud file (format from the extension); ``encoding`` is
    ``ascii``, ``binary``, ``binary_big_endian`` (PLY) or ``binary_compressed`` (PCD);
    ``double`` stores positions as float64."""

def bag_topics(path: _Path) -> Dict[str, Any]:
    """A ROS 2 bag's topics, message counts and point fields (``urbansem cloud info --json``)."""

def bag_poses(path: _Path, topic: str, *, child_frame: Optional[str] = None) -> Dict[str, Any]:
    """Every pose on an Odometry, PoseStamped or TF topic: ``stamp_ns``, ``log_time_ns``,
    ``translation`` (n, 3), ``rotation`` (n, 4) ``[x, y, z, w]``, ``yaw`` (n,), ``frame_id``,
    ``child_frame_id``; ``child_frame`` keeps one child frame of a TF topic."""

# --- OpenStreetMap ----------------------------------------------------------------------

class OsmMap:
    """An OpenStreetMap map (.osm XML or .osm.pbf) in its local metric frame (east, north)."""

    @staticmethod
    def load(path: _Path) -> "OsmMap":
        """Reads a map file."""
    @property
    def path(self) -> str: ...
    @property
    def origin(self) -> Tuple[float, float]:
        """``(lat, lon)`` of the local frame's origin."""
    @property
    def bbox_lonlat(self) -> Tuple[float, float, float, float]: ...
    @property
    def building_count(self) -> int: ...
    @property
    def buildings(self) -> List[np.ndarray]:
        """Each building's outer ring, (k, 2) float64, counter-clockwise, not closed."""
    @property
    def building_holes(self) -> List[List[np.ndarray]]: ...
    @property
    def building_ids(self) -> np.ndarray: ...
    @property
    def segments(self) -> np.ndarray:
        """Street segments, (m, 4) float64 ``[ax, ay, bx, by]``."""
    @property
    def segment_highways(self) -> List[str]: ...
    @property
    def segment_ways(self) -> np.ndarray: ...
    @property
    def streets(self) -> List[np.ndarray]:
        """Each highway way's centre line, (k, 2) float64."""
    @property
    def street_highways(self) -> List[str]: ...
    @property
    def intersections(self) -> np.ndarray: ...
    def to_wgs84(self, xy: npt.ArrayLike) -> np.ndarray:
        """Local points (n, 2) → ``[lat, lon]`` (n, 2)."""
    def to_local(self, latlon: npt.ArrayLike) -> np.ndarray:
        """``[lat, lon]`` (n, 2) → local points (n, 2)."""
    def to_geojson(self) -> Dict[str, Any]:
        """Buildings (Polygons) and highways (LineStrings) as an RFC 7946 FeatureCollection."""

# --- pseudo-Boolean optimization --------------------------------------------------------

def pbo_solve(
    terms: Sequence[Tuple[float, Sequence[int]]],
    *,
    constant: float = 0.0,
    num_vars: Optional[int] = None,
    quadratize: str = "ish",
    probe: bool = False,
    improve: int = 0,
    seed: int = 0,
) -> Dict[str, Any]: ...
def pbo_solve_file(
    path: _Path, *, quadratize: str = "ish", probe: bool = False, improve: int = 0, seed: int = 0
) -> Dict[str, Any]: ...

# --- Markov logic -----------------------------------------------------------------------

def mln_infer(
    program: _Path,
    evidence: Sequence[_Path],
    queries: Optional[Sequence[str]] = None,
    *,
    query_file: Optional[_Path] = None,
    method: str = "qpbo",
    quadratize: str = "asm",
    representation: str = "auto",
    probe: bool = False,
    improve: int = 0,
    tabu: int = 20000,
    polish: int = 0,
    flips: int = 1000000,
    chains: int = 2,
    seed: int = 0,
) -> Tuple[Dict[str, int], Dict[str, Any]]: ...
def mln_marginals(
    program: _Path,
    evidence: Sequence[_Path],
    queries: Optional[Sequence[str]] = None,
    *,
    query_file: Optional[_Path] = None,
    samples: int = 5000,
    burn_in: int = 500,
    chains: int = 2,
    seed: int = 0,
) -> Tuple[Dict[str, float], Dict[str, Any]]: ...
def mln_learn(
    program: _Path,
    training: Sequence[_Path],
    queries: Optional[Sequence[str]] = None,
    *,
    query_file: Optional[_Path] = None,
    output: Optional[_Path] = None,
    method: str = "perceptron",
    expectations: str = "map",
    samples: int = 500,
    epochs: int = 30,
    rate: float = 1.0,
    l2: float = 0.0,
    warm_start: bool = False,
    seed: int = 0,
) -> Tuple[str, Dict[str, Any]]: ...

# --- semantic map (srtree) ----------------------------------------------------------------

#: What every cell query of :class:`SemanticMap` returns, one row per cell in the query's
#: order: ``centre`` (n, 3) float64 metres, ``label`` (n,) uint8 class id (see
#: :meth:`SemanticMap.class_names`), ``object`` (n,) uint32 majority object id (0: none),
#: ``hits`` (n,) uint32 points that fell in the cell, ``occupancy`` (n,) float64
#: probability, ``rgb`` (n, 3) uint8 mean colour (128 grey without colours), ``counts``
#: (n, 10) uint16 class histogram.
Cells = Dict[str, np.ndarray]

class SemanticMap:
    """The semantic R-tree map: fixed-size occupancy cells kept where occupied (class
    histogram, colour, object per cell) under an R-tree, the objects of the cells and the
    spatial relation graph between them; saved as ``.srt`` files. Long calls release the
    GIL; queries from several threads run in parallel."""

    def __init__(
        self,
        resolution: float = 0.1,
        *,
        ray_casting: bool = False,
        log_odds_hit: float = 0.85,
        log_odds_miss: float = -0.4,
        log_odds_min: float = -2.0,
        log_odds_max: float = 3.5,
        max_ray: float = 100.0,
        dirichlet: Optional[Union[Dict[str, Any], _Path]] = None,
    ) -> None:
        """An empty map: ``resolution`` is the cell edge (m); ``ray_casting`` marks the
        cells between a sensor origin and its points as free; ``dirichlet`` a label model
        (dict or JSON file of ``urbansem map eval-labels --model-out``)."""
    @staticmethod
    def build(
        xyz: npt.ArrayLike,
        label: Optional[npt.ArrayLike] = None,
        *,
        rgb: Optional[npt.ArrayLike] = None,
        object: Optional[npt.ArrayLike] = None,
        sensor_origin: Optional[Sequence[float]] = None,
        resolution: float = 0.1,
        ray_casting: Optional[bool] = None,
        dirichlet: Optional[Union[Dict[str, Any], _Path]] = None,
        objects: bool = True,
    ) -> "SemanticMap":
        """A map of one cloud given as arrays (``xyz`` (n, 3), ``label`` class ids 0–9,
        ``rgb`` (n, 3) uint8, ``object`` ids), with its objects, as ``urbansem map build``;
        ray casting from ``sensor_origin`` unless ``ray_casting=False``."""
    @staticmethod
    def from_cloud(
        path: _Path,
        *,
        labels: Optional[_Path] = None,
        label_set: Optional[str] = None,
        sensor_origin: Optional[Sequence[float]] = None,
        resolution: float = 0.1,
        ray_casting: Optional[bool] = None,
        dirichlet: Optional[Union[Dict[str, Any], _Path]] = None,
        objects: bool = True,
    ) -> "SemanticMap":
        """A map of a cloud file (.ply, .pcd, .las, .laz, KITTI .bin) as ``urbansem map
        build --cloud`` writes it; ``labels`` attaches a per-point uint32 label file whose ids
        ``label_set`` (``kitti360`` or ``mcd``) maps onto the classes."""
    @staticmethod
    def load(path: _Path) -> "SemanticMap":
        """Reads a ``.srt`` map file (cells, objects, relations)."""
    def save(self, path: _Path) -> None:
        """Writes the map as a ``.srt`` file."""
    def insert(
        self,
        xyz: npt.ArrayLike,
        label: Optional[npt.ArrayLike] = None,
        *,
        rgb: Optional[npt.ArrayLike] = None,
        object: Optional[npt.ArrayLike] = None,
        origin: Optional[Sequence[float]] = None,
    ) -> Dict[str, Any]:
        """Inserts a batch of points (ray casting from ``origin`` if the map casts rays),
        extracts the objects anew and drops the relation edges; returns the statistics
        (``points``, ``new_cells``, ``touched_cells``, ``rays``, ``misses``,
        ``bulk_loaded``)."""
    def extract_objects(
        self,
        *,
        min_cells: int = 5,
        normal_radius: float = 0.3,
        yaw_bins: int = 45,
        shrink_percentile: float = 2.0,
    ) -> int:
        """Extracts the objects anew with these options (drops the relation edges); returns
        their number."""
    def query_box(self, min: Sequence[float], max: Sequence[float]) -> Cells:
        """Occupied cells intersecting the box ``[min, max]`` (m), in cell order."""
    def query_radius(self, centre: Sequence[float], radius: float) -> Cells:
        """Occupied cells whose centre lies within ``radius`` m of ``centre``, in cell order."""
    def knn(self, point: Sequence[float], k: int) -> Cells:
        """The ``k`` occupied cells with centres nearest to ``point``, nearest first."""
    def cells_of_class(self, cls: Union[str, int]) -> Cells:
        """Occupied cells of a class (name such as ``"car"``, or id), in cell order."""
    def cells_of_object(self, object: int) -> Cells:
        """Occupied cells whose majority object is ``object``, in cell order."""
    def cells(self, *, occupied_only: bool = True) -> Cells:
        """Every stored cell (by default only the occupied ones), in cell order."""
    @staticmethod
    def class_names() -> List[str]:
        """The class names indexed by class id (``unlabelled``, ``car``, ``building``, …)."""
    def __len__(self) -> int:
        """Number of stored cells (free cells kept by ray casting included)."""
    @property
    def resolution(self) -> float:
        """Cell edge length, metres."""
    @property
    def options(self) -> Dict[str, Any]:
        """``resolution``, ``ray_casting``, ``log_odds_*``, ``max_ray``."""
    @property
    def tree_height(self) -> int:
        """Height of the R-tree."""
    def memory(self) -> Dict[str, Any]:
        """Bytes held by part (``cells``, ``cell_bytes``, …, ``total_bytes``,
        ``bytes_per_cell``), as ``urbansem map build --json``'s ``memory``."""
    def objects(self) -> Dict[str, np.ndarray]:
        """The objects: ``id`` uint32, ``label`` uint8, ``cells`` uint64, ``centroid`` (m, 3),
        oriented box ``box_centre`` (m, 3), ``half_extents`` (m, 3), ``yaw`` (radians)."""
    def relations(self, *, base_only: bool = False) -> List[Tuple[int, str, int]]:
        """``(subject_id, relation, object_id)`` triples: ``On``, ``LeftOf``, ``Behind`` and
        (unless ``base_only``) the converses ``RightOf``, ``InFrontOf``."""
    def relation_graph(self) -> Dict[str, Any]:
        """The relation graph as ``urbansem relations infer --json`` prints it."""
    def to_dot(self) -> str:
        """The relation graph in Graphviz DOT (``urbansem relations infer --dot``)."""
    def infer_relations(
        self,
        model: _Path,
        viewpoint: Tuple[float, float, float],
        *,
        osm: Optional[OsmMap] = None,
        cloud_frame: str = "local",
        seed: int = 1,
    ) -> List[Tuple[int, str, int]]:
        """Infers the relations between the objects seen from ``(x, y, yaw)`` with a model
        of ``urbansem relations train`` (SVMs + MLN), as ``urbansem relations infer``;
        ``osm`` outlines complete the buildings. Stores and returns the triples."""
    @property
    def viewpoint(self) -> Optional[Tuple[float, float, float, float]]:
        """``(x, y, z, yaw)`` the relations were inferred for, or None."""

# --- localization -----------------------------------------------------------------------

class _Localizer:
    """A map prepared once for global localization (``urbansem.Localizer`` wraps it)."""

    def __init__(
        self,
        map: Union[OsmMap, str],
        *,
        sensor: str = "auto",
        cost: str = "symmetric",
        grid_m: float = 0.5,
        yaw_step_deg: float = 0.5,
        clearance_m: Optional[float] = None,
        voxel_m: Optional[float] = None,
        max_range_m: Optional[float] = None,
        min_range_m: Optional[float] = None,
        min_z_m: Optional[float] = None,
        max_z_m: Optional[float] = None,
        ground_cell_m: Optional[float] = None,
        column_radius_m: Optional[float] = None,
        max_flatness: Optional[float] = None,
        min_columns: Optional[int] = None,
        max_see_through: Optional[float] = None,
        min_cell_count: Optional[int] = None,
        min_segment_m: Optional[float] = None,
        level: str = "off",
        vehicle: str = "auto",
        max_raw_poses: int = 20000,
    ) -> None:
        """Prepares an OsmMap, an .osm/.osm.pbf map or a .uloc index with the CLI's options."""
    def localize(self, points: np.ndarray, *, top: int = 10, name: str = "<array>") -> Dict[str, Any]:
        """Localizes an (n, 3) float64 levelled scan: the dict ``urbansem localize --json`` prints."""
    def track(
        self,
        scans: Sequence[np.ndarray],
        odometry: np.ndarray,
        *,
        window: int = 5,
        top: int = 5,
        names: Optional[Sequence[str]] = None,
        history_m: float = 300.0,
    ) -> List[Dict[str, Any]]:
        """Localizes scans tied by (m, 3) odometry poses: the rows of ``localize track --json``."""
    def scan_segments(self, points: np.ndarray) -> Tuple[np.ndarray, Optional[Dict[str, Any]]]:
        """A scan's wall segments (k, 4) in the sensor frame and the sensor it was processed as."""
    @property
    def map(self) -> OsmMap:
        """The map the localizer was prepared on."""
    @property
    def map_path(self) -> str:
        """The map (or index) file, as the reports name it."""
    @property
    def uses_index(self) -> bool:
        """Whether the map was read from a .uloc index."""
    @property
    def cost(self) -> str:
        """The cost that ranks the candidates."""
    @property
    def edges(self) -> np.ndarray:
        """Building outline edges, (m, 4) float64 ``[ax, ay, bx, by]``."""
    @property
    def seconds(self) -> Dict[str, float]:
        """Seconds of reading and preparing the map."""

def localize_mcd_frames(folder: _Path) -> List[int]:
    """The frame numbers of an MCD sequence folder that have a scan, sorted."""

def localize_read_odometry(path: _Path, names: List[str]) -> np.ndarray:
    """An odometry file as ``localize track --odometry`` reads it: (m, 3) x, y, yaw."""

def localize_mcd_scan(folder: _Path, map: OsmMap, frame: int) -> Dict[str, Any]:
    """An MCD scan levelled as the evaluation does: ``name``, ``frame``, ``points`` (n, 3),
    ``truth`` (x, y, yaw) and ``levelling`` (3, 3)."""

# --- streets ----------------------------------------------------------------------------

def streets_estimate(
    map: Union[OsmMap, str],
    cloud: Union[str, Dict[str, np.ndarray]],
    *,
    model_path: Optional[_Path] = None,
    model_json: Optional[bytes] = None,
    cloud_frame: str = "local",
    target: Optional[str] = None,
    driving_model_path: Optional[_Path] = None,
    driving_model_json: Optional[bytes] = None,
) -> Dict[str, Any]:
    """Street offset and width per drivable segment: the GeoJSON ``urbansem streets estimate`` writes."""

def streets_transfer(
    train: List[_Path],
    test: _Path,
    *,
    scans_per_source: int = 40,
    test_scans: int = 0,
    raw_features: bool = False,
    max_train_bins: int = 3000,
    svm_c: float = 4.0,
    seed: int = 1,
) -> Dict[str, Any]:
    """The bin classifier trained on some labelled sequences, scored on another: ``urbansem streets transfer --json``."""

# --- fleet shards ------------------------------------------------------------------------

def shard_plan(
    map: _Path,
    inputs: _Path,
    out: _Path,
    *,
    results: Optional[_Path] = ...,
    batch: int = ...,
    top: int = ...,
    cost: str = ...,
    level: str = ...,
    vehicle: str = ...,
) -> Dict[str, Any]: ...
def shard_run(
    plan: _Path,
    shard: int,
    *,
    tiles: Optional[Dict[int, Tuple[bytes, bytes]]] = ...,
    threads: Optional[int] = ...,
) -> Dict[str, Any]: ...
def shard_merge(plan: _Path) -> Dict[str, Any]: ...
