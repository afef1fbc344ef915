#!/usr/bin/env python3
"""PLY interop: files written by another library (PyPI `plyfile`) read by urbansem, and back.

Writes PLY files with plyfile into a temporary folder — ascii, binary_little_endian and
binary_big_endian; x y z as float and as double; intensity (float), red green blue (uchar),
an extra scalar property, a `face` element with a `vertex_indices` list (before or after the
vertices), `comment` and `obj_info` lines — and for each one:

1. runs `urbansem cloud info FILE --json` and compares the point count, the columns, the
   precision and the bounds with what was written;
2. runs `urbansem cloud convert FILE OUT.ply --ascii` and reads OUT.ply back with plyfile,
   comparing every x, y, z, intensity and colour value exactly.

Prints one line per file and exits 1 on any difference.

    python3 scripts/ply_interop.py [--urbansem target/release/urbansem] [--points 1000]

Installs plyfile and numpy with pip if they are missing.
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

try:
    import numpy as np
    from plyfile import PlyData, PlyElement
except ImportError:
    subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", "plyfile", "numpy"])
    import numpy as np
    from plyfile import PlyData, PlyElement

REPO = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def make_vertices(n, coord, seed):
    """n vertices with coordinates of dtype `coord` ('f4' or 'f8'), seeded."""
    rng = np.random.default_rng(seed)
    v = np.empty(
        n,
        dtype=[
            ("x", coord), ("y", coord), ("z", coord),
            ("intensity", "f4"),
            ("red", "u1"), ("green", "u1"), ("blue", "u1"),
            ("quality", "f8"),
        ],
    )
    scale = rng.choice([1e-3, 1.0, 1e3], size=(n, 3))
    xyz = rng.uniform(-5000.0, 5000.0, size=(n, 3)) * scale
    for k, axis in enumerate("xyz"):
        v[axis] = xyz[:, k].astype(coord)
    v["intensity"] = rng.uniform(-1e3, 1e3, n).astype("f4")
    for c in ("red", "green", "blue"):
        v[c] = rng.integers(0, 256, n, dtype="u1")
    v["quality"] = rng.normal(size=n)
    return v


def make_faces(n_vertices, n_faces, seed):
    rng = np.random.default_rng(seed + 1)
    f = np.empty(n_faces, dtype=[("vertex_indices", "O")])
    f["vertex_indices"] = [
        rng.integers(0, n_vertices, rng.integers(3, 6), dtype="i4") for _ in range(n_faces)
    ]
    return f


def write(path, vertices, faces, text, byte_order, faces_first):
    elements = [PlyElement.describe(vertices, "vertex"), PlyElement.describe(faces, "face")]
    if faces_first:
        elements.reverse()
    PlyData(
        elements,
        text=text,
        byte_order=byte_order,
        comments=["written by plyfile for urbansem's interop check"],
        obj_info=["scripts/ply_interop.py"],
    ).write(path)


def check(urbansem, path, vertices, coord, tmp):
    """Returns a list of differences (empty when urbansem agrees with what was written)."""
    problems = []
    run = subprocess.run([urbansem, "cloud", "info", path, "--json"], capture_output=True, text=True)
    if run.returncode != 0:
        return [f"cloud info failed: {run.stderr.strip()}"]
    info = json.loads(run.stdout)
    n = len(vertices)
    if info["points"] != n or info["points_in_file"] != n:
        problems.append(f"points {info['points']} / {info['points_in_file']}, wrote {n}")
    want_columns = ["x", "y", "z", "intensity", "rgb"]
    if info["columns"] != want_columns:
        problems.append(f"columns {info['columns']}, want {want_columns}")
    want_precision = "f32" if coord == "f4" else "f64"
    if info["precision"] != want_precision:
        problems.append(f"precision {info['precision']}, want {want_precision}")
    for k, axis in enumerate("xyz" if n else ""):
        lo = float(vertices[axis].min())
        hi = float(vertices[axis].max())
        if info["bounds"]["min"][k] != lo or info["bounds"]["max"][k] != hi:
            problems.append(
                f"{axis} bounds {info['bounds']['min'][k]}..{info['bounds']['max'][k]}, want {lo}..{hi}"
            )
    out = os.path.join(tmp, "back.ply")
    run = subprocess.run([urbansem, "cloud", "convert", path, out, "--ascii"], capture_output=True, text=True)
    if run.returncode != 0:
        return problems + [f"cloud convert failed: {run.stderr.strip()}"]
    back = PlyData.read(out)["vertex"].data
    if len(back) != n:
        return problems + [f"converted file has {len(back)} vertices, wrote {n}"]
    for name in ("x", "y", "z", "intensity", "red", "green", "blue"):
        got = np.asarray(back[name], dtype="f8")
        want = np.asarray(vertices[name], dtype="f8")
        bad = np.flatnonzero(got != want)
        if bad.size:
            i = int(bad[0])
            problems.append(f"{name} differs at {bad.size} vertices, first {i}: {got[i]!r} vs {want[i]!r}")
    return problems


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--urbansem", default=os.path.join(REPO, "target", "release", "urbansem"))
    ap.add_argument("--points", type=int, default=1000, help="vertices per file (at least 1)")
    args = ap.parse_args()
    if not os.path.exists(args.urbansem):
        sys.exit(f"{args.urbansem} not found; build it with `cargo build --release -p urbansem`")
    failures = 0
    with tempfile.TemporaryDirectory(prefix="urbansem-ply-interop-") as tmp:
        seed = 0
        for coord in ("f4", "f8"):
            for text, byte_order, label in (
                (True, "=", "ascii"),
                (False, "<", "binary_little_endian"),
                (False, ">", "binary_big_endian"),
            ):
                for faces_first in (False, True):
                    seed += 1
                    vertices = make_vertices(args.points, coord, seed)
                    faces = make_faces(args.points, 20, seed)
                    name = f"{label}-{'float' if coord == 'f4' else 'double'}-{'faces-first' if faces_first else 'vertices-first'}.ply"
                    path = os.path.join(tmp, name)
                    write(path, vertices, faces, text, byte_order, faces_first)
                    problems = check(args.urbansem, path, vertices, coord, tmp)
                    status = "ok" if not problems else "FAIL"
                    print(f"{status:4} {name:50} {args.points} points, {os.path.getsize(path)} bytes")
                    for p in problems:
                        print(f"     {p}")
                    failures += bool(problems)
    print(f"{12 - failures} of 12 plyfile files read back identically")
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
