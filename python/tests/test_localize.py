"""urbansem.Localizer on real MCD scans and the KTH campus map: the same answers as the CLI,
accurate top candidates, tracks, and clear errors on bad input."""

import json
import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import urbansem
from urbansem.localize import THESIS_MAX_M, THESIS_MAX_RAD, _odometry, load_mcd_scan, mcd_frames

REPO = Path(__file__).resolve().parents[2]
# Scans spread along the sequence (indices into its 30 frames).
SCANS = (0, 6, 12)


@pytest.fixture(scope="module")
def data() -> Path:
    """The shared data folder beside the repository (CI: X/main and X/shared/data)."""
    root = REPO.parent / "shared" / "data"
    if root.is_dir():
        return root
    pytest.fail(f"shared data not found beside {REPO} (expected ../shared/data)")


@pytest.fixture(scope="module")
def cli() -> Path:
    """The urbansem command line, built by `cargo build --release -p urbansem`."""
    exe = Path(os.environ.get("URBANSEM_CLI", REPO / "target" / "release" / "urbansem"))
    if not exe.is_file():
        pytest.fail(f"{exe} not found: build it with `cargo build --release -p urbansem`")
    return exe


@pytest.fixture(scope="module")
def map_path(data: Path) -> str:
    """The KTH campus OSM map."""
    return str(data / "osm" / "kth_campus_stockholm.osm")


@pytest.fixture(scope="module")
def mcd(data: Path) -> Path:
    """The MCD kth_day_06 sequence folder."""
    return data / "lidar" / "mcd_kth_day_06"


@pytest.fixture(scope="module")
def localizer(map_path: str) -> urbansem.Localizer:
    """The KTH map prepared once with the CLI's default options."""
    return urbansem.Localizer(map_path)


@pytest.fixture(scope="module")
def scans(localizer, mcd, tmp_path_factory):
    """A few levelled MCD scans, each also written as a PLY (float64) for the CLI."""
    folder = tmp_path_factory.mktemp("scans")
    out = []
    for i in SCANS:
        s = load_mcd_scan(mcd, localizer.map, index=i)
        ply = folder / f"{s.name}.ply"
        urbansem.write_cloud(ply, s.points, double=True)
        out.append((s, ply))
    return out


@pytest.fixture(scope="module")
def results(localizer, scans):
    """The Python results of the scans, named by their PLY path as the CLI names them."""
    return [localizer.localize(s.points, name=str(ply)) for s, ply in scans]


def run_json(cli: Path, *args) -> dict:
    """Runs the CLI and parses its JSON output (failing with its stderr)."""
    done = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def without_seconds(d: dict) -> dict:
    """A report without its timings (the only entry that differs between runs)."""
    return {k: v for k, v in d.items() if k != "seconds"}


def test_candidates_equal_the_cli_json(cli, map_path, scans, results):
    s, ply = scans[0]
    expected = run_json(cli, "localize", "--map", map_path, "--scan", ply, "--json")
    got = results[0]
    assert without_seconds(got.report) == without_seconds(expected)
    assert [c.to_dict() for c in got.candidates] == expected["candidates"]
    assert got.sensor is not None and got.sensor.profile == expected["sensor"]["profile"]
    assert got.segments == expected["segments"] > 0
    assert got.cost == "symmetric" and got.best.cost == got.best.symmetric


def test_max_raw_poses_equals_the_cli(cli, map_path, scans, results):
    s, ply = scans[0]
    capped = urbansem.Localizer(map_path, max_raw_poses=3).localize(s.points, name=str(ply))
    expected = run_json(
        cli, "localize", "--map", map_path, "--scan", ply, "--max-raw-poses", "3", "--json"
    )
    assert without_seconds(capped.report) == without_seconds(expected)
    assert capped.report["raw_poses"] == 3 < results[0].report["raw_poses"]


def test_level_auto_equals_the_cli_and_reports_the_tilt(cli, map_path, scans, results, tmp_path):
    s, _ = scans[0]
    # The MCD scans stand within about a degree of level; roll this one by 4 degrees.
    r = math.radians(4.0)
    roll = np.array([[1, 0, 0], [0, math.cos(r), -math.sin(r)], [0, math.sin(r), math.cos(r)]])
    tilted = s.points @ roll.T
    ply = tmp_path / f"{s.name}-rolled.ply"
    urbansem.write_cloud(ply, tilted, double=True)
    levelled = urbansem.Localizer(map_path, level="auto").localize(tilted, name=str(ply))
    expected = run_json(
        cli, "localize", "--map", map_path, "--scan", ply, "--level", "auto", "--json"
    )
    assert without_seconds(levelled.report) == without_seconds(expected)
    level = levelled.report["level"]
    assert level["up"] is not None and 3.0 < level["tilt_deg"] < 5.5, level
    assert level["applied"] is True
    assert results[0].report["level"] is None
    # Levelled again, the rolled scan is found where the scan itself is.
    assert math.hypot(levelled.best.x - results[0].best.x, levelled.best.y - results[0].best.y) < 1.0


def test_vehicle_free_equals_the_cli(cli, map_path, scans, results):
    s, ply = scans[0]
    free = urbansem.Localizer(map_path, vehicle="free").localize(s.points, name=str(ply))
    expected = run_json(cli, "localize", "--map", map_path, "--scan", ply, "--vehicle", "free", "--json")
    assert without_seconds(free.report) == without_seconds(expected)
    assert free.report["filtered"]["across_streets"] == 0
    # The default (auto) takes the detected OS1-64 for a car's sensor.
    assert results[0].report["sensor"]["profile"] == "os1-64"
    with pytest.raises(ValueError, match="vehicle"):
        urbansem.Localizer(map_path, vehicle="bicycle")


def test_top_candidate_is_within_the_thesis_threshold(scans, results):
    for (s, _), r in zip(scans, results):
        assert r.best is not None, (s.name, r.message)
        assert r.accepted and r.message is None, (s.name, r.message)
        x, y, yaw = s.truth
        err_m = math.hypot(r.best.x - x, r.best.y - y)
        err_rad = abs((r.best.yaw_grid - yaw + math.pi) % (2 * math.pi) - math.pi)
        assert err_m <= THESIS_MAX_M and err_rad <= THESIS_MAX_RAD, (s.name, err_m, err_rad)
        assert r.sensor is not None and r.sensor.detected


def test_track_rows_equal_the_cli_json(cli, map_path, localizer, scans, tmp_path):
    names = [ply.name for _, ply in scans]
    odometry = np.array([s.truth for s, _ in scans])
    rows = localizer.track([s.points for s, _ in scans], odometry, window=3, names=names)
    assert len(rows) == len(scans)
    assert [r.scan for r in rows] == names
    odo_file = tmp_path / "odometry.txt"
    odo_file.write_text("".join(f"{n} {float(x)!r} {float(y)!r} {float(yaw)!r}\n" for n, (x, y, yaw) in zip(names, odometry)))
    expected = run_json(
        cli, "localize", "track", "--map", map_path, "--scans", scans[0][1].parent,
        "--odometry", odo_file, "--window", "3", "--json",
    )
    assert [r.report for r in rows] == expected["scans"]
    assert expected["history_m"] == 300.0 and expected["smoothed"] is True and expected["pose_graph"] is True
    # The same odometry as a LiDAR odometry tool writes it (TUM: time, position, quaternion).
    tum_file = tmp_path / "odometry.tum"
    tum_file.write_text("".join(
        f"{k * 0.1!r} {float(x)!r} {float(y)!r} 0.5 0 0 {math.sin(yaw / 2)!r} {math.cos(yaw / 2)!r}\n"
        for k, (x, y, yaw) in enumerate(odometry)
    ))
    tum = run_json(
        cli, "localize", "track", "--map", map_path, "--scans", scans[0][1].parent,
        "--odometry", tum_file, "--window", "3", "--json",
    )
    assert [t["scan"] for t in tum["scans"]] == names
    # Python reads the file as the CLI does.
    read = urbansem.read_odometry(tum_file, names)
    assert read.shape == (len(names), 3)
    np.testing.assert_allclose(read[:, :2], odometry[:, :2], atol=1e-9)
    np.testing.assert_allclose(np.cos(read[:, 2] - odometry[:, 2]), 1.0, atol=1e-12)
    with pytest.raises(urbansem.LocalizeError, match=f"odometry.tum:{len(names)}: .* poses for"):
        urbansem.read_odometry(tum_file, names + ["extra.ply"])
    for t, e in zip(tum["scans"], expected["scans"]):
        assert abs(t["lat"] - e["lat"]) < 1e-9 and abs(t["lon"] - e["lon"]) < 1e-9, (t, e)
        assert abs(t["yaw"] - e["yaw"]) < 1e-6, (t, e)
    for r, (s, _) in zip(rows, scans):
        assert r.x is not None and math.hypot(r.x - s.truth[0], r.y - s.truth[1]) <= THESIS_MAX_M
    # The runs the pose graph refined carry the drift it estimated; this odometry is the truth.
    runs = [r.odometry_run for r in rows if r.odometry_run is not None]
    assert runs, "no run of linked answers"
    for run in runs:
        drift = run["drift"]
        assert run["scans"] >= 2 and run["length_m"] > 0.0
        assert abs(drift["scale_error"]) < 0.02 and drift["scale_error_sd"] > 0.0
        assert abs(drift["heading_bias_deg_per_100m"]) < 2.0
    # The history reaches the library as the CLI's --history-m does; a negative one is refused.
    short = localizer.track([s.points for s, _ in scans], odometry, window=3, names=names, history_m=0.0)
    expected = run_json(
        cli, "localize", "track", "--map", map_path, "--scans", scans[0][1].parent,
        "--odometry", odo_file, "--window", "3", "--history-m", "0", "--json",
    )
    assert [r.report for r in short] == expected["scans"] and expected["history_m"] == 0.0
    # Causal ranking (the scans before each scan only) reaches the library as --causal does.
    causal = localizer.track([s.points for s, _ in scans], odometry, window=3, names=names, causal=True)
    expected = run_json(
        cli, "localize", "track", "--map", map_path, "--scans", scans[0][1].parent,
        "--odometry", odo_file, "--window", "3", "--causal", "--json",
    )
    assert [r.report for r in causal] == expected["scans"] and expected["smoothed"] is False
    # So does the pose graph's switch (--no-pose-graph).
    chains = localizer.track([s.points for s, _ in scans], odometry, window=3, names=names, pose_graph=False)
    expected = run_json(
        cli, "localize", "track", "--map", map_path, "--scans", scans[0][1].parent,
        "--odometry", odo_file, "--window", "3", "--no-pose-graph", "--json",
    )
    assert [r.report for r in chains] == expected["scans"] and expected["pose_graph"] is False
    assert all(r.odometry_run is None for r in chains)
    with pytest.raises(ValueError, match="history_m"):
        localizer.track([s.points for s, _ in scans], odometry, window=3, history_m=-1.0)
    # 4 × 4 odometry matrices are read as the same (x, y, yaw) rows.
    mats = np.tile(np.eye(4), (len(scans), 1, 1))
    for m, (x, y, yaw) in zip(mats, odometry):
        m[:2, :2] = [[math.cos(yaw), -math.sin(yaw)], [math.sin(yaw), math.cos(yaw)]]
        m[:2, 3] = [x, y]
    assert np.allclose(_odometry(mats), odometry, atol=1e-12)
    # Relative steps chain into poses that differ from the absolute ones by one rigid motion.
    steps = []
    for (x0, y0, a0), (x1, y1, a1) in zip(odometry[:-1], odometry[1:]):
        c, s = math.cos(a0), math.sin(a0)
        steps.append((c * (x1 - x0) + s * (y1 - y0), -s * (x1 - x0) + c * (y1 - y0), a1 - a0))
    chained = _odometry(steps, relative=True)
    assert chained.shape == odometry.shape and np.allclose(chained[0], 0)
    c, s = math.cos(odometry[0, 2]), math.sin(odometry[0, 2])
    moved = chained[:, :2] @ np.array([[c, s], [-s, c]]) + odometry[0, :2]
    assert np.allclose(moved, odometry[:, :2], atol=1e-9)
    assert np.allclose(chained[:, 2] + odometry[0, 2], odometry[:, 2], atol=1e-12)


def test_index_and_osm_map_give_the_same_candidates(cli, map_path, scans, results, tmp_path):
    index = tmp_path / "kth.uloc"
    run_json(cli, "localize", "index", "--map", map_path, "--out", index, "--json")
    from_index = urbansem.Localizer(index)
    s, ply = scans[0]
    r = from_index.localize(s.points, name=str(ply))
    assert [c.to_dict() for c in r.candidates] == [c.to_dict() for c in results[0].candidates]
    from_map = urbansem.Localizer(urbansem.OsmMap.load(map_path))
    assert from_map.edges.shape == from_index.edges.shape and from_map.edges.shape[1] == 4


def test_levelling_matrix_levels_the_raw_scan(mcd, scans):
    s, _ = scans[0]
    assert s.frame == mcd_frames(mcd)[SCANS[0]]
    raw = np.fromfile(mcd / "lidar_bin" / f"{s.name}.bin", dtype=np.float32).reshape(-1, 4)[:, :3]
    assert np.allclose(raw.astype(np.float64) @ s.levelling.T, s.points, atol=1e-6)


def test_bad_input_is_a_clear_error(localizer, scans, tmp_path):
    pts = scans[0][0].points
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        localizer.localize(pts[:, :2])
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        localizer.localize(pts[:, 0])
    with pytest.raises(ValueError, match="empty"):
        localizer.localize(np.zeros((0, 3)))
    bad = pts[:1000].copy()
    bad[7, 1] = np.nan
    with pytest.raises(urbansem.LocalizeError, match="scan point 7 is not finite"):
        localizer.localize(bad)
    with pytest.raises(urbansem.LocalizeError, match="no-such-map.osm"):
        urbansem.Localizer(tmp_path / "no-such-map.osm")
    with pytest.raises(ValueError, match="unknown sensor"):
        urbansem.Localizer(tmp_path / "no-such-map.osm", sensor="lidar9000")
    with pytest.raises(ValueError, match="use auto or off"):
        urbansem.Localizer(tmp_path / "no-such-map.osm", level="tilted")
    with pytest.raises(ValueError, match="odometry has 1 poses for 2 scans"):
        localizer.track([pts, pts], np.zeros((1, 3)))
    with pytest.raises(ValueError, match="odometry must have shape"):
        localizer.track([pts], np.zeros((1, 2)))
    with pytest.raises(urbansem.LocalizeError, match="pose_inW.csv"):
        load_mcd_scan(tmp_path, localizer.map, 11)
