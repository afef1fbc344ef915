"""urbansem: semantic maps for robots in cities.

A thin Python layer over the urbansem Rust libraries: point clouds and ROS 2 bags as NumPy
arrays, OpenStreetMap maps, the semantic R-tree map, global localization on building
outlines, street geometry, Markov logic and pseudo-Boolean optimization, and fleet jobs as
shards on Ray (:mod:`urbansem.distributed`). Long calls release
the GIL; errors are :class:`UrbansemError` subclasses carrying the Rust message.
"""

from . import distributed, localize, mln, pbo, streets
from ._urbansem import (
    CloudError,
    FleetError,
    LocalizeError,
    MapError,
    MlnError,
    OsmError,
    OsmMap,
    PboError,
    SemanticMap,
    StreetsError,
    UrbansemError,
    __version__,
    bag_poses,
    bag_topics,
    read_cloud,
    write_cloud,
)
from .localize import Candidate, LocalizeResult, Localizer, McdScan, Sensor, TrackRow, read_odometry

__all__ = [
    "Candidate",
    "CloudError",
    "FleetError",
    "LocalizeError",
    "LocalizeResult",
    "Localizer",
    "MapError",
    "McdScan",
    "MlnError",
    "OsmError",
    "OsmMap",
    "PboError",
    "SemanticMap",
    "Sensor",
    "StreetsError",
    "TrackRow",
    "UrbansemError",
    "__version__",
    "bag_poses",
    "bag_topics",
    "distributed",
    "localize",
    "mln",
    "pbo",
    "read_cloud",
    "read_odometry",
    "streets",
    "write_cloud",
]
