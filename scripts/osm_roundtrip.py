#!/usr/bin/env python3
"""OSM XML written by urbansem, read back by osmium (issue 16, item 7: format conformance).

For each seed, writes a city with `urbansem sim city --seed S --out FILE`, then reads FILE
  * with pyosmium (libosmium's XML reader): nodes, ways, relations, buildings (closed ways
    with building=* other than "no", plus type=multipolygon relations with building=*),
    highway ways, and the building areas libosmium's assembler builds (outer and inner
    rings);
  * with Python's own XML parser: every tag key and value, which must equal pyosmium's;
  * with `urbansem osm info FILE --json`: the same counts, and the building outlines
    urbansem assembles (one per outer ring),
and prints one line per seed. Exit status 1 on any difference.

Usage: python3 scripts/osm_roundtrip.py [--binary target/release/urbansem] [--seeds 1 2 3]
Installs pyosmium (pip install osmium) when it is missing.
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET


def ensure_pyosmium():
    try:
        import osmium  # noqa: F401
    except ImportError:
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "osmium"], check=True)


def osmium_read(path):
    import osmium

    class Reader(osmium.SimpleHandler):
        def __init__(self):
            super().__init__()
            self.nodes = self.ways = self.relations = 0
            self.building_ways = self.building_relations = self.highway_ways = 0
            self.outer_rings = self.inner_rings = 0
            self.tags = []

        def node(self, n):
            self.nodes += 1

        def way(self, w):
            self.ways += 1
            self.tags.extend((t.k, t.v) for t in w.tags)
            b = w.tags.get("building")
            if b is not None and b != "no" and len(w.nodes) >= 4 and w.nodes[0].ref == w.nodes[-1].ref:
                self.building_ways += 1
            if "highway" in w.tags:
                self.highway_ways += 1

        def relation(self, r):
            self.relations += 1
            self.tags.extend((t.k, t.v) for t in r.tags)
            b = r.tags.get("building")
            if r.tags.get("type") == "multipolygon" and b is not None and b != "no":
                self.building_relations += 1

        def area(self, a):
            b = a.tags.get("building")
            if b is not None and b != "no":
                for outer in a.outer_rings():
                    self.outer_rings += 1
                    self.inner_rings += sum(1 for _ in a.inner_rings(outer))

    reader = Reader()
    reader.apply_file(path, locations=True)
    return reader


def etree_tags(path):
    root = ET.parse(path).getroot()
    return [(t.get("k"), t.get("v")) for el in root if el.tag in ("way", "relation") for t in el.iter("tag")]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    here = os.path.dirname(os.path.abspath(__file__))
    parser.add_argument("--binary", default=os.path.join(here, "..", "target", "release", "urbansem"))
    parser.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    parser.add_argument("--size-m", type=float, default=1000.0)
    args = parser.parse_args()
    ensure_pyosmium()

    failed = False
    with tempfile.TemporaryDirectory() as tmp:
        for seed in args.seeds:
            path = os.path.join(tmp, f"city_{seed}.osm")
            subprocess.run(
                [args.binary, "sim", "city", "--seed", str(seed), "--size-m", str(args.size_m), "--out", path],
                check=True,
                stdout=subprocess.DEVNULL,
            )
            ours = json.loads(
                subprocess.run([args.binary, "osm", "info", path, "--json"], check=True, capture_output=True, text=True).stdout
            )
            peer = osmium_read(path)
            pairs = {
                "nodes": (ours["nodes"], peer.nodes),
                "ways": (ours["ways"], peer.ways),
                "relations": (ours["relations"], peer.relations),
                "buildings": (ours["buildings"], peer.building_ways + peer.building_relations),
                "highway_ways": (ours["highway_ways"], peer.highway_ways),
                "outlines/outer rings": (ours["building_outlines"], peer.outer_rings),
            }
            tags_equal = etree_tags(path) == peer.tags
            same = all(a == b for a, b in pairs.values()) and tags_equal
            failed |= not same
            print(
                f"seed {seed}: "
                + ", ".join(f"{k} {a}/{b}" for k, (a, b) in pairs.items())
                + f", holes (osmium) {peer.inner_rings}, {len(peer.tags)} tags "
                + ("equal" if tags_equal else "DIFFER")
                + (" -> same" if same else " -> DIFFERENT")
            )
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
