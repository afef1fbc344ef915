"""Issue 19: a localization plan run as Ray tasks (a local cluster of 2 CPUs) merges into
exactly what one process computes with `urbansem shard run` + `shard merge`; a task that
raises, or whose worker process dies, is retried and the merged result is still complete
and identical; a re-run is a no-op. A map-building plan through Ray gives the GeoJSON the
command line's merge writes."""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Any, Dict, List

import pytest

import urbansem
from urbansem import distributed


def ray_or_skip() -> Any:
    try:
        import ray
    except ImportError:
        if os.environ.get("URBANSEM_CLI_REQUIRED"):
            pytest.fail("ray is not installed (pip install ray)")
        pytest.skip("ray is not installed")
    return ray


@pytest.fixture(scope="module")
def job(tmp_path_factory: pytest.TempPathFactory, data: Path, cli: Any) -> Dict[str, Path]:
    """A tiled KTH map and three simulated scans."""
    d = tmp_path_factory.mktemp("fleet")
    kth = data / "osm" / "kth_campus_stockholm.osm"
    cli("localize", "index", "--map", kth, "--tile-m", "300", "--out", d / "tiles")
    cli("sim", "dataset", "--kind", "localization", "--map", kth, "--scans", "3", "--seed", "5",
        "--out", d / "scans")
    return {"dir": d, "manifest": d / "tiles" / "manifest.json", "scans": d / "scans"}


def plain(value: Any) -> Any:
    """As JSON holds it (tuples become lists)."""
    return json.loads(json.dumps(value))


def single_process(job: Dict[str, Path], cli: Any) -> Dict[str, Any]:
    plan = job["dir"] / "one.json"
    cli("shard", "plan", "--job", "localize", "--map", job["manifest"], "--inputs", job["scans"],
        "--out", plan, "--batch", "2")
    shards = len(json.loads(plan.read_text())["shards"])
    for i in range(shards):
        cli("shard", "run", plan, "--shard", i)
    out = job["dir"] / "one-result.json"
    cli("shard", "merge", plan, "--out", out)
    return json.loads(out.read_text())


@pytest.fixture(scope="module")
def ray_cluster() -> Any:
    ray = ray_or_skip()
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()


def test_ray_run_equals_one_process_and_survives_failing_tasks_and_workers(
    job: Dict[str, Path], cli: Any, ray_cluster: Any
) -> None:
    reference = single_process(job, cli)
    assert len(reference["scans"]) == 3
    assert sum(r["lat"] is not None for r in reference["scans"]) >= 2

    plan = job["dir"] / "ray.json"
    p = distributed.plan_localize(job["manifest"], job["scans"], plan, batch=2)
    assert [s["name"] for s in p["stages"]] == [
        "extract", "minimum-0.4m", "minimum-0.55m", "minimum-0.8m", "minimum", "poses"
    ]
    report: List[Dict[str, Any]] = []
    merged = distributed.run_plan(plan, report=report)
    assert plain(merged["scans"]) == reference["scans"]
    # One outcome per shard, from worker processes that say how much memory they used.
    assert sorted(r["shard"] for r in report) == [s["id"] for s in p["shards"]]
    assert all(r["max_rss_mb"] > 0 and r["pid"] != os.getpid() for r in report)

    # A task that raises the first time it runs shard `bad` is retried; the merge is complete
    # and identical.
    flaky = job["dir"] / "flaky.json"
    p = distributed.plan_localize(job["manifest"], job["scans"], flaky, batch=2)
    bad = p["stages"][-1]["shards"][0]
    marker = job["dir"] / "failed-once"

    def fail_once(shard: int) -> None:
        if shard == bad and not marker.exists():
            marker.write_text("x")
            raise RuntimeError(f"injected failure in shard {shard}")

    merged = distributed.run_plan(flaky, before_shard=fail_once)
    assert marker.exists()
    assert plain(merged["scans"]) == reference["scans"]

    # A worker that dies in the middle of a shard (the process exits) is replaced and the
    # shard retried; the merge is complete and identical.
    killed = job["dir"] / "killed.json"
    p = distributed.plan_localize(job["manifest"], job["scans"], killed, batch=2)
    victim = p["stages"][1]["shards"][1]
    tombstone = job["dir"] / "killed-once"

    def die_once(shard: int) -> None:
        if shard == victim and not tombstone.exists():
            tombstone.write_text("x")
            os._exit(1)

    merged = distributed.run_plan(killed, before_shard=die_once)
    assert tombstone.exists()
    assert plain(merged["scans"]) == reference["scans"]

    # Running the plan again: every shard is complete, nothing runs, the same answer.
    again = distributed.run_shard(flaky, bad)
    assert again["skipped"] is True
    assert plain(distributed.merge(flaky)["scans"]) == reference["scans"]


def test_the_level_option_is_written_into_the_plan_as_the_cli_writes_it(
    job: Dict[str, Path], cli: Any
) -> None:
    """plan_localize(level=...) writes the plan `shard plan --level` writes; a bad value is
    refused before anything is written."""
    by_cli = job["dir"] / "level-cli.json"
    cli("shard", "plan", "--job", "localize", "--map", job["manifest"], "--inputs", job["scans"],
        "--out", by_cli, "--batch", "2", "--level", "auto")
    by_py = job["dir"] / "level-py.json"
    p = distributed.plan_localize(job["manifest"], job["scans"], by_py, batch=2, level="auto",
                                  results=str(by_cli.with_suffix(".d")))
    assert p["options"]["level"] == "auto"
    assert json.loads(by_py.read_text()) == json.loads(by_cli.read_text())
    default = distributed.plan_localize(job["manifest"], job["scans"], job["dir"] / "off.json")
    assert default["options"]["level"] == "off"
    bad = job["dir"] / "bad-level.json"
    with pytest.raises(ValueError, match="sideways"):
        distributed.plan_localize(job["manifest"], job["scans"], bad, level="sideways")
    assert not bad.exists()


def test_shard_errors_are_fleet_errors(tmp_path: Path) -> None:
    not_a_plan = tmp_path / "plan.json"
    not_a_plan.write_text("[]")
    with pytest.raises(urbansem.FleetError, match="shard plan"):
        distributed.run_shard(not_a_plan, 0)
    with pytest.raises(urbansem.FleetError, match="plan.json"):
        distributed.merge(not_a_plan)


def test_a_map_plan_on_ray_gives_the_command_line_merge(
    tmp_path: Path, cli: Any, ray_cluster: Any
) -> None:
    cli("sim", "dataset", "--kind", "streets", "--scans", "3", "--out", tmp_path / "sim")
    clouds = tmp_path / "clouds"
    clouds.mkdir()
    (clouds / "cloud.ply").write_bytes((tmp_path / "sim" / "cloud.ply").read_bytes())
    plans = {}
    for name in ("one", "ray"):
        plans[name] = tmp_path / f"{name}.json"
        cli("shard", "plan", "--job", "map", "--map", tmp_path / "sim" / "city.osm",
            "--inputs", clouds, "--tile-m", "50", "--out", plans[name])
    shards = len(json.loads(plans["one"].read_text())["shards"])
    assert shards >= 2
    for i in range(shards):
        cli("shard", "run", plans["one"], "--shard", i)
    out = tmp_path / "one.geojson"
    cli("shard", "merge", plans["one"], "--out", out)
    merged = distributed.run_plan(plans["ray"])
    assert plain(merged) == json.loads(out.read_text())
    kinds = [f["properties"]["kind"] for f in merged["features"]]
    assert kinds.count("tile") == shards and kinds.count("object") > 0
