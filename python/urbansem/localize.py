"""Global localization of a gravity-levelled 3-D scan on OpenStreetMap building outlines.

The map is prepared once (distance-transform tensor, bound pyramid, feasible poses) and reused
by every call; results equal ``urbansem localize --json`` on the same scan::

    >>> import urbansem
    >>> loc = urbansem.Localizer("kth_campus_stockholm.osm")       # or an OsmMap, or a .uloc
    >>> scan = urbansem.localize.load_mcd_scan("mcd_kth_day_06", loc.map, 11)
    >>> r = loc.localize(scan.points)
    >>> r.best.x, r.best.y, r.best.yaw, r.sensor.profile
"""

from __future__ import annotations

import os
from dataclasses import dataclass, field
from typing import Any, Dict, List, Optional, Sequence, Tuple, Union

import numpy as np

from ._urbansem import OsmMap
from ._urbansem import _Localizer
from ._urbansem import localize_mcd_frames as _mcd_frames
from ._urbansem import localize_mcd_scan as _mcd_scan
from ._urbansem import localize_read_odometry as _read_odometry

__all__ = [
    "Candidate",
    "LocalizeResult",
    "Localizer",
    "McdScan",
    "Sensor",
    "TrackRow",
    "load_mcd_scan",
    "mcd_frames",
    "read_odometry",
]

PathLike = Union[str, os.PathLike]

#: The thesis' accuracy thresholds of the chamfer methods: 4 m and 0.2 rad.
THESIS_MAX_M = 4.0
THESIS_MAX_RAD = 0.2


@dataclass(frozen=True)
class Candidate:
    """A ranked pose candidate, in the map's local frame and in WGS84."""

    #: Rank, 1 = best.
    rank: int
    #: Metres east in the map's local frame.
    x: float
    #: Metres north in the map's local frame.
    y: float
    #: Latitude, degrees.
    lat: float
    #: Longitude, degrees.
    lon: float
    #: Heading from true east, radians in [0, 2π).
    yaw: float
    #: Heading from grid east of the map's local frame, radians.
    yaw_grid: float
    #: d_DCM of the search, metres.
    dcm: float
    #: Forward cost, metres.
    forward: float
    #: Reverse cost, metres.
    reverse: float
    #: Symmetric cost, metres.
    symmetric: float
    #: Whether the pose was refined.
    refined: bool
    #: Margin to the best distinct other candidate, [0, 1].
    confidence: float
    #: The value of the cost that ranks the candidates (one of the four above), metres.
    cost: float

    @staticmethod
    def from_dict(d: Dict[str, Any], cost: str) -> "Candidate":
        """A candidate from a dict of the CLI's JSON, ranked by the cost named ``cost``."""
        return Candidate(cost=float(d[cost]), **d)

    def to_dict(self) -> Dict[str, Any]:
        """The candidate as the CLI's JSON lists it (without ``cost``)."""
        d = {k: getattr(self, k) for k in self.__dataclass_fields__ if k != "cost"}
        return d


@dataclass(frozen=True)
class Sensor:
    """The sensor a scan was processed as: profile, whether detected, geometry."""

    #: Profile name (``terrestrial``, ``hdl64``, ``vlp16``, ``os1-64``, ``os1-128``).
    profile: str
    #: Whether the profile and geometry were estimated from the scan (``sensor="auto"``).
    detected: bool
    #: Height of the sensor above the ground, metres.
    mount_height_m: float
    #: Lowest and highest beam elevation, degrees.
    vfov_deg: Tuple[float, float]
    #: Number of beams.
    beams: int

    @staticmethod
    def from_dict(d: Optional[Dict[str, Any]]) -> Optional["Sensor"]:
        """The sensor of a report's ``sensor`` entry (``None`` stays ``None``)."""
        if d is None:
            return None
        return Sensor(
            profile=d["profile"],
            detected=d["detected"],
            mount_height_m=d["mount_height_m"],
            vfov_deg=(d["vfov_deg"][0], d["vfov_deg"][1]),
            beams=d["beams"],
        )


@dataclass(frozen=True)
class LocalizeResult:
    """One scan localized: the best candidates, the sensor, counts and seconds."""

    #: The best candidates, best first.
    candidates: List[Candidate]
    #: The sensor the scan was processed as (``None`` under manual options).
    sensor: Optional[Sensor]
    #: Wall segments extracted from the scan.
    segments: int
    #: Seconds per stage (map load and preparation included).
    seconds: Dict[str, float]
    #: The cost that ranks the candidates (``dcm``, ``forward``, ``reverse``, ``symmetric``).
    cost: str
    #: Confidence of the top candidate, [0, 1].
    confidence: float
    #: Number of candidates (all, not only those listed).
    candidate_count: int
    #: Why the scan could not be localized, or why its best candidate is not accepted.
    message: Optional[str]
    #: Whether the best candidate passes the acceptance gate (``max_accept_cost_m``); the
    #: candidates and their confidence are listed either way.
    accepted: bool
    #: The dict ``urbansem localize --json`` prints.
    report: Dict[str, Any] = field(repr=False, compare=False)

    @property
    def best(self) -> Optional[Candidate]:
        """The top candidate, or ``None`` when nothing was found."""
        return self.candidates[0] if self.candidates else None

    @staticmethod
    def from_dict(d: Dict[str, Any]) -> "LocalizeResult":
        """The result of a report dict (``urbansem localize --json``)."""
        return LocalizeResult(
            candidates=[Candidate.from_dict(c, d["cost"]) for c in d["candidates"]],
            sensor=Sensor.from_dict(d["sensor"]),
            segments=d["segments"],
            seconds=d["seconds"],
            cost=d["cost"],
            confidence=d["confidence"],
            candidate_count=d["candidate_count"],
            message=d["message"],
            accepted=d["accepted"],
            report=d,
        )


@dataclass(frozen=True)
class TrackRow:
    """One scan of a track: its best pose (``None`` when nothing was found) and candidates."""

    #: The scan's name.
    scan: str
    #: Latitude of the best candidate, degrees.
    lat: Optional[float]
    #: Longitude of the best candidate, degrees.
    lon: Optional[float]
    #: Heading of the best candidate from true east, radians.
    yaw: Optional[float]
    #: Metres east of the best candidate in the map frame.
    x: Optional[float]
    #: Metres north of the best candidate in the map frame.
    y: Optional[float]
    #: Confidence of the best candidate.
    confidence: float
    #: The best candidates, ranked along the track.
    candidates: List[Candidate]
    #: Wall segments extracted from the scan.
    segments: int
    #: The sensor the scan was processed as.
    sensor: Optional[Sensor]
    #: Why the scan could not be localized, if so.
    message: Optional[str]
    #: The run of scans the pose graph refined with this one (``first_scan``, ``scans``,
    #: ``length_m``) and the odometry drift it estimated over it (``drift``:
    #: ``scale_error``, ``heading_bias_deg_per_100m`` and their ``_sd``); ``None`` outside a run.
    odometry_run: Optional[Dict[str, Any]]
    #: The row as ``urbansem localize track --json`` prints it.
    report: Dict[str, Any] = field(repr=False, compare=False)

    @staticmethod
    def from_dict(d: Dict[str, Any], cost: str) -> "TrackRow":
        """A row of ``localize track --json``, its candidates ranked by ``cost``."""
        return TrackRow(
            scan=d["scan"],
            lat=d["lat"],
            lon=d["lon"],
            yaw=d["yaw"],
            x=d["x"],
            y=d["y"],
            confidence=d["confidence"],
            candidates=[Candidate.from_dict(c, cost) for c in d["candidates"]],
            segments=d["segments"],
            sensor=Sensor.from_dict(d["sensor"]),
            message=d["message"],
            odometry_run=d.get("odometry_run"),
            report=d,
        )


@dataclass(frozen=True)
class McdScan:
    """A real MCD scan levelled into the sensor frame, with its true pose."""

    #: Frame name (10 digits, as the scan file).
    name: str
    #: Frame number.
    frame: int
    #: Levelled points, (n, 3) float64 (x forward, z up, origin at the sensor).
    points: np.ndarray = field(repr=False)
    #: True pose ``(x, y, yaw)`` in the map's local frame (yaw from grid east, radians).
    truth: Tuple[float, float, float]
    #: Rotation (3, 3) from the raw sensor frame into the levelled one.
    levelling: np.ndarray = field(repr=False)


def _json(v: Any) -> Any:
    """A pythonized report as its JSON reads back: tuples (Rust arrays) become lists."""
    if isinstance(v, dict):
        return {k: _json(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_json(x) for x in v]
    return v


def _points(points: Any, what: str = "points") -> np.ndarray:
    """A scan as a C-contiguous (n, 3) float64 array (a clear ValueError otherwise)."""
    a = np.asarray(points, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{what} must have shape (n, 3); got {a.shape}")
    return np.ascontiguousarray(a)


def _odometry(odometry: Any, relative: bool = False) -> np.ndarray:
    """Odometry as (m, 3) ``x, y, yaw`` poses: from such rows or from (m, 4, 4) / (m, 3, 3)
    matrices; ``relative`` steps (pose i+1 in the frame of pose i) are chained from the origin."""
    a = np.asarray(odometry, dtype=np.float64)
    if a.ndim == 3 and a.shape[1:] in ((4, 4), (3, 3)):
        t = a.shape[1] - 1
        a = np.stack([a[:, 0, t], a[:, 1, t], np.arctan2(a[:, 1, 0], a[:, 0, 0])], axis=1)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(
            f"odometry must have shape (m, 3) (x, y, yaw per scan) or (m, 4, 4); got {a.shape}"
        )
    if relative:
        poses = [(0.0, 0.0, 0.0)]
        for dx, dy, dyaw in a:
            x, y, yaw = poses[-1]
            c, s = np.cos(yaw), np.sin(yaw)
            poses.append((x + c * dx - s * dy, y + s * dx + c * dy, yaw + dyaw))
        a = np.array(poses)
    return np.ascontiguousarray(a)


class Localizer:
    """A map prepared once for global localization of gravity-levelled scans.

    ``map`` is an :class:`urbansem.OsmMap`, the path of an ``.osm``/``.osm.pbf`` map or of a
    ``.uloc`` index (``urbansem localize index``). The options are the CLI's: ``sensor``
    (``auto``, ``terrestrial``, ``hdl64``, ``vlp16``, ``os1-64``, ``os1-128``), ``cost`` (the
    ranking cost), ``grid_m``, ``yaw_step_deg``, the extraction knobs (``None``: the sensor
    profile's value), ``level``, ``vehicle`` (``auto``, ``car``: poses head along a street
    near them, ``free``) and ``max_raw_poses`` (the cheapest poses the search keeps; 0: every
    pose within the keep factor).
    """

    def __init__(
        self,
        map: Union[OsmMap, PathLike],
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
        """Prepares the map (the expensive part, done once)."""
        if not isinstance(map, OsmMap):
            map = os.fspath(map)
        self._native = _Localizer(
            map,
            sensor=sensor,
            cost=cost,
            grid_m=grid_m,
            yaw_step_deg=yaw_step_deg,
            clearance_m=clearance_m,
            voxel_m=voxel_m,
            max_range_m=max_range_m,
            min_range_m=min_range_m,
            min_z_m=min_z_m,
            max_z_m=max_z_m,
            ground_cell_m=ground_cell_m,
            column_radius_m=column_radius_m,
            max_flatness=max_flatness,
            min_columns=min_columns,
            max_see_through=max_see_through,
            min_cell_count=min_cell_count,
            min_segment_m=min_segment_m,
            level=level,
            vehicle=vehicle,
            max_raw_poses=max_raw_poses,
        )

    def localize(self, points: Any, *, top: int = 10, name: str = "<array>") -> LocalizeResult:
        """Localizes one gravity-levelled scan, (n, 3) points in the sensor frame; ``top``
        candidates are listed, ``name`` names the scan in the report."""
        return LocalizeResult.from_dict(_json(self._native.localize(_points(points), top=top, name=name)))

    def track(
        self,
        scans: Sequence[Any],
        odometry: Any,
        *,
        window: int = 5,
        top: int = 5,
        names: Optional[Sequence[str]] = None,
        relative: bool = False,
        history_m: float = 300.0,
        causal: bool = False,
        pose_graph: bool = True,
    ) -> List[TrackRow]:
        """Localizes every scan with the windows of ``window`` scans before and after it, tied
        by odometry: one pose per scan in any odometry frame, as (m, 3) ``x, y, yaw`` rows (the
        lines of ``localize track --odometry``) or (m, 4, 4) matrices, or with ``relative``
        the m − 1 steps between consecutive scans (each in the previous scan's frame); one
        row per scan, as ``urbansem localize track --json`` lists them. ``history_m``: the
        odometry distance before the window through which a chain's consistency still counts
        (``localize track --history-m``). ``causal``: rank each scan by the scans before it
        only, as a robot driving would (``localize track --causal``). ``pose_graph``: refine
        the smoothed answers together with the odometry, whose scale error and heading bias
        each run of linked answers estimates (``False``: ``--no-pose-graph``)."""
        arrays = [_points(s, f"scans[{i}]") for i, s in enumerate(scans)]
        rows = self._native.track(
            arrays,
            _odometry(odometry, relative),
            window=window,
            top=top,
            names=list(names) if names is not None else None,
            history_m=history_m,
            causal=causal,
            pose_graph=pose_graph,
        )
        return [TrackRow.from_dict(_json(r), self.cost) for r in rows]

    def scan_segments(self, points: Any) -> Tuple[np.ndarray, Optional[Sensor]]:
        """The wall segments of a scan in the sensor frame, (k, 4) ``[ax, ay, bx, by]``, and
        the sensor it was processed as."""
        segs, sensor = self._native.scan_segments(_points(points))
        return segs, Sensor.from_dict(sensor)

    @property
    def map(self) -> OsmMap:
        """The map the localizer was prepared on."""
        return self._native.map

    @property
    def map_path(self) -> str:
        """The map (or index) file, as the reports name it."""
        return self._native.map_path

    @property
    def cost(self) -> str:
        """The cost that ranks the candidates."""
        return self._native.cost

    @property
    def edges(self) -> np.ndarray:
        """The map's building outline edges, (m, 4) ``[ax, ay, bx, by]`` metres."""
        return self._native.edges

    @property
    def seconds(self) -> Dict[str, float]:
        """Seconds of reading and preparing the map."""
        return self._native.seconds

    def __repr__(self) -> str:
        """The map and the preparation, in one line."""
        return repr(self._native)


def read_odometry(path: PathLike, names: Sequence[str]) -> np.ndarray:
    """The odometry file of ``localize track --odometry`` for the scans ``names`` (in order):
    an (m, 3) array of x, y (metres) and yaw (radians), to pass to ``Localizer.track``.

    Lines are ``x y yaw``, ``scan x y yaw`` (the name must match), TUM ``timestamp tx ty tz
    qx qy qz qw`` or a KITTI 3 × 4 pose (12 numbers); the 3-D layouts are the sensor's poses
    in a frame whose z axis points up (as LiDAR odometry writes them). Raises
    ``LocalizeError`` naming the file and line of a malformed one.
    """
    return _read_odometry(os.fspath(path), [str(n) for n in names])


def mcd_frames(folder: PathLike) -> List[int]:
    """The frame numbers of an MCD sequence folder (``lidar_bin/``, ``pose_inW.csv``)."""
    return _mcd_frames(os.fspath(folder))


def load_mcd_scan(folder: PathLike, map: OsmMap, frame: Optional[int] = None, *, index: int = 0) -> McdScan:
    """Loads an MCD scan levelled into the sensor frame with its true pose in ``map``'s frame,
    as ``urbansem localize eval`` does: frame number ``frame``, or the ``index``-th frame."""
    folder = os.fspath(folder)
    if frame is None:
        frames = _mcd_frames(folder)
        if not 0 <= index < len(frames):
            raise ValueError(f"index {index} is out of range: {folder} has {len(frames)} scans")
        frame = frames[index]
    d = _mcd_scan(folder, map, int(frame))
    return McdScan(
        name=d["name"],
        frame=d["frame"],
        points=d["points"],
        truth=tuple(d["truth"]),
        levelling=d["levelling"],
    )
