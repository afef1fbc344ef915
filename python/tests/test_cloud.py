"""read_cloud / write_cloud: real scans in, every writer's format back, the CLI's numbers,
and clear errors."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import urbansem
from conftest import kitti_scans


@pytest.fixture(scope="module")
def scan(data: Path) -> Path:
    return kitti_scans(data)[0]


def test_kitti_scan_matches_the_raw_file_and_the_cli(scan: Path, cli) -> None:
    c = urbansem.read_cloud(scan)
    raw = np.fromfile(scan, dtype=np.float32).reshape(-1, 4)
    assert c["xyz"].dtype == np.float64 and c["xyz"].shape == (len(raw), 3)
    assert np.array_equal(c["xyz"], raw[:, :3].astype(np.float64))
    assert np.array_equal(c["intensity"], raw[:, 3])
    info = cli("cloud", "info", scan, "--json", json_out=True)
    assert info["points"] == len(c["xyz"])
    assert np.allclose(c["xyz"].min(axis=0), info["bounds"]["min"])
    assert np.allclose(c["xyz"].max(axis=0), info["bounds"]["max"])


def test_labels_attach_as_the_cli_does(scan: Path, data: Path, tmp_path: Path, cli) -> None:
    labels = scan.parent.parent / "gt_labels" / scan.name
    c = urbansem.read_cloud(scan, labels=labels, label_set="kitti360")
    assert c["label"].dtype == np.uint8 and c["raw_label"].dtype == np.uint32
    assert np.array_equal(c["raw_label"], np.fromfile(labels, dtype=np.uint32))
    out = tmp_path / "cli.ply"
    cli("cloud", "convert", scan, out, "--labels", labels, "--label-set", "kitti360")
    back = urbansem.read_cloud(out)
    for key in ("label", "raw_label", "intensity"):
        assert np.array_equal(back[key], c[key]), key
    assert np.allclose(back["xyz"], c["xyz"], atol=1e-5)


@pytest.mark.parametrize(
    "name,encoding,double",
    [
        ("a.ply", "binary", False),
        ("a.ply", "ascii", True),
        ("a.ply", "binary_big_endian", True),
        ("a.pcd", "binary", True),
        ("a.pcd", "binary_compressed", False),
        ("a.pcd", "ascii", True),
        ("a.las", "binary", True),
        ("a.laz", "binary", True),
    ],
)
def test_write_read_round_trip(tmp_path: Path, name: str, encoding: str, double: bool) -> None:
    rng = np.random.default_rng(7)
    n = 500
    xyz = rng.uniform(-50, 50, size=(n, 3))
    if not double:
        xyz = xyz.astype(np.float32).astype(np.float64)
    cols = {
        "intensity": rng.uniform(0, 1, n).astype(np.float32),
        "label": rng.integers(0, 10, n, dtype=np.uint8),
        "object": rng.integers(0, 1000, n, dtype=np.uint32),
    }
    path = tmp_path / name
    urbansem.write_cloud(path, xyz, encoding=encoding, double=double, **cols)
    back = urbansem.read_cloud(path)
    tol = 1e-3 if name.endswith((".las", ".laz")) else (1e-9 if double else 0)
    assert np.abs(back["xyz"] - xyz).max() <= tol
    for key, values in cols.items():
        if key in back:
            assert np.array_equal(back[key], values), key


def test_non_contiguous_input_is_read_correctly(tmp_path: Path) -> None:
    xyz = np.arange(60, dtype=np.float64).reshape(20, 3)[::2]
    assert not xyz.flags["C_CONTIGUOUS"]
    urbansem.write_cloud(tmp_path / "s.ply", xyz, double=True)
    assert np.array_equal(urbansem.read_cloud(tmp_path / "s.ply")["xyz"], xyz)


def test_bad_input_gives_clear_errors(tmp_path: Path, scan: Path) -> None:
    with pytest.raises(urbansem.CloudError, match="No such file"):
        urbansem.read_cloud(tmp_path / "missing.ply")
    truncated = tmp_path / "t.bin"
    truncated.write_bytes(scan.read_bytes()[:1001])
    with pytest.raises(urbansem.CloudError, match="t.bin"):
        urbansem.read_cloud(truncated)
    with pytest.raises(ValueError, match=r"shape \(n, 3\)"):
        urbansem.write_cloud(tmp_path / "x.ply", np.zeros((4, 2)))
    with pytest.raises(ValueError, match="intensity"):
        urbansem.write_cloud(tmp_path / "x.ply", np.zeros((4, 3)), intensity=np.zeros(3, np.float32))
    with pytest.raises(ValueError, match="encoding"):
        urbansem.write_cloud(tmp_path / "x.ply", np.zeros((4, 3)), encoding="zip")
    with pytest.raises(ValueError, match="ROS 2 bag"):
        urbansem.read_cloud(scan, topic="/points")
    with pytest.raises(ValueError, match="label_set"):
        urbansem.read_cloud(scan, labels=scan, label_set="nuscenes")
    nan = tmp_path / "nan.bin"
    pts = np.zeros((3, 4), np.float32)
    pts[1, 0] = np.nan
    pts.tofile(nan)
    with pytest.raises(urbansem.CloudError):
        urbansem.read_cloud(nan)
    assert len(urbansem.read_cloud(nan, drop_non_finite=True)["xyz"]) == 2
    assert issubclass(urbansem.CloudError, urbansem.UrbansemError)
