"""urbansem.SemanticMap on a real labelled KITTI-360 scan: every query against a brute-force
computation on the map's own cells, the cells against NumPy binning of the points, the
.srt round trip, and (when the CLI is built) byte equality with ``urbansem map build``,
``map query`` and ``relations infer``.

Data: ``../shared/data`` beside the repository (CI layout: repo at X/main, data at
X/shared/data). The CLI: ``target/release/urbansem`` of the repository.
"""

from __future__ import annotations

import json
import subprocess
import threading
from pathlib import Path

import numpy as np
import pytest

import urbansem
from urbansem import MapError, SemanticMap

REPO = Path(__file__).resolve().parents[2]
KITTI = "lidar/kitti360_2013_05_28_drive_0009"
FRAME = "0000002000"
RELATION_NAMES = ["On", "LeftOf", "Behind", "RightOf", "InFrontOf"]
CELL_COLUMNS = ["centre", "label", "object", "hits", "occupancy", "rgb", "counts"]


@pytest.fixture(scope="module")
def data_dir() -> Path:
    d = REPO.parent / "shared" / "data"
    if not (d / KITTI).is_dir():
        pytest.skip(f"the shared data is not at {d} (expected {d / KITTI})")
    return d


@pytest.fixture(scope="module")
def scan_paths(data_dir):
    bin_ = data_dir / KITTI / "velodyne_points" / f"{FRAME}.bin"
    labels = data_dir / KITTI / "gt_labels" / f"{FRAME}.bin"
    for p in (bin_, labels):
        assert p.is_file(), f"missing {p}"
    return bin_, labels


@pytest.fixture(scope="module")
def scan(scan_paths):
    """The scan's points (float64) and class ids 0–9 derived from its raw KITTI-360 ids (the
    map does not care what the ids mean)."""
    bin_, labels = scan_paths
    xyz = urbansem.read_cloud(bin_)["xyz"]
    raw = np.fromfile(labels, dtype="<u4")
    assert raw.shape == (len(xyz),)
    label = (raw % 10).astype(np.uint8)
    return xyz, label


@pytest.fixture(scope="module")
def cli() -> Path:
    exe = REPO / "target" / "release" / "urbansem"
    if not exe.is_file():
        pytest.skip(f"the CLI is not built ({exe} missing: cargo build --release -p urbansem)")
    return exe


def run(cli, *args) -> str:
    p = subprocess.run([str(cli), *map(str, args)], capture_output=True, text=True)
    assert p.returncode == 0, f"urbansem {' '.join(map(str, args))} failed:\n{p.stderr}"
    return p.stdout


def sort_rows(cells):
    """The cells' columns sorted by centre (x, then y, then z)."""
    c = cells["centre"]
    order = np.lexsort((c[:, 2], c[:, 1], c[:, 0]))
    return {k: v[order] for k, v in cells.items()}


def assert_cells_equal(a, b):
    assert sorted(a) == sorted(b) == sorted(CELL_COLUMNS)
    for k in CELL_COLUMNS:
        np.testing.assert_array_equal(a[k], b[k], err_msg=k)


# --- building: the cells are the points binned ------------------------------------------


def test_build_equals_numpy_binning(scan):
    xyz, label = scan
    r = 0.2
    m = SemanticMap.build(xyz, label, resolution=r)
    keys = np.floor(xyz / r).astype(np.int64)
    uniq, inverse, hits = np.unique(keys, axis=0, return_inverse=True, return_counts=True)
    inverse = inverse.reshape(-1)
    counts = np.zeros((len(uniq), 10), dtype=np.int64)
    np.add.at(counts, (inverse, label), 1)
    assert len(m) == len(uniq) > 10_000
    assert m.resolution == r
    cells = sort_rows(m.cells())
    want_centre = (uniq + 0.5) * r
    order = np.lexsort((want_centre[:, 2], want_centre[:, 1], want_centre[:, 0]))
    np.testing.assert_array_equal(cells["centre"], want_centre[order])
    np.testing.assert_array_equal(cells["hits"], hits[order])
    np.testing.assert_array_equal(cells["counts"], counts[order])
    # Without a Dirichlet model the label is the majority (lowest id on ties).
    np.testing.assert_array_equal(cells["label"], counts[order].argmax(axis=1))
    assert (cells["occupancy"] > 0.5).all()
    assert (cells["object"] == 0).all()
    assert cells["hits"].sum() == len(xyz)


def test_class_query_matches_the_label_histogram(scan_paths):
    bin_, labels = scan_paths
    m = SemanticMap.from_cloud(bin_, labels=labels, label_set="kitti360")
    cells = m.cells()
    names = SemanticMap.class_names()
    assert names[:3] == ["unlabelled", "car", "building"] and len(names) == 10
    seen = 0
    for cid, name in enumerate(names):
        by_name = m.cells_of_class(name)
        by_id = m.cells_of_class(cid)
        assert_cells_equal(by_name, by_id)
        mask = cells["label"] == cid
        np.testing.assert_array_equal(by_name["centre"], cells["centre"][mask])
        assert (by_name["label"] == cid).all()
        # The label is the histogram's majority.
        if mask.any():
            np.testing.assert_array_equal(by_name["counts"].argmax(axis=1), cid)
        seen += len(by_name["label"])
    assert seen == len(m)
    # A real scan of a street: cars, buildings, road, vegetation all present.
    for name in ["car", "street", "tree"]:
        assert len(m.cells_of_class(name)["label"]) > 100, name
    assert len(m.cells_of_class("CAR")["label"]) == len(m.cells_of_class("car")["label"])


def test_insert_in_batches_equals_one_build(scan):
    xyz, label = scan
    whole = SemanticMap.build(xyz, label, objects=False)
    m = SemanticMap(0.1)
    assert len(m) == 0
    half = len(xyz) // 2
    s1 = m.insert(xyz[:half], label[:half])
    s2 = m.insert(xyz[half:], label[half:])
    assert s1["points"] + s2["points"] == len(xyz)
    assert s1["new_cells"] + s2["new_cells"] == len(whole) == len(m)
    a, b = sort_rows(m.cells()), sort_rows(whole.cells())
    for k in CELL_COLUMNS:
        if k != "occupancy":
            np.testing.assert_array_equal(a[k], b[k], err_msg=k)
    # Occupancy is per scan (one batch is one scan, +0.85 log-odds per scan that hits the
    # cell): the cells both halves hit have had two hits.
    r = m.resolution
    k1 = {tuple(k) for k in np.floor(xyz[:half] / r).astype(np.int64)}
    k2 = {tuple(k) for k in np.floor(xyz[half:] / r).astype(np.int64)}
    both = np.array([tuple(k) in k1 and tuple(k) in k2 for k in np.floor(a["centre"] / r).astype(np.int64)])
    assert 0 < both.sum() < len(both)
    one_hit, two_hits = 1 / (1 + np.exp(-0.85)), 1 / (1 + np.exp(-1.7))
    np.testing.assert_allclose(a["occupancy"], np.where(both, two_hits, one_hit), rtol=1e-6)
    np.testing.assert_allclose(b["occupancy"], one_hit, rtol=1e-6)
    # Non-contiguous and non-float64 inputs are converted.
    m2 = SemanticMap(0.1)
    m2.insert(np.asfortranarray(xyz), label.astype(np.int64))
    assert_cells_equal(sort_rows(m2.cells()), sort_rows(whole.cells()))


# --- queries against brute force ---------------------------------------------------------


@pytest.fixture(scope="module")
def kitti_map(scan_paths):
    bin_, labels = scan_paths
    return SemanticMap.from_cloud(bin_, labels=labels, label_set="kitti360", resolution=0.15)


def test_box_query_equals_a_filter_of_the_cells(kitti_map):
    m = kitti_map
    cells = m.cells()
    c = cells["centre"]
    h = 0.5 * m.resolution
    rng = np.random.default_rng(5)
    nonempty = 0
    for _ in range(40):
        a, b = rng.uniform(-30, 30, 3), rng.uniform(-30, 30, 3)
        a[2], b[2] = rng.uniform(-3, 3, 2)
        lo, hi = np.minimum(a, b), np.maximum(a, b)
        got = m.query_box(lo, hi)
        keep = np.all((c >= lo - h) & (c <= hi + h), axis=1)
        np.testing.assert_array_equal(got["centre"], c[keep])
        np.testing.assert_array_equal(got["label"], cells["label"][keep])
        nonempty += keep.any()
    assert nonempty > 10
    # An inverted box is empty.
    assert len(m.query_box([1, 1, 1], [0, 0, 0])["label"]) == 0


def test_radius_query_equals_a_filter_of_the_cells(kitti_map):
    m = kitti_map
    c = m.cells()["centre"]
    rng = np.random.default_rng(6)
    for _ in range(30):
        p = rng.uniform(-20, 20, 3)
        p[2] = rng.uniform(-2, 1)
        radius = float(rng.uniform(0, 6))
        d = c - p
        d2 = d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1] + d[:, 2] * d[:, 2]
        got = m.query_radius(p, radius)
        np.testing.assert_array_equal(got["centre"], c[d2 <= radius * radius])


def test_knn_equals_brute_force_sorted_by_distance(kitti_map):
    m = kitti_map
    c = m.cells()["centre"]
    rng = np.random.default_rng(7)
    for _ in range(30):
        p = rng.uniform(-40, 40, 3)
        k = int(rng.integers(1, 60))
        got = m.knn(p, k)
        dist = lambda x: np.sqrt(((x - p) ** 2).sum(axis=1))  # noqa: E731
        want = np.sort(dist(c))[:k]
        np.testing.assert_allclose(dist(got["centre"]), want, rtol=0, atol=1e-12)
        assert np.all(np.diff(dist(got["centre"])) >= -1e-12)
    assert len(m.knn([0, 0, 0], 0)["label"]) == 0
    assert len(m.knn([0, 0, 0], len(m) + 5)["label"]) == len(m)


def test_queries_run_in_parallel_threads(kitti_map):
    want = kitti_map.knn([3.0, 1.0, 0.0], 500)["centre"]
    out = [None] * 4

    def work(i):
        for _ in range(5):
            out[i] = kitti_map.knn([3.0, 1.0, 0.0], 500)["centre"]

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for o in out:
        np.testing.assert_array_equal(o, want)


def test_ray_casting_frees_cells_queries_return_occupied_only(scan):
    xyz, label = scan
    m = SemanticMap.build(xyz, label, sensor_origin=(0.0, 0.0, 0.0))
    assert m.options["ray_casting"]
    assert len(m.cells(occupied_only=False)["label"]) == len(m.cells()["label"])
    # The same scan again from three sensor positions beside the first: its rays cross cells
    # only the first scan hit (one miss per scan each: −0.4 three times outweighs one +0.85).
    for shift in ([0.35, 0.2, 0.0], [0.7, 0.4, 0.0], [1.05, 0.6, 0.0]):
        stats = m.insert(xyz + shift, label, origin=shift)
        assert stats["rays"] == len(xyz) and stats["misses"] > 0
    everything = m.cells(occupied_only=False)
    occupied = m.cells()
    assert len(everything["label"]) == len(m) > len(occupied["label"])
    assert (everything["occupancy"] <= 0.5).sum() == len(m) - len(occupied["label"])
    assert (occupied["occupancy"] > 0.5).all()
    for got in (m.query_box([-10, -10, -3], [10, 10, 3]), m.knn([0, 0, 0], 200)):
        assert (got["occupancy"] > 0.5).all()
    # No ray casting: an origin would be ignored, so it is refused.
    plain = SemanticMap(0.1)
    with pytest.raises(ValueError, match="ray_casting"):
        plain.insert(xyz[:10], origin=(0, 0, 0))


# --- objects -----------------------------------------------------------------------------


def test_objects_are_the_cells_grouped_by_object_id(scan):
    xyz, label = scan
    tiles = np.floor(xyz[:, :2] / 8.0).astype(np.int64) + 100
    obj = (1 + tiles[:, 0] * 1000 + tiles[:, 1]).astype(np.uint32)
    m = SemanticMap.build(xyz, label, object=obj)
    o = m.objects()
    assert set(o) == {"id", "label", "cells", "centroid", "box_centre", "half_extents", "yaw"}
    assert len(o["id"]) > 20
    cells = m.cells()
    ids, n = np.unique(cells["object"][cells["object"] != 0], return_counts=True)
    np.testing.assert_array_equal(np.sort(o["id"]), ids[n >= 5])
    for i, oid in enumerate(o["id"]):
        mine = m.cells_of_object(int(oid))
        assert len(mine["label"]) == o["cells"][i]
        votes = np.bincount(mine["label"], minlength=10)
        assert o["label"][i] == votes.argmax()
        np.testing.assert_allclose(o["centroid"][i], mine["centre"].mean(axis=0), atol=1e-9)
        assert (o["half_extents"][i] >= 0).all()
    # Fewer objects with a larger minimum.
    assert m.extract_objects(min_cells=200) == len(m.objects()["id"]) < len(o["id"])
    assert m.relations() == [] and m.viewpoint is None


# --- files ------------------------------------------------------------------------------


def test_save_load_round_trip(kitti_map, tmp_path):
    p = tmp_path / "m.srt"
    kitti_map.save(p)
    back = SemanticMap.load(p)
    assert len(back) == len(kitti_map) and back.resolution == kitti_map.resolution
    assert back.options == kitti_map.options
    assert_cells_equal(sort_rows(back.cells()), sort_rows(kitti_map.cells()))
    for q in [
        lambda m: m.query_box([-5, -5, -2], [5, 5, 2]),
        lambda m: m.query_radius([2, 3, 0], 4.0),
        lambda m: m.cells_of_class("street"),
    ]:
        assert_cells_equal(sort_rows(q(back)), sort_rows(q(kitti_map)))
    a, b = back.knn([1, 2, 0], 50), kitti_map.knn([1, 2, 0], 50)
    np.testing.assert_array_equal(
        np.linalg.norm(a["centre"] - [1, 2, 0], axis=1), np.linalg.norm(b["centre"] - [1, 2, 0], axis=1)
    )
    q = tmp_path / "again.srt"
    back.save(q)
    assert q.read_bytes() == p.read_bytes()
    assert back.memory()["cells"] == len(back)


def test_bad_input_raises_clear_errors(scan, tmp_path, kitti_map):
    xyz, label = scan
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        SemanticMap.build(xyz[:, :2])
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        SemanticMap.build(xyz[:, 0])
    with pytest.raises(ValueError, match="label"):
        SemanticMap.build(xyz, label[:-1])
    with pytest.raises(ValueError, match=r"0\.\.=9"):
        SemanticMap.build(xyz[:3], np.array([0, 1, 10], dtype=np.uint8))
    with pytest.raises(ValueError, match="integers"):
        SemanticMap.build(xyz[:3], [0.5, 1, 2])
    bad = xyz[:100].copy()
    bad[42, 1] = np.nan
    with pytest.raises(MapError, match="42"):
        SemanticMap.build(bad)
    m = SemanticMap(0.1)
    with pytest.raises(MapError):
        m.insert(bad)
    assert len(m) == 0, "a failed insertion leaves the map unchanged"
    with pytest.raises(ValueError, match="resolution"):
        SemanticMap(0.0)
    with pytest.raises(MapError, match="no_such.srt"):
        SemanticMap.load(tmp_path / "no_such.srt")
    with pytest.raises(MapError, match="no_such.ply"):
        SemanticMap.from_cloud(tmp_path / "no_such.ply")
    with pytest.raises(ValueError, match="label_set"):
        SemanticMap.from_cloud(tmp_path / "x.bin", labels=tmp_path / "y.bin")
    with pytest.raises(ValueError, match="unknown label_set"):
        SemanticMap.from_cloud(tmp_path / "x.bin", labels=tmp_path / "y.bin", label_set="semkitti")
    good = tmp_path / "good.srt"
    kitti_map.save(good)
    data = good.read_bytes()
    truncated = tmp_path / "truncated.srt"
    truncated.write_bytes(data[: len(data) // 2])
    with pytest.raises(MapError, match="truncated|checksum"):
        SemanticMap.load(truncated)
    flipped = bytearray(data)
    flipped[len(data) // 3] ^= 0xFF
    corrupt = tmp_path / "corrupt.srt"
    corrupt.write_bytes(bytes(flipped))
    with pytest.raises(MapError, match="checksum|corrupt"):
        SemanticMap.load(corrupt)
    with pytest.raises(ValueError, match="unknown class"):
        kitti_map.cells_of_class("spaceship")
    with pytest.raises(ValueError, match="class id"):
        kitti_map.cells_of_class(42)
    with pytest.raises(ValueError, match="finite"):
        kitti_map.knn([0, np.nan, 0], 3)
    with pytest.raises(ValueError, match="radius"):
        kitti_map.query_radius([0, 0, 0], -1.0)
    with pytest.raises(MapError, match="no_model.json"):
        kitti_map.infer_relations(tmp_path / "no_model.json", (0.0, 0.0, 0.0))
    assert issubclass(MapError, urbansem.UrbansemError)


# --- the CLI on the same input ----------------------------------------------------------


def test_python_and_cli_write_the_same_map(cli, scan_paths, tmp_path):
    bin_, labels = scan_paths
    ply = tmp_path / "scan.ply"
    run(cli, "cloud", "convert", bin_, ply, "--labels", labels, "--label-set", "kitti360")
    cli_srt = tmp_path / "cli.srt"
    report = json.loads(run(cli, "map", "build", "--cloud", ply, "--out", cli_srt, "--json"))
    m = SemanticMap.from_cloud(bin_, labels=labels, label_set="kitti360")
    py_srt = tmp_path / "py.srt"
    m.save(py_srt)
    assert py_srt.read_bytes() == cli_srt.read_bytes()
    assert report["cells"] == len(m)
    assert report["objects"] == len(m.objects()["id"])
    assert report["memory"]["cells"] == m.memory()["cells"]
    assert report["tree_height"] == m.tree_height
    # From arrays: the same map.
    cloud = urbansem.read_cloud(ply)
    from_arrays = SemanticMap.build(cloud["xyz"], cloud["label"])
    arrays_srt = tmp_path / "arrays.srt"
    from_arrays.save(arrays_srt)
    assert arrays_srt.read_bytes() == cli_srt.read_bytes()
    # Queries: the CLI's cells are the same, in the same order.
    queries = [
        (["--box=-5,-5,-2,5,5,2"], lambda: m.query_box([-5, -5, -2], [5, 5, 2])),
        (["--near=3,1,0", "--k", "25"], lambda: m.knn([3, 1, 0], 25)),
        (["--near=3,1,0", "--radius", "2.5"], lambda: m.query_radius([3, 1, 0], 2.5)),
        (["--class", "car"], lambda: m.cells_of_class("car")),
    ]
    names = SemanticMap.class_names()
    for args, query in queries:
        out = json.loads(run(cli, "map", "query", cli_srt, *args, "--json"))
        got = query()
        assert out["count"] == len(got["label"]) > 0, args
        np.testing.assert_array_equal(np.array([c["centre"] for c in out["cells"]]), got["centre"])
        assert [c["class"] for c in out["cells"]] == [names[i] for i in got["label"]]
        np.testing.assert_array_equal([c["hits"] for c in out["cells"]], got["hits"])
        np.testing.assert_allclose([c["occupancy"] for c in out["cells"]], got["occupancy"])


@pytest.fixture(scope="module")
def relations_setup(cli, tmp_path_factory):
    """A small simulated relations dataset and a model trained on it (by the CLI)."""
    d = tmp_path_factory.mktemp("relations")
    ds = d / "dataset"
    run(cli, "sim", "dataset", "--kind", "relations", "--out", ds, "--scans", "6", "--seed", "3")
    model = d / "model.json"
    run(cli, "relations", "train", "--dataset", ds, "--out", model)
    return ds, model


def test_relations_equal_the_cli(cli, relations_setup, tmp_path):
    ds, model = relations_setup
    scene = ds / "scene_000.ply"
    vp = json.loads((ds / "scene_000.json").read_text())["viewpoint"]
    viewpoint = (vp["x"], vp["y"], vp["yaw"])
    cli_srt = tmp_path / "cli.srt"
    run(cli, "map", "build", "--cloud", scene, "--out", cli_srt)
    graph = json.loads(
        run(
            cli, "relations", "infer", "--map", cli_srt, "--model", model,
            "--viewpoint", ",".join(map(repr, viewpoint)), "--json", "--save", tmp_path / "cli_rel.srt",
        )
    )
    dot = run(
        cli, "relations", "infer", "--map", cli_srt, "--model", model,
        "--viewpoint", ",".join(map(repr, viewpoint)), "--dot",
    )
    want = [
        (e["a"], name, e["b"])
        for e in graph["edges"]
        for bit, name in enumerate(RELATION_NAMES)
        if e["bits"] >> bit & 1
    ]
    m = SemanticMap.from_cloud(scene)
    assert len(m.objects()["id"]) == len(graph["objects"]) > 3
    got = m.infer_relations(model, viewpoint)
    assert got == want and len(got) > 0
    assert m.relations() == want
    assert m.relations(base_only=True) == [t for t in want if t[1] in ("On", "LeftOf", "Behind")]
    assert json.loads(json.dumps(m.relation_graph())) == graph
    assert m.to_dot() == dot
    assert m.viewpoint == (vp["x"], vp["y"], 1.8, vp["yaw"])
    # Saved with its relations: the same file as the CLI's --save, and back.
    p = tmp_path / "py_rel.srt"
    m.save(p)
    assert p.read_bytes() == (tmp_path / "cli_rel.srt").read_bytes()
    back = SemanticMap.load(p)
    assert back.relations() == want
    ob, om = back.objects(), m.objects()
    for k in om:
        # The file keeps the graph as JSON, whose floats may come back 1 ulp off.
        np.testing.assert_allclose(ob[k], om[k], rtol=1e-15, atol=0, err_msg=k)
    # With the OSM outlines completing the buildings, as `relations infer --osm`.
    osm_graph = json.loads(
        run(
            cli, "relations", "infer", "--map", cli_srt, "--model", model,
            "--viewpoint", ",".join(map(repr, viewpoint)), "--json", "--osm", ds / "city.osm",
        )
    )
    with_osm = m.infer_relations(model, viewpoint, osm=urbansem.OsmMap.load(ds / "city.osm"))
    assert json.loads(json.dumps(m.relation_graph())) == osm_graph
    assert len(with_osm) > 0
    with pytest.raises(ValueError):
        m.infer_relations(model, viewpoint, cloud_frame="mars:1")
    # Inserting drops the edges (they described the old cells) but keeps objects.
    back.insert(np.array([[vp["x"], vp["y"], 0.05]]))
    assert back.relations() == [] and back.viewpoint is None
    assert len(back.objects()["id"]) == len(om["id"])


def test_dirichlet_labels_equal_the_cli(cli, scan_paths, data_dir, tmp_path):
    model = tmp_path / "dirichlet.json"
    run(cli, "map", "eval-labels", "--data", data_dir / "lidar", "--max-scans", "8", "--model-out", model)
    assert any(c is not None for c in json.loads(model.read_text())["classes"])
    bin_, labels = scan_paths
    ply = tmp_path / "scan.ply"
    run(cli, "cloud", "convert", bin_, ply, "--labels", labels, "--label-set", "kitti360")
    cli_srt = tmp_path / "cli.srt"
    run(cli, "map", "build", "--cloud", ply, "--out", cli_srt, "--dirichlet", model)
    by_path = SemanticMap.from_cloud(bin_, labels=labels, label_set="kitti360", dirichlet=model)
    py_srt = tmp_path / "py.srt"
    by_path.save(py_srt)
    assert py_srt.read_bytes() == cli_srt.read_bytes()
    by_dict = SemanticMap.from_cloud(
        bin_, labels=labels, label_set="kitti360", dirichlet=json.loads(model.read_text())
    )
    assert_cells_equal(by_dict.cells(), by_path.cells())
    # The model travels with the file: an insertion after loading labels the same way.
    back = SemanticMap.load(py_srt)
    empty = SemanticMap(0.1, dirichlet=model)
    cloud = urbansem.read_cloud(ply)
    empty.insert(cloud["xyz"], cloud["label"])
    assert_cells_equal(sort_rows(empty.cells()), sort_rows(back.cells()))
    with pytest.raises(ValueError, match="Dirichlet"):
        SemanticMap(0.1, dirichlet={"smoothing": "much"})
    with pytest.raises(MapError, match="nope.json"):
        SemanticMap(0.1, dirichlet=tmp_path / "nope.json")
