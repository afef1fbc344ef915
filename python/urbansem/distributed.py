"""Fleet jobs on Ray: run a shard plan (``urbansem shard plan``) as Ray tasks and merge.

Each shard becomes one Ray task; the stages of the plan run as waves (a stage's shards read
only results of earlier stages). Every tile's index and map crop is read once and put in
Ray's object store, and the tasks of that tile receive it from there instead of reading or
rebuilding it. The Rust work releases the GIL and runs on as many threads as the task was
given CPUs. A task that raises or whose worker dies is retried (``max_retries``); a shard's
result is written atomically with a completion record, so a retried or re-run shard never
corrupts the merge, and a finished shard is not run again.

The same plan runs without Ray, shard by shard (``urbansem shard run plan.json --shard I``,
e.g. as a Slurm array or a Kubernetes indexed job), and merges with ``urbansem shard merge``.
"""

from __future__ import annotations

import json
import os
import sys
from typing import Any, Callable, Dict, List, Optional, Tuple

from . import _urbansem

__all__ = ["plan_localize", "run_plan", "run_shard", "merge"]


def plan_localize(
    map: str,
    inputs: str,
    out: str,
    *,
    results: Optional[str] = None,
    batch: int = 8,
    top: int = 5,
    cost: str = "symmetric",
    level: str = "off",
    vehicle: str = "auto",
) -> Dict[str, Any]:
    """Plans a localization job over a tiled map (``localize index --tile-m``) and writes
    the plan to ``out``; returns the plan. ``level="auto"`` levels tilted scans by their
    walls, as ``urbansem shard plan --job localize --level auto``; ``vehicle`` is
    ``localize --vehicle`` (``auto``, ``car``, ``free``)."""
    return _urbansem.shard_plan(
        str(map), str(inputs), str(out), results=results, batch=batch, top=top, cost=cost,
        level=level, vehicle=vehicle,
    )


def run_shard(plan: str, shard: int) -> Dict[str, Any]:
    """Runs one shard in this process (a no-op when its result is complete)."""
    return _urbansem.shard_run(str(plan), shard)


def merge(plan: str) -> Dict[str, Any]:
    """Merges every shard's result of a plan: what ``urbansem shard merge`` writes (for a
    localization plan the rows per scan, for a streets plan the GeoJSON)."""
    return _urbansem.shard_merge(str(plan))


def _tile_files(plan: Dict[str, Any]) -> Tuple[str, List[Dict[str, Any]]]:
    manifest_path = plan["map"]["path"]
    with open(manifest_path, encoding="utf-8") as f:
        manifest = json.load(f)
    return os.path.dirname(manifest_path), manifest["tiles"]


def _run_task(
    plan_path: str,
    shard: int,
    tile: Optional[int],
    tile_bytes: Optional[Tuple[bytes, bytes]],
    before: Optional[Callable[[int], None]],
) -> Dict[str, Any]:
    import ray

    if before is not None:
        before(shard)
    cpus = ray.get_runtime_context().get_assigned_resources().get("CPU", 1.0)
    tiles = {tile: tile_bytes} if tile is not None and tile_bytes is not None else None
    outcome = dict(_urbansem.shard_run(plan_path, shard, tiles=tiles, threads=max(1, int(cpus))))
    outcome["pid"] = os.getpid()
    outcome["node"] = ray.get_runtime_context().get_node_id()
    outcome["max_rss_mb"] = _max_rss_mb()
    return outcome


def _max_rss_mb() -> float:
    """Peak resident memory of this process so far, MB (0 where unknown)."""
    try:
        import resource
    except ImportError:  # not on every platform
        return 0.0
    kb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    # Linux reports KiB, macOS bytes.
    return kb / (1024.0 * 1024.0) if sys.platform == "darwin" else kb / 1024.0


def run_plan(
    plan: str,
    address: Optional[str] = None,
    *,
    cpus_per_task: float = 1.0,
    max_retries: int = 3,
    before_shard: Optional[Callable[[int], None]] = None,
    report: Optional[List[Dict[str, Any]]] = None,
) -> Dict[str, Any]:
    """Runs every shard of ``plan`` as Ray tasks, stage by stage, and returns the merge (what
    ``urbansem shard merge`` writes).

    ``address``: the Ray cluster to join (``None``: the running one, else a local one);
    ``cpus_per_task``: CPUs each task reserves and uses; ``max_retries``: how often a task
    that raised or lost its worker is tried again; ``before_shard``: called with the shard id
    at the start of each task (a hook for tests and instrumentation); ``report``: a list that
    receives one dict per shard, as ``urbansem shard run --json`` prints it plus the worker's
    ``pid``, ``node`` and peak resident memory so far (``max_rss_mb``).
    """
    import ray

    if not ray.is_initialized():
        ray.init(address=address)
    plan_path = os.path.abspath(str(plan))
    with open(plan_path, encoding="utf-8") as f:
        p = json.load(f)
    # Localization tiles go through the object store; the streets and map jobs' shards read
    # their (checksummed) inputs themselves.
    base, tiles = _tile_files(p) if p["job"] == "localize" else ("", [])
    refs: Dict[int, Any] = {}

    def tile_ref(k: int) -> Any:
        if k not in refs:
            t = tiles[k]
            with open(os.path.join(base, t["index"]["path"]), "rb") as f:
                index = f.read()
            with open(os.path.join(base, t["crop"]["path"]), "rb") as f:
                crop = f.read()
            refs[k] = ray.put((index, crop))
        return refs[k]

    task = ray.remote(_run_task).options(
        num_cpus=cpus_per_task, max_retries=max_retries, retry_exceptions=True
    )
    for stage in p["stages"]:
        pending = []
        for sid in stage["shards"]:
            tile = p["shards"][sid].get("tile") if tiles else None
            data = tile_ref(tile) if tile is not None else None
            pending.append(task.remote(plan_path, sid, tile, data, before_shard))
        outcomes = ray.get(pending)
        if report is not None:
            report.extend(outcomes)
    return merge(plan_path)
