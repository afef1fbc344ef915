"""Render the semantic map the demo exports (`demo-out/semantic_map.ply` and `.mcap`) as a
viewer would show it: cells coloured by class (from the PLY, read with urbansem), object boxes
and relation lines (from the bag's `foxglove.SceneUpdate`, read with the `mcap` package).

Usage: python render_semantic_map.py [demo-out] [OUT.png]
"""

import json
import math
import sys
from pathlib import Path

import numpy as np

import urbansem

folder = Path(sys.argv[1] if len(sys.argv) > 1 else "demo-out")
out = sys.argv[2] if len(sys.argv) > 2 else "semantic_map.png"

cells = urbansem.read_cloud(folder / "semantic_map.ply")
boxes, lines = [], []
try:
    from mcap.reader import make_reader
except ImportError:
    print("pip install mcap to draw the object boxes and relations of semantic_map.mcap")
else:
    with open(folder / "semantic_map.mcap", "rb") as f:
        for schema, channel, message in make_reader(f).iter_messages():
            if schema.name == "foxglove.SceneUpdate":
                for entity in json.loads(message.data)["entities"]:
                    boxes += entity["cubes"]
                    lines += entity["lines"]

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

fig = plt.figure(figsize=(10, 7))
ax = fig.add_subplot(projection="3d")
xyz, rgb = cells["xyz"], cells["rgb"] / 255.0
keep = np.random.default_rng(0).permutation(len(xyz))[: 60_000]  # enough to see every class
ax.scatter(*xyz[keep].T, c=rgb[keep], s=0.3, depthshade=False)
for cube in boxes:
    p, s, q = cube["pose"]["position"], cube["size"], cube["pose"]["orientation"]
    yaw = 2 * math.atan2(q["z"], q["w"])
    c, si = math.cos(yaw), math.sin(yaw)
    corners = [(dx * s["x"] / 2, dy * s["y"] / 2) for dx, dy in ((-1, -1), (1, -1), (1, 1), (-1, 1), (-1, -1))]
    ring = np.array([(p["x"] + c * a - si * b, p["y"] + si * a + c * b) for a, b in corners])
    for z in (p["z"] - s["z"] / 2, p["z"] + s["z"] / 2):
        ax.plot(ring[:, 0], ring[:, 1], z, color="k", lw=0.5)
for line in lines:
    a, b = line["points"][0], line["points"][1]
    ax.plot([a["x"], b["x"]], [a["y"], b["y"]], [a["z"], b["z"]], color="orange", lw=0.6)
ax.set_xlabel("east (m)")
ax.set_ylabel("north (m)")
ax.set_zlabel("up (m)")
span = np.ptp(xyz, axis=0)
ax.set_box_aspect((span[0], span[1], max(span[2], 0.15 * span[0])))
ax.view_init(elev=35, azim=-60)
ax.set_title(f"semantic map: {len(xyz)} cells by class, {len(boxes)} objects, {len(lines)} relations")
fig.savefig(out, dpi=110, bbox_inches="tight")
print(f"wrote {out}")
