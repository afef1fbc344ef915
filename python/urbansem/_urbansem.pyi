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

# --- semantic map (srtree) ----------------------------------------------------------------

# --- localization -----------------------------------------------------------------------

# --- streets ----------------------------------------------------------------------------
