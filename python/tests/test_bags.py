"""ROS 2 bags written by another library (the `mcap` and `mcap-ros2-support` Python packages)
read by urbansem exactly as the scans they were made from."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

import urbansem
from conftest import kitti_scans

mcap_ros2_writer = pytest.importorskip(
    "mcap_ros2.writer", reason="pip install mcap mcap-ros2-support (.ci/run installs them)"
)
from mcap.writer import CompressionType  # noqa: E402

POINT_CLOUD2 = """std_msgs/Header header
uint32 height
uint32 width
PointField[] fields
bool    is_bigendian
uint32  point_step
uint32  row_step
uint8[] data
bool is_dense
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: sensor_msgs/PointField
uint8 INT8    = 1
uint8 UINT8   = 2
uint8 INT16   = 3
uint8 UINT16  = 4
uint8 INT32   = 5
uint8 UINT32  = 6
uint8 FLOAT32 = 7
uint8 FLOAT64 = 8
string name
uint32 offset
uint8  datatype
uint32 count
"""

FLOAT32, FLOAT64, UINT16 = 7, 8, 4


def message(points: np.ndarray, fields, stamp: int):
    """A PointCloud2 dict of a structured array `points`."""
    return {
        "header": {"stamp": {"sec": stamp, "nanosec": 0}, "frame_id": "velodyne"},
        "height": 1,
        "width": len(points),
        "fields": [
            {"name": n, "offset": o, "datatype": t, "count": 1} for n, o, t in fields
        ],
        "is_bigendian": False,
        "point_step": points.dtype.itemsize,
        "row_step": points.dtype.itemsize * len(points),
        "data": points.tobytes(),
        "is_dense": True,
    }


def kitti_layout(raw: np.ndarray):
    dtype = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("intensity", "<f4")])
    pts = np.zeros(len(raw), dtype)
    for i, n in enumerate(("x", "y", "z", "intensity")):
        pts[n] = raw[:, i]
    return pts, [("x", 0, FLOAT32), ("y", 4, FLOAT32), ("z", 8, FLOAT32), ("intensity", 12, FLOAT32)]


def ouster_layout(raw: np.ndarray):
    # float64 positions, uint16 ring, 6 bytes of padding: another driver's layout.
    dtype = np.dtype(
        {"names": ["x", "y", "z", "ring"], "formats": ["<f8", "<f8", "<f8", "<u2"],
         "offsets": [0, 8, 16, 24], "itemsize": 32}
    )
    pts = np.zeros(len(raw), dtype)
    for i, n in enumerate(("x", "y", "z")):
        pts[n] = raw[:, i].astype(np.float64)
    pts["ring"] = np.arange(len(raw)) % 64
    return pts, [("x", 0, FLOAT64), ("y", 8, FLOAT64), ("z", 16, FLOAT64), ("ring", 24, UINT16)]


@pytest.mark.parametrize("compression", [CompressionType.NONE, CompressionType.ZSTD, CompressionType.LZ4])
@pytest.mark.parametrize("layout", [kitti_layout, ouster_layout])
def test_bag_from_python_reads_as_the_scans(data: Path, tmp_path: Path, compression, layout) -> None:
    scans = kitti_scans(data)[:3]
    bag = tmp_path / "drive.mcap"
    with open(bag, "wb") as f:
        w = mcap_ros2_writer.Writer(f, compression=compression, chunk_size=256 * 1024)
        schema = w.register_msgdef("sensor_msgs/msg/PointCloud2", POINT_CLOUD2)
        for i, scan in enumerate(scans):
            raw = np.fromfile(scan, dtype=np.float32).reshape(-1, 4)
            pts, fields = layout(raw)
            t = (1_000 + i) * 10**9
            w.write_message("/points", schema, message(pts, fields, 1_000 + i), log_time=t, publish_time=t)
        w.finish()
    info = urbansem.bag_topics(bag)
    topics = {t["topic"]: t for t in info["topics"]}
    assert topics["/points"]["messages"] == len(scans)
    for i, scan in enumerate(scans):
        want = urbansem.read_cloud(scan)
        got = urbansem.read_cloud(bag, topic="/points", index=i)
        assert np.array_equal(got["xyz"], want["xyz"])
        if layout is kitti_layout:
            assert np.array_equal(got["intensity"], want["intensity"])
    with pytest.raises(urbansem.CloudError, match="index|message"):
        urbansem.read_cloud(bag, topic="/points", index=len(scans))


ODOMETRY = """std_msgs/Header header
string child_frame_id
geometry_msgs/PoseWithCovariance pose
geometry_msgs/TwistWithCovariance twist
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/PoseWithCovariance
Pose pose
float64[36] covariance
================================================================================
MSG: geometry_msgs/Pose
Point position
Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
================================================================================
MSG: geometry_msgs/TwistWithCovariance
Twist twist
float64[36] covariance
================================================================================
MSG: geometry_msgs/Twist
Vector3  linear
Vector3  angular
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"""


def test_odometry_and_time_pick_from_a_python_bag(data: Path, tmp_path: Path) -> None:
    scans = kitti_scans(data)[:3]
    bag = tmp_path / "odom.mcap"
    yaws = [0.0, 0.3, -1.2]
    with open(bag, "wb") as f:
        w = mcap_ros2_writer.Writer(f)
        cloud_schema = w.register_msgdef("sensor_msgs/msg/PointCloud2", POINT_CLOUD2)
        odom_schema = w.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY)
        for i, scan in enumerate(scans):
            t = (1_000 + i) * 10**9
            raw = np.fromfile(scan, dtype=np.float32).reshape(-1, 4)
            pts, fields = kitti_layout(raw)
            w.write_message("/points", cloud_schema, message(pts, fields, 1_000 + i), log_time=t, publish_time=t)
            odom = {
                "header": {"stamp": {"sec": 1_000 + i, "nanosec": 500}, "frame_id": "odom"},
                "child_frame_id": "base_link",
                "pose": {
                    "pose": {
                        "position": {"x": 2.0 * i, "y": -1.0, "z": 0.5},
                        "orientation": {"x": 0.0, "y": 0.0, "z": np.sin(yaws[i] / 2), "w": np.cos(yaws[i] / 2)},
                    },
                    "covariance": [0.0] * 36,
                },
                "twist": {"twist": {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}, "covariance": [0.0] * 36},
            }
            w.write_message("/odom", odom_schema, odom, log_time=t + 1, publish_time=t + 1)
        w.finish()
    p = urbansem.bag_poses(bag, "/odom")
    assert p["stamp_ns"].tolist() == [(1_000 + i) * 10**9 + 500 for i in range(3)]
    assert np.allclose(p["translation"], [[2.0 * i, -1.0, 0.5] for i in range(3)])
    assert np.allclose(p["yaw"], yaws)
    assert p["child_frame_id"] == ["base_link"] * 3
    got = urbansem.read_cloud(bag, topic="/points", time=1_001.4)
    assert np.array_equal(got["xyz"], urbansem.read_cloud(scans[1])["xyz"])
    with pytest.raises(urbansem.CloudError, match="holds no poses"):
        urbansem.bag_poses(bag, "/points")
    with pytest.raises(ValueError, match="not both"):
        urbansem.read_cloud(bag, topic="/points", time=1.0, index=0)


def quaternion(r: np.ndarray) -> list:
    """A rotation matrix as [x, y, z, w] (Shepperd's method, w branch suffices here)."""
    w = np.sqrt(max(1e-12, 1.0 + r[0, 0] + r[1, 1] + r[2, 2])) / 2.0
    return [(r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w), w]


def test_map_build_from_a_bag_places_scans_by_their_poses(data: Path, tmp_path: Path, cli) -> None:
    seq = data / "lidar" / "kitti360_2013_05_28_drive_0009"
    poses = {}
    for line in (seq / "velodyne_poses_1900-3100.txt").read_text().splitlines():
        v = line.split()
        poses[int(v[0])] = np.array(v[1:], dtype=float).reshape(4, 4)
    scans = kitti_scans(data)[:3]
    frames = [int(s.stem) for s in scans]
    shift = poses[frames[0]][:3, 3].copy()
    bag = tmp_path / "drive.mcap"
    with open(bag, "wb") as f:
        w = mcap_ros2_writer.Writer(f)
        cloud_schema = w.register_msgdef("sensor_msgs/msg/PointCloud2", POINT_CLOUD2)
        odom_schema = w.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY)
        for i, (scan, frame) in enumerate(zip(scans, frames)):
            t = (1_000 + i) * 10**9
            pose = poses[frame]
            x, y, z = pose[:3, 3] - shift
            qx, qy, qz, qw = quaternion(pose[:3, :3])
            odom = {
                "header": {"stamp": {"sec": 1_000 + i, "nanosec": 0}, "frame_id": "map"},
                "child_frame_id": "velodyne",
                "pose": {"pose": {"position": {"x": x, "y": y, "z": z},
                                  "orientation": {"x": qx, "y": qy, "z": qz, "w": qw}},
                         "covariance": [0.0] * 36},
                "twist": {"twist": {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}, "covariance": [0.0] * 36},
            }
            w.write_message("/odom", odom_schema, odom, log_time=t, publish_time=t)
            raw = np.fromfile(scan, dtype=np.float32).reshape(-1, 4)
            pts, fields = kitti_layout(raw)
            w.write_message("/points", cloud_schema, message(pts, fields, 1_000 + i), log_time=t + 5, publish_time=t + 5)
        w.finish()
    out = tmp_path / "bag.srt"
    report = cli("map", "build", "--cloud", bag, "--topic", "/points", "--poses", "/odom", "--out", out, "--json", json_out=True)
    assert report["bag"]["inserted"] == 3 and report["bag"]["poses"] == 3
    # The same scans placed by the same poses in Python.
    ours = urbansem.SemanticMap(resolution=0.1)
    for scan, frame in zip(scans, frames):
        raw = np.fromfile(scan, dtype=np.float32).reshape(-1, 4)[:, :3].astype(np.float64)
        pose = poses[frame]
        ours.insert(raw @ pose[:3, :3].T + (pose[:3, 3] - shift))
    theirs = urbansem.SemanticMap.load(out)
    a, b = ours.cells(), theirs.cells()
    key = lambda c: np.lexsort(np.round(c["centre"], 3).T[::-1])
    ia, ib = key(a), key(b)
    assert len(ia) == len(ib) == report["cells"]
    assert np.allclose(a["centre"][ia], b["centre"][ib])
    assert np.array_equal(a["hits"][ia], b["hits"][ib])
    # A scan far from every pose is skipped, and a missing pose topic is a clear error.
    far = cli("map", "build", "--cloud", bag, "--topic", "/points", "--poses", "/odom", "--max-gap", "0", "--every", "2", "--out", tmp_path / "b.srt", "--json", json_out=True)
    assert far["bag"]["inserted"] == 2  # stamps of scans and poses coincide: gap 0 is enough
    rays = cli("map", "build", "--cloud", bag, "--topic", "/points", "--poses", "/odom", "--ray-casting", "--out", tmp_path / "r.srt", "--json", json_out=True)
    assert rays["rays"] == report["points"] and rays["misses"] > 0
    with pytest.raises(subprocess.CalledProcessError) as e:
        cli("map", "build", "--cloud", bag, "--topic", "/points", "--poses", "/tf", "--out", tmp_path / "c.srt")
    assert "no topic" in e.value.stderr and "/odom" in e.value.stderr


POSE_STAMPED = """std_msgs/Header header
Pose pose
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Pose
Point position
Quaternion orientation
================================================================================
MSG: geometry_msgs/Point
float64 x
float64 y
float64 z
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
"""


def rotation_to_quaternion(r: np.ndarray) -> list:
    """[x, y, z, w] of a rotation matrix (any rotation: the largest-component branch)."""
    t = np.trace(r)
    if t > 0:
        s = 2.0 * np.sqrt(1.0 + t)
        return [(r[2, 1] - r[1, 2]) / s, (r[0, 2] - r[2, 0]) / s, (r[1, 0] - r[0, 1]) / s, s / 4]
    i = int(np.argmax(np.diag(r)))
    j, k = (i + 1) % 3, (i + 2) % 3
    s = 2.0 * np.sqrt(1.0 + r[i, i] - r[j, j] - r[k, k])
    q = [0.0, 0.0, 0.0, (r[k, j] - r[j, k]) / s]
    q[i] = s / 4
    q[j] = (r[j, i] + r[i, j]) / s
    q[k] = (r[k, i] + r[i, k]) / s
    return q


def test_localize_track_from_a_bag_of_tilted_mcd_scans(data: Path, tmp_path: Path, cli) -> None:
    """Raw (tilted) Ouster scans and their 3-D poses in a bag: `localize track --bag` levels
    each scan by its pose and localizes the track on the KTH map near the truth."""
    mcd = data / "lidar" / "mcd_kth_day_06"
    osm_path = data / "osm" / "kth_campus_stockholm.osm"
    osm = urbansem.OsmMap.load(osm_path)
    frames = urbansem.localize.mcd_frames(mcd)[:4]
    bag = tmp_path / "mcd.mcap"
    truths = []
    with open(bag, "wb") as f:
        w = mcap_ros2_writer.Writer(f)
        cloud_schema = w.register_msgdef("sensor_msgs/msg/PointCloud2", POINT_CLOUD2)
        pose_schema = w.register_msgdef("geometry_msgs/msg/PoseStamped", POSE_STAMPED)
        for i, frame in enumerate(frames):
            scan = urbansem.localize.load_mcd_scan(mcd, osm, frame)
            x, y, yaw = scan.truth
            truths.append(scan.truth)
            rz = np.array([[np.cos(yaw), -np.sin(yaw), 0], [np.sin(yaw), np.cos(yaw), 0], [0, 0, 1]])
            qx, qy, qz, qw = rotation_to_quaternion(rz @ scan.levelling)
            t = (2_000 + i) * 10**9
            pose = {"header": {"stamp": {"sec": 2_000 + i, "nanosec": 0}, "frame_id": "odom"},
                    "pose": {"position": {"x": x, "y": y, "z": 0.0},
                             "orientation": {"x": qx, "y": qy, "z": qz, "w": qw}}}
            w.write_message("/pose", pose_schema, pose, log_time=t, publish_time=t)
            raw = np.fromfile(mcd / "lidar_bin" / f"{frame:010}.bin", dtype=np.float32).reshape(-1, 4)
            pts, fields = kitti_layout(raw)
            w.write_message("/os1/points", cloud_schema, message(pts, fields, 2_000 + i), log_time=t, publish_time=t)
        w.finish()
    report = cli("localize", "track", "--map", osm_path, "--bag", bag, "--topic", "/os1/points",
                 "--odometry-topic", "/pose", "--window", "3", "--json", json_out=True)
    rows = report["scans"]
    assert [r["scan"] for r in rows] == [f"/os1/points#{i}" for i in range(len(frames))]
    for row, (x, y, yaw) in zip(rows, truths):
        best = row["candidates"][0]
        assert np.hypot(best["x"] - x, best["y"] - y) < 4.0, row["scan"]
        d = (best["yaw_grid"] - yaw + np.pi) % (2 * np.pi) - np.pi
        assert abs(d) < 0.2, row["scan"]
    # One message of the bag localizes as the same points from a file do (streets estimate and
    # map build read bag messages through the same option group).
    raw = np.fromfile(mcd / "lidar_bin" / f"{frames[1]:010}.bin", dtype=np.float32).reshape(-1, 4)
    ply = tmp_path / "scan1.ply"
    urbansem.write_cloud(ply, raw[:, :3].astype(np.float64))
    from_bag = cli("localize", "--map", osm_path, "--scan", bag, "--topic", "/os1/points", "--index", "1", "--json", json_out=True)
    from_file = cli("localize", "--map", osm_path, "--scan", ply, "--json", json_out=True)
    assert from_bag["scan"].endswith("/os1/points#1")
    assert from_bag["candidates"] == from_file["candidates"]
    by_time = cli("localize", "--map", osm_path, "--scan", bag, "--topic", "/os1/points", "--time", "2001.2", "--json", json_out=True)
    assert by_time["candidates"] == from_file["candidates"]
    # The same scans levelled by the library and tracked in Python agree with the bag's track.
    loc = urbansem.Localizer(osm)
    scans = [urbansem.localize.load_mcd_scan(mcd, osm, f).points for f in frames]
    ours = loc.track(scans, np.array(truths), window=3)
    for a, b in zip(ours, rows):
        assert np.hypot(a.candidates[0].x - b["candidates"][0]["x"], a.candidates[0].y - b["candidates"][0]["y"]) < 0.5
