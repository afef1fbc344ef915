#!/usr/bin/env python3
"""Side-by-side check of `urbansem osm info` against independent OSM readers.

For every file in ../shared/data/osm (or the files given on the command line):
  * counts: buildings (closed ways with building=* other than "no", plus type=multipolygon
    relations with building=* other than "no") and highway ways (ways with highway=*), from
    pyosmium, next to urbansem's `--json` output;
  * time: wall-clock of `osmium fileinfo -e FILE` (osmium-tool) and of `urbansem osm info
    FILE --json`, best of N runs each, interleaved, and their ratio.
Installs its peers itself (apt osmium-tool, pip osmium) when they are missing.
Exit status 1 if a count differs.
"""
import json, os, shutil, subprocess, sys, time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
DATA = os.path.join(ROOT, "..", "shared", "data", "osm")
RUNS = int(os.environ.get("RUNS", "7"))


def ensure_peers():
    if shutil.which("osmium") is None:
        subprocess.run(["apt-get", "install", "-y", "osmium-tool"], check=True, stdout=subprocess.DEVNULL)
    try:
        import osmium  # noqa: F401
    except ImportError:
        subprocess.run([sys.executable, "-m", "pip", "install", "-q", "osmium"], check=True)


def pyosmium_counts(path):
    import osmium

    class Counter(osmium.SimpleHandler):
        def __init__(self):
            super().__init__()
            self.building_ways = self.building_relations = self.highway_ways = 0

        def way(self, w):
            b = w.tags.get("building")
            if b is not None and b != "no" and len(w.nodes) >= 4 and w.nodes[0].ref == w.nodes[-1].ref:
                self.building_ways += 1
            if "highway" in w.tags:
                self.highway_ways += 1

        def relation(self, r):
            b = r.tags.get("building")
            if r.tags.get("type") == "multipolygon" and b is not None and b != "no":
                self.building_relations += 1

    c = Counter()
    c.apply_file(path)
    return c


def best_times(cmd_a, cmd_b):
    """Best wall-clock of RUNS runs of each command, alternating a, b so both see the same load."""
    best = [float("inf"), float("inf")]
    for _ in range(RUNS):
        for k, cmd in enumerate((cmd_a, cmd_b)):
            t0 = time.perf_counter()
            subprocess.run(cmd, check=True, stdout=subprocess.DEVNULL)
            best[k] = min(best[k], time.perf_counter() - t0)
    return best


def main():
    ensure_peers()
    binary = os.path.join(ROOT, "target", "release", "urbansem")
    if os.environ.get("URBANSEM"):
        binary = os.environ["URBANSEM"]
    elif not os.path.exists(binary):
        subprocess.run(["cargo", "build", "--release", "-p", "urbansem"], cwd=ROOT, check=True)
    files = sys.argv[1:] or sorted(os.path.join(DATA, f) for f in os.listdir(DATA) if f.endswith((".osm", ".pbf")))
    ok = True
    print(f"{'file':28} {'buildings ours/pyosmium':>24} {'highway ways ours/pyosmium':>27} {'osmium fileinfo -e':>19} {'urbansem osm info':>18} {'ratio':>6}")
    for path in files:
        ours = json.loads(subprocess.run([binary, "osm", "info", path, "--json"], check=True, capture_output=True, text=True).stdout)
        peer = pyosmium_counts(path)
        peer_b = peer.building_ways + peer.building_relations
        same = ours["buildings"] == peer_b and ours["highway_ways"] == peer.highway_ways
        ok &= same
        t_peer, t_ours = best_times(["osmium", "fileinfo", "-e", path], [binary, "osm", "info", path, "--json"])
        print(
            f"{os.path.basename(path):28} {ours['buildings']:>11} / {peer_b:<10} {ours['highway_ways']:>12} / {peer.highway_ways:<12}"
            f" {t_peer:>17.3f}s {t_ours:>16.3f}s {t_ours / t_peer:>6.2f}{'' if same else '  COUNT MISMATCH'}"
        )
    sys.exit(0 if ok else 1)


if __name__ == "__main__":
    main()
