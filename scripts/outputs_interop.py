#!/usr/bin/env python3
"""Issue 18 outputs read by other tools: the demo's files opened with PyPI `evo`, `plyfile`
and `mcap` (the readers of evo, CloudCompare-like PLY tools and Foxglove's MCAP library).

Checks in the demo folder (default `demo-out`, written by `urbansem demo`):

1. `track_tum.txt` and `track_kitti.txt` read by evo's file interface: the same number of
   poses, the same SE(3) matrices (within 1e-6), z = 0, a rotation about z only;
2. `semantic_map.ply` read by plyfile: x y z (double), red green blue label (uchar), object
   (uint), every label a class id 0..9;
3. `semantic_map.mcap` read by the mcap reader: a `sensor_msgs/msg/PointCloud2` (ros2msg
   schema, cdr) whose width is the PLY's vertex count, and a `foxglove.SceneUpdate` (json)
   with one cube per object;
4. every `*.geojson`: a FeatureCollection with the OpenStreetMap attribution, positions
   [lon, lat] in range.

Prints one line per check and exits 1 on any failure.

    python3 scripts/outputs_interop.py [demo-out]

Installs evo, plyfile and mcap with pip if they are missing (use a venv).
"""
import glob
import json
import os
import struct
import subprocess
import sys

try:
    import numpy as np
    from evo.tools import file_interface
    from mcap.reader import make_reader
    from plyfile import PlyData
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "-q", "evo", "plyfile", "mcap"])
    import numpy as np
    from evo.tools import file_interface
    from mcap.reader import make_reader
    from plyfile import PlyData

FAILED = []


def check(name, ok, detail=""):
    print(f"{'ok  ' if ok else 'FAIL'} {name}{': ' + detail if detail else ''}")
    if not ok:
        FAILED.append(name)


def trajectories(folder):
    tum = file_interface.read_tum_trajectory_file(os.path.join(folder, "track_tum.txt"))
    kitti = file_interface.read_kitti_poses_file(os.path.join(folder, "track_kitti.txt"))
    check("evo reads TUM and KITTI", tum.num_poses == kitti.num_poses > 0,
          f"{tum.num_poses} and {kitti.num_poses} poses")
    diff = max(np.abs(a - b).max() for a, b in zip(tum.poses_se3, kitti.poses_se3))
    check("TUM and KITTI poses agree", diff < 1e-6, f"largest difference {diff:.2e}")
    planar = all(abs(p[2, 3]) < 1e-9 and abs(p[2, 2] - 1.0) < 1e-9 for p in tum.poses_se3)
    check("poses are planar (z = 0, rotation about z)", planar)


def ply(folder):
    v = PlyData.read(os.path.join(folder, "semantic_map.ply"))["vertex"]
    names = v.data.dtype.names
    check("plyfile reads semantic_map.ply",
          names == ("x", "y", "z", "red", "green", "blue", "label", "object"), f"{len(v)} points, {names}")
    check("labels are class ids", int(v["label"].max()) <= 9)
    return len(v)


def bag(folder, points):
    with open(os.path.join(folder, "semantic_map.mcap"), "rb") as f:
        messages = [(s, c, m) for s, c, m in make_reader(f).iter_messages()]
    kinds = [(s.name, s.encoding, c.message_encoding) for s, c, _ in messages]
    check("mcap reads semantic_map.mcap", kinds == [
        ("sensor_msgs/msg/PointCloud2", "ros2msg", "cdr"),
        ("foxglove.SceneUpdate", "jsonschema", "json"),
    ], str(kinds))
    data = messages[0][2].data
    # CDR: header 4 bytes, stamp 8, frame_id (u32 length + bytes, padded to 4), height, width.
    n = struct.unpack_from("<I", data, 12)[0]
    at = 16 + n
    at += (4 - (at - 4) % 4) % 4
    height, width = struct.unpack_from("<II", data, at)
    check("PointCloud2 holds the PLY's points", height * width == points, f"{height} × {width}")
    scene = json.loads(messages[1][2].data)
    cubes = scene["entities"][0]["cubes"]
    check("SceneUpdate has object boxes", len(cubes) > 0, f"{len(cubes)} cubes")


def geojson(folder):
    for path in sorted(glob.glob(os.path.join(folder, "*.geojson"))):
        fc = json.load(open(path))
        positions = []

        def walk(c):
            if isinstance(c[0], (int, float)):
                positions.append(c)
            else:
                for x in c:
                    walk(x)

        for f in fc["features"]:
            walk(f["geometry"]["coordinates"])
        in_range = all(-180 <= p[0] <= 180 and -90 <= p[1] <= 90 for p in positions)
        check(f"{os.path.basename(path)}",
              fc["type"] == "FeatureCollection" and "OpenStreetMap" in fc.get("attribution", "") and in_range,
              f"{len(fc['features'])} features")


def main():
    folder = sys.argv[1] if len(sys.argv) > 1 else "demo-out"
    trajectories(folder)
    bag(folder, ply(folder))
    geojson(folder)
    sys.exit(1 if FAILED else 0)


if __name__ == "__main__":
    main()
