#!/usr/bin/env python3
"""SRTree map against OctoMap (pyoctomap) and libspatialindex (rtree), side by side in one run.

1. Runs `urbansem bench srtree --json --export DIR`: all real labelled scans of
   ../shared/data/lidar (KITTI-360 drive 0009 and MCD kth_day_06) registered into one
   cloud, inserted scan by scan into the SRTree map with and without free-space ray
   casting, then box queries. The registered cloud, the scan origins, the occupied cell
   centres and the query boxes are written to DIR.
2. Inserts the same cloud, scan by scan, at the same resolution into an OctoMap OcTree:
   without ray casting by `updateNodes(points, True, lazy_eval=True)` (a Cython loop over
   the points calling the C++ `updateNode`; the points are converted to Python lists
   before the clock starts) followed by `updateInnerOccupancy()`; with ray casting by the
   native `insertPointCloud(points, origin, max_range)` (OctoMap's own batch insertion).
   Without ray casting both sides build `--insert-repeat` times (default 3) and report
   the median time; with ray casting once.
   Memory is OctoMap's `memoryUsage()` (bytes of its nodes) and the process RSS growth;
   ours is every byte the map holds (`memory.total_bytes`: cell records, histogram table,
   R-tree nodes). Times are wall clock and process CPU time (CPU time is less disturbed
   by other jobs on a shared machine); the ratios are given for both.
3. Loads the same occupied cells (as boxes of one cell) into a libspatialindex R-tree
   (rtree, bulk stream loading) and runs the same boxes with `intersection_v` (one C call
   for all boxes) as many times as we do (`--repeat`, default 9), median time (wall and
   thread CPU) on both sides; the cell counts must equal ours.
4. Prints both sides and the ratios.

pyoctomap, rtree and numpy are installed with pip when missing.
Usage: python3 scripts/bench_srtree_octomap.py [--urbansem target/release/urbansem]
       [--data ../shared/data/lidar] [--resolution 0.1] [--max-scans N] [--no-ray-casting]
       [--insert-repeat 3] [--json]
"""

import argparse
import json
import os
import subprocess
import sys
import time


def ensure(module, package):
    try:
        __import__(module)
    except ImportError:
        subprocess.check_call([sys.executable, "-m", "pip", "install", "-q", package])


def rss_bytes():
    try:
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE")
    except OSError:
        return 0


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--urbansem", default="target/release/urbansem")
    ap.add_argument("--data", default="../shared/data/lidar")
    ap.add_argument("--export", default="target/bench-srtree")
    ap.add_argument("--resolution", type=float, default=0.1)
    ap.add_argument("--max-scans", type=int)
    ap.add_argument("--insert-repeat", type=int, default=3,
                    help="builds without ray casting on each side; the median time is reported")
    ap.add_argument("--no-ray-casting", action="store_true",
                    help="skip the runs with ray casting (OctoMap's takes long and GBs)")
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    for module, package in [("numpy", "numpy"), ("pyoctomap", "pyoctomap"), ("rtree", "rtree")]:
        ensure(module, package)
    import numpy as np
    import pyoctomap
    from rtree import index

    cmd = [args.urbansem, "bench", "srtree", "--json", "--export", args.export,
           "--data", args.data, "--resolution", str(args.resolution)]
    cmd += ["--insert-repeat", str(args.insert_repeat)]
    if args.max_scans:
        cmd += ["--max-scans", str(args.max_scans)]
    if args.no_ray_casting:
        cmd += ["--no-ray-casting"]
    print("running:", " ".join(cmd), file=sys.stderr)
    ours = json.loads(subprocess.check_output(cmd))
    meta = json.load(open(os.path.join(args.export, "meta.json")))
    points = np.fromfile(os.path.join(args.export, "points.f64")).reshape(-1, 3)
    cells = np.fromfile(os.path.join(args.export, "cells.f64")).reshape(-1, 3)
    boxes = np.fromfile(os.path.join(args.export, "boxes.f64")).reshape(-1, 6)
    scans = meta["scans"]
    r = meta["resolution_m"]
    n = len(points)

    octo = []
    for ray_casting in (False,) if args.no_ray_casting else (False, True):
        print(f"OctoMap, ray casting {ray_casting} …", file=sys.stderr)
        rss0 = rss_bytes()
        tree = pyoctomap.OcTree(r)
        if ray_casting:
            batches = [(np.ascontiguousarray(points[s["start"]:s["end"]]),
                        np.array(s["origin"], dtype=np.float64)) for s in scans]
            t, c = time.perf_counter(), time.process_time()
            for pts, origin in batches:
                tree.insertPointCloud(pts, origin, meta["max_ray_m"])
            seconds, cpu = time.perf_counter() - t, time.process_time() - c
        else:
            # As many builds as ours (`builds`), median time; the last tree is measured.
            batches = [points[s["start"]:s["end"]].tolist() for s in scans]
            walls, cpus = [], []
            rss_growth = None
            for b in range(ours["insert"][0].get("builds", 1)):
                if b > 0:
                    del tree
                    tree = pyoctomap.OcTree(r)
                t, c = time.perf_counter(), time.process_time()
                for pts in batches:
                    tree.updateNodes(pts, True, lazy_eval=True)
                tree.updateInnerOccupancy()
                walls.append(time.perf_counter() - t)
                cpus.append(time.process_time() - c)
                if rss_growth is None:  # the first build (later ones reuse freed pages)
                    rss_growth = rss_bytes() - rss0
            seconds, cpu = sorted(walls)[len(walls) // 2], sorted(cpus)[len(cpus) // 2]
            del batches
        octo.append({
            "ray_casting": ray_casting,
            "seconds": seconds,
            "points_per_second": n / seconds,
            "cpu_seconds": cpu,
            "points_per_cpu_second": n / cpu,
            "leaf_nodes": tree.getNumLeafNodes(),
            "nodes": tree.size(),
            "memory_bytes": tree.memoryUsage(),
            "rss_growth_bytes": rss_growth if not ray_casting else rss_bytes() - rss0,
        })
        del tree

    print("libspatialindex …", file=sys.stderr)
    h = 0.5 * r
    prop = index.Property()
    prop.dimension = 3
    t = time.perf_counter()
    rt = index.Index(((i, (c[0] - h, c[1] - h, c[2] - h, c[0] + h, c[1] + h, c[2] + h), None)
                      for i, c in enumerate(cells.tolist())), properties=prop)
    build_s = time.perf_counter() - t
    mins = np.ascontiguousarray(boxes[:, :3])
    maxs = np.ascontiguousarray(boxes[:, 3:])
    walls, cpus = [], []
    found = 0
    for _ in range(ours["queries"].get("repeat", 9)):
        t, c = time.perf_counter(), time.thread_time()
        _ids, counts = rt.intersection_v(mins, maxs)
        walls.append(time.perf_counter() - t)
        cpus.append(time.thread_time() - c)
        found = int(np.sum(counts))
        del _ids
    best = sorted(walls)[len(walls) // 2]
    best_cpu = sorted(cpus)[len(cpus) // 2]
    peer_q = {"seconds": best, "cpu_seconds": best_cpu, "repeat": len(walls),
              "cells_found": found, "build_seconds": build_s}

    ratios = {
        "query_speed_vs_libspatialindex": best / ours["queries"]["seconds"],
        "query_speed_vs_libspatialindex_cpu": best_cpu / ours["queries"]["cpu_seconds"],
    }
    for k, suffix in enumerate(("", "_ray_casting")[:len(octo)]):
        o, p = ours["insert"][k], octo[k]
        ratios["insert_rate_vs_octomap" + suffix] = o["points_per_second"] / p["points_per_second"]
        ratios["insert_rate_vs_octomap" + suffix + "_cpu"] = o["points_per_cpu_second"] / p["points_per_cpu_second"]
        ratios["memory_vs_octomap" + suffix] = o["memory"]["total_bytes"] / p["memory_bytes"]
    result = {"srtree": ours, "octomap": octo, "libspatialindex": peer_q, "ratios": ratios,
              "queries_agree": found == ours["queries"]["cells_found"]}
    if args.json:
        print(json.dumps(result, indent=2))
        return
    print(f"{n} points in {len(scans)} scans, {r} m cells")
    print(f"{'insertion':<28} {'SRTree':>14} {'OctoMap':>14} {'ratio':>8}")
    for k, name in enumerate(("no ray casting", "ray casting")[:len(octo)]):
        o, p = ours["insert"][k], octo[k]
        print(f"{'  rate, ' + name:<28} {o['points_per_second'] / 1e6:>10.2f} M/s {p['points_per_second'] / 1e6:>10.2f} M/s "
              f"{o['points_per_second'] / p['points_per_second']:>7.2f}×")
        print(f"{'  rate per CPU s, ' + name:<28} {o['points_per_cpu_second'] / 1e6:>10.2f} M/s {p['points_per_cpu_second'] / 1e6:>10.2f} M/s "
              f"{o['points_per_cpu_second'] / p['points_per_cpu_second']:>7.2f}×")
        print(f"{'  memory, ' + name:<28} {o['memory']['total_bytes'] / 1e6:>11.1f} MB {p['memory_bytes'] / 1e6:>11.1f} MB "
              f"{o['memory']['total_bytes'] / p['memory_bytes']:>7.2f}×")
        print(f"{'  cells / leaves, ' + name:<28} {o['occupied_cells']:>14} {p['leaf_nodes']:>14}")
        print(f"{'  RSS growth, ' + name:<28} {o['rss_growth_bytes'] / 1e6:>11.1f} MB {p['rss_growth_bytes'] / 1e6:>11.1f} MB")
    q = ours["queries"]
    print(f"box queries ({q['boxes']} boxes, median of {len(walls)} runs): SRTree {q['seconds'] * 1e3:.1f} ms "
          f"({q['cpu_seconds'] * 1e3:.1f} ms CPU), libspatialindex {best * 1e3:.1f} ms ({best_cpu * 1e3:.1f} ms CPU) "
          f"→ SRTree {best / q['seconds']:.2f}× as fast ({best_cpu / q['cpu_seconds']:.2f}× in CPU time); cells found "
          f"{q['cells_found']} vs {found} ({'equal' if found == q['cells_found'] else 'DIFFERENT'})")


if __name__ == "__main__":
    main()
