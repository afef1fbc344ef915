"""urbansem.streets.estimate on a small simulated street dataset: the same GeoJSON as
`urbansem streets estimate`, valid RFC 7946, clear errors on bad input."""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import urbansem
from urbansem import streets

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def cli() -> Path:
    """The urbansem command line, built by `cargo build --release -p urbansem`."""
    exe = Path(os.environ.get("URBANSEM_CLI", REPO / "target" / "release" / "urbansem"))
    if not exe.is_file():
        pytest.fail(f"{exe} not found: build it with `cargo build --release -p urbansem`")
    return exe


def run(cli: Path, *args) -> None:
    """Runs the CLI (failing with its stderr)."""
    done = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr


@pytest.fixture(scope="module")
def small(cli, tmp_path_factory):
    """A two-scan simulated street dataset, a model trained on it, and the CLI's GeoJSON."""
    d = tmp_path_factory.mktemp("streets")
    run(cli, "sim", "dataset", "--kind", "streets", "--scans", "2", "--route-m", "300", "--out", d)
    run(cli, "streets", "train", "--dataset", d, "--out", d / "model.json", "--max-train-bins", "300")
    out = d / "cli.geojson"
    run(
        cli, "streets", "estimate", "--map", d / "city.osm", "--cloud", d / "cloud.ply",
        "--model", d / "model.json", "--out", out,
    )
    return d, json.loads(out.read_text())


def test_estimate_from_paths_equals_the_cli_geojson(small):
    d, expected = small
    fc = streets.estimate(d / "city.osm", d / "cloud.ply", d / "model.json")
    assert fc == expected
    assert len(fc["features"]) > 0


def test_estimate_from_arrays_equals_the_cli_geojson(small):
    d, expected = small
    cloud = urbansem.read_cloud(d / "cloud.ply")
    model = json.loads((d / "model.json").read_text())
    fc = streets.estimate(urbansem.OsmMap.load(d / "city.osm"), cloud, model)
    assert fc == expected


def ring_area(ring) -> float:
    """Shoelace area of a closed [lon, lat] ring (positive: counter-clockwise)."""
    a = np.asarray(ring)
    return 0.5 * float(np.sum(a[:-1, 0] * a[1:, 1] - a[1:, 0] * a[:-1, 1]))


def test_geojson_passes_rfc_7946_checks(small):
    _, fc = small
    assert fc["type"] == "FeatureCollection"
    for f in fc["features"]:
        assert f["type"] == "Feature"
        g = f["geometry"]
        assert g["type"] == "Polygon" and len(g["coordinates"]) >= 1
        outer = g["coordinates"][0]
        assert len(outer) >= 4 and outer[0] == outer[-1]
        for lon, lat in outer:
            assert -180 <= lon <= 180 and -90 <= lat <= 90
        assert ring_area(outer) > 0, "exterior rings are counter-clockwise (RFC 7946 §3.1.6)"
        p = f["properties"]
        assert {"segment", "osm_way", "highway", "width", "offset", "bins"} <= p.keys()
        assert p["width"] > 0
    json.dumps(fc, allow_nan=False)


def test_without_a_model_the_shipped_default_model_is_used(small):
    d, _ = small
    shipped = Path(__file__).resolve().parents[2] / "crates" / "streets" / "models" / "default.json"
    fc = streets.estimate(d / "city.osm", d / "cloud.ply")
    assert fc["type"] == "FeatureCollection" and fc["features"]
    assert fc == streets.estimate(d / "city.osm", d / "cloud.ply", shipped)


def test_with_sidewalk_equals_the_cli_and_centres_on_the_driving_area(cli, small):
    """A with-sidewalk model with its sidewalk margins: the CLI's GeoJSON, with the shipped
    driving-area model or a given one; the wrong kind of model is a ValueError."""
    d, _ = small
    run(
        cli, "streets", "train", "--dataset", d, "--target", "with-sidewalk",
        "--out", d / "ws.json", "--max-train-bins", "300",
    )
    for driving in [None, d / "model.json"]:
        out = d / "ws.geojson"
        extra = [] if driving is None else ["--driving-model", driving]
        run(
            cli, "streets", "estimate", "--map", d / "city.osm", "--cloud", d / "cloud.ply",
            "--model", d / "ws.json", "--out", out, *extra,
        )
        fc = streets.estimate(d / "city.osm", d / "cloud.ply", d / "ws.json", driving_model=driving)
        assert fc == json.loads(out.read_text())
        assert fc["features"][0]["properties"]["target"] == "with_sidewalk"
    shipped = streets.estimate(d / "city.osm", d / "cloud.ply", target="with_sidewalk")
    assert shipped["features"][0]["properties"]["target"] == "with_sidewalk"
    with pytest.raises(ValueError, match="driving-area model"):
        streets.estimate(d / "city.osm", d / "cloud.ply", d / "ws.json", driving_model=d / "ws.json")
    with pytest.raises(ValueError, match="with-sidewalk model"):
        streets.estimate(d / "city.osm", d / "cloud.ply", d / "model.json", driving_model=d / "model.json")
    with pytest.raises(ValueError, match="target"):
        streets.estimate(d / "city.osm", d / "cloud.ply", d / "model.json", target="with_sidewalk")
    with pytest.raises(ValueError, match="expected"):
        streets.estimate(d / "city.osm", d / "cloud.ply", target="sidewalk")


def test_bad_input_is_a_clear_error(small, tmp_path):
    d, _ = small
    with pytest.raises(urbansem.CloudError, match="no-such-cloud.ply"):
        streets.estimate(d / "city.osm", tmp_path / "no-such-cloud.ply", d / "model.json")
    with pytest.raises(urbansem.OsmError, match="no-such-map.osm"):
        streets.estimate(tmp_path / "no-such-map.osm", d / "cloud.ply", d / "model.json")
    with pytest.raises(ValueError, match="xyz"):
        streets.estimate(d / "city.osm", {"label": np.zeros(3)}, d / "model.json")
    bad = tmp_path / "model.json"
    bad.write_text('{"target": "driving_area"}')
    with pytest.raises(urbansem.StreetsError, match="model.json"):
        streets.estimate(d / "city.osm", d / "cloud.ply", bad)
    with pytest.raises(urbansem.StreetsError, match="does not overlap"):
        far = {"xyz": np.full((100, 3), 1e6)}
        streets.estimate(d / "city.osm", far, d / "model.json")


KITTI360 = REPO.parent / "shared" / "data" / "lidar" / "kitti360_2013_05_28_drive_0009"


def test_transfer_equals_the_cli_report(cli, tmp_path):
    """streets.transfer gives the report `urbansem streets transfer --json` prints."""
    sim = tmp_path / "sim"
    run(cli, "sim", "dataset", "--kind", "localization", "--sensor", "hdl64", "--scans", "6",
        "--seed", "1", "--out", sim)
    args = ["--scans-per-source", "4", "--test-scans", "3", "--max-train-bins", "800"]
    done = subprocess.run(
        [str(cli), "streets", "transfer", "--train", str(sim), "--test", str(KITTI360), *args, "--json"],
        capture_output=True, text=True,
    )
    assert done.returncode == 0, done.stderr
    expected = json.loads(done.stdout)
    got = streets.transfer(sim, KITTI360, scans_per_source=4, test_scans=3, max_train_bins=800)
    for r in (expected, got):
        del r["seconds"]
    assert got == expected
    assert got["normalised"] is True and got["test"]["layout"] == "kitti360"
    assert got["driving_area"]["test_positives"] > 1000
    raw = streets.transfer([sim], KITTI360, scans_per_source=4, test_scans=3,
                           max_train_bins=800, raw_features=True)
    assert raw["normalised"] is False


def test_transfer_errors_name_the_folder(tmp_path):
    with pytest.raises(urbansem.StreetsError, match="no/such/folder"):
        streets.transfer("no/such/folder", KITTI360)
    unlabelled = REPO.parent / "shared" / "data" / "lidar" / "kitti_raw_2011_09_26_drive_0005_frame0"
    with pytest.raises(urbansem.StreetsError, match="no per-point labels"):
        streets.transfer(KITTI360, unlabelled)
