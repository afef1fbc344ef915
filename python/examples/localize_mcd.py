"""Localize a real MCD scan on the KTH campus OpenStreetMap map, without GPS or prior.

Usage: python localize_mcd.py [OUT.png] [--data ../shared/data] [--index 0]

Reads one LiDAR scan of the MCD `kth_day_06` sequence with NumPy, levels it with the
sequence's pose (roll and pitch removed, as `urbansem localize eval` does), localizes it on
the building outlines of the whole campus and plots the map with the best candidates
(matplotlib, optional).
"""

import argparse
import math
from pathlib import Path

import numpy as np

import urbansem

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("out", nargs="?", default="localize_mcd.png", help="PNG to write")
parser.add_argument("--data", default=Path(__file__).resolve().parents[3] / "shared" / "data")
parser.add_argument("--index", type=int, default=0, help="scan of the sequence (0–29)")
args = parser.parse_args()
data = Path(args.data)
mcd = data / "lidar" / "mcd_kth_day_06"

# 1. The map, prepared once (distance transforms of the outlines): reuse it for every scan.
osm = urbansem.OsmMap.load(data / "osm" / "kth_campus_stockholm.osm")
localizer = urbansem.Localizer(osm, sensor="auto")
print(localizer)

# 2. A raw scan: KITTI-style float32 x, y, z, intensity in the tilted sensor frame.
frame = urbansem.localize.mcd_frames(mcd)[args.index]
raw = np.fromfile(mcd / "lidar_bin" / f"{frame:010}.bin", dtype=np.float32).reshape(-1, 4)
# The localizer needs a gravity-levelled scan: rotate by the sequence's levelling rotation
# (from pose_inW.csv and the calibration); the true pose comes along for the comparison.
mcd_scan = urbansem.localize.load_mcd_scan(mcd, osm, frame)
points = raw[:, :3].astype(np.float64) @ mcd_scan.levelling.T

# 3. Localize: candidates ranked by the reverse chamfer cost, in metres and in WGS84.
result = localizer.localize(points, top=5)
print(f"{len(points)} points, {result.segments} wall segments, sensor {result.sensor.profile}")
tx, ty, tyaw = mcd_scan.truth
for c in result.candidates:
    err = math.hypot(c.x - tx, c.y - ty)
    print(
        f"#{c.rank}: x {c.x:8.2f} y {c.y:8.2f} yaw {math.degrees(c.yaw_grid):7.2f}° "
        f"({c.lat:.6f}, {c.lon:.6f}) cost {c.cost:.3f} m, {err:.1f} m from the truth"
    )

# 4. The picture: building outlines, streets, the scan at the best pose, the candidates.
try:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
except ImportError:
    print("matplotlib is not installed (pip install matplotlib): no plot")
else:
    fig, ax = plt.subplots(figsize=(8, 8))
    for ring in osm.buildings:
        closed = np.vstack([ring, ring[:1]])
        ax.plot(closed[:, 0], closed[:, 1], color="0.4", lw=0.8)
    for a_x, a_y, b_x, b_y in osm.segments:
        ax.plot([a_x, b_x], [a_y, b_y], color="0.85", lw=0.6, zorder=0)
    best = result.best
    if best is not None:
        segs, _ = localizer.scan_segments(points)
        c, s = math.cos(best.yaw_grid), math.sin(best.yaw_grid)
        for a_x, a_y, b_x, b_y in segs:
            xs = [best.x + c * a_x - s * a_y, best.x + c * b_x - s * b_y]
            ys = [best.y + s * a_x + c * a_y, best.y + s * b_x + c * b_y]
            ax.plot(xs, ys, color="tab:red", lw=2)
    for cand in result.candidates:
        ax.plot(cand.x, cand.y, "o", color="tab:blue", ms=4)
        ax.annotate(str(cand.rank), (cand.x, cand.y), fontsize=8)
    ax.plot(tx, ty, "x", color="tab:green", ms=10, mew=2, label="true pose")
    ax.set_xlim(tx - 150, tx + 150)
    ax.set_ylim(ty - 150, ty + 150)
    ax.set_aspect("equal")
    ax.set_xlabel("east (m, map frame)")
    ax.set_ylabel("north (m)")
    ax.set_title(f"MCD kth_day_06 scan {frame}: walls (red) at the best candidate")
    ax.legend(loc="upper right")
    fig.savefig(args.out, dpi=120, bbox_inches="tight")
    print(f"wrote {args.out}")
