"""Street geometry: offset and width of every drivable OSM street segment estimated from a
point cloud with a trained model (thesis ch. 4), as the GeoJSON ``urbansem streets estimate``
writes::

    >>> from urbansem import streets
    >>> fc = streets.estimate("map.osm", "cloud.ply", "model.json")
    >>> fc["features"][0]["properties"]["width"]
"""

from __future__ import annotations

import json
import os
from typing import Any, Dict, Mapping, Optional, Sequence, Union

import numpy as np

from ._urbansem import OsmMap
from ._urbansem import streets_estimate as _estimate
from ._urbansem import streets_transfer as _transfer

__all__ = ["estimate", "transfer"]

PathLike = Union[str, os.PathLike]

_COLUMNS = {
    "xyz": np.float64,
    "intensity": np.float32,
    "rgb": np.uint8,
    "label": np.uint8,
    "raw_label": np.uint32,
    "object": np.uint32,
}


def _cloud(cloud: Union[PathLike, Mapping[str, Any]]) -> Union[str, Dict[str, np.ndarray]]:
    """A cloud path as a string, or a cloud dict with each column in its dtype."""
    if isinstance(cloud, Mapping):
        if "xyz" not in cloud:
            raise ValueError('the cloud dict has no "xyz" array (see urbansem.read_cloud)')
        return {
            k: np.ascontiguousarray(np.asarray(v, dtype=_COLUMNS[k]))
            for k, v in cloud.items()
            if k in _COLUMNS and v is not None
        }
    return os.fspath(cloud)


def _model_args(model: Optional[Union[PathLike, Mapping[str, Any], bytes]], prefix: str) -> Dict[str, Any]:
    """The keyword arguments that pass ``model`` (a path, its parsed dict or its bytes)."""
    if model is None:
        return {}
    if isinstance(model, Mapping):
        return {f"{prefix}_json": json.dumps(model).encode()}
    if isinstance(model, (bytes, bytearray)):
        return {f"{prefix}_json": bytes(model)}
    return {f"{prefix}_path": os.fspath(model)}


def estimate(
    map: Union[OsmMap, PathLike],
    cloud: Union[PathLike, Mapping[str, Any]],
    model: Optional[Union[PathLike, Mapping[str, Any], bytes]] = None,
    *,
    cloud_frame: str = "local",
    target: Optional[str] = None,
    driving_model: Optional[Union[PathLike, Mapping[str, Any], bytes]] = None,
) -> Dict[str, Any]:
    """Estimates offset and width per drivable street segment of ``map`` from ``cloud`` (a
    path, or a dict of arrays as :func:`urbansem.read_cloud` returns) with ``model`` (the JSON
    of ``urbansem streets train``: a path, its parsed dict or its bytes; ``None``: the shipped
    model of ``target``, trained on simulated scans, as ``urbansem streets estimate`` without
    ``--model``).

    ``target`` is ``"driving_area"`` (the default without a model) or ``"with_sidewalk"``;
    with a model it must be the model's. A with-sidewalk model with sidewalk margins centres
    each segment's prior on the driving area estimated first by ``driving_model`` (same forms;
    ``None``: the shipped driving-area model), as ``--driving-model`` does.

    ``cloud_frame`` is the cloud's frame as ``--cloud-frame`` takes it (``local``,
    ``utm:32N``, ``enu:LAT,LON``). Returns the RFC 7946 FeatureCollection (a dict) that
    ``urbansem streets estimate`` writes: one Polygon per segment with ``segment``,
    ``osm_way``, ``highway``, ``width``, ``offset`` and ``bins``.
    """
    if not isinstance(map, OsmMap):
        map = os.fspath(map)
    return _estimate(
        map,
        _cloud(cloud),
        cloud_frame=cloud_frame,
        target=target,
        **_model_args(model, "model"),
        **_model_args(driving_model, "driving_model"),
    )


def transfer(
    train: Union[PathLike, Sequence[PathLike]],
    test: PathLike,
    *,
    scans_per_source: int = 40,
    test_scans: int = 0,
    raw_features: bool = False,
    max_train_bins: int = 3000,
    svm_c: float = 4.0,
    seed: int = 1,
) -> Dict[str, Any]:
    """Trains the street bin classifier on the labelled scans of ``train`` (one sequence
    folder or several: simulated car LiDAR from ``urbansem sim dataset --kind localization
    --sensor hdl64``, MCD, KITTI-360) and scores it on the ``test`` sequence's scans.

    Features are standardised per scan unless ``raw_features``. Returns the dict that
    ``urbansem streets transfer --json`` prints: ``train`` and ``test`` (per sequence
    ``name``, ``layout``, ``scans``, ``bins``, ``street_share``, ``sidewalk_share``),
    ``normalised``, ``driving_area`` and ``with_sidewalk`` (``precision``, ``recall``,
    ``f1``, ``train_positives``, ``test_positives``; ``None`` when the training bins hold
    one class for that target) and ``seconds``.
    """
    if isinstance(train, (str, os.PathLike)):
        train = [train]
    return _transfer(
        [os.fspath(t) for t in train],
        os.fspath(test),
        scans_per_source=scans_per_source,
        test_scans=test_scans,
        raw_features=raw_features,
        max_train_bins=max_train_bins,
        svm_c=svm_c,
        seed=seed,
    )
