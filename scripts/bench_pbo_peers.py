#!/usr/bin/env python3
"""Peer side of `urbansem bench pbo`: times Kolmogorov's QPBO (PyPI thinqpbo) and
Boykov-Kolmogorov max-flow (PyPI PyMaxflow) on the instances urbansem wrote.

Instance format (little-endian, see pbo::instances::QuadraticInstance::write_raw):
8 bytes b"PBOQUAD1", u64 n, u64 m, n x (i32 E0, i32 E1), m x (i32 i, i32 j, i32 E00, E01, E10, E11).

For every instance and repetition the peer is built from scratch and solved; the script
reports the fastest build+solve and the fastest solve alone (wall clock, and the solve's
thread CPU time, which a loaded machine disturbs less), plus what is needed to check
urbansem's answer exactly: the energy of the QPBO labelling (unlabelled variables as 0),
the number of labelled variables, twice the roof-dual lower bound, and for max-flow the
flow value and the number of nodes on the sink side. Results go to --json-out.
"""

import argparse
import importlib
import json
import subprocess
import sys
import time

import numpy as np

MAGIC = b"PBOQUAD1"
CHUNK = 1 << 20


def ensure(module, package):
    """Imports `module`, installing `package` with pip first if it is missing."""
    try:
        mod = importlib.import_module(module)
        print(f"peer {package}: already installed", flush=True)
        return mod
    except ImportError:
        print(f"peer {package}: not found, installing with pip install {package}", flush=True)
        subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", package])
        importlib.invalidate_caches()
        return importlib.import_module(module)


def load(path):
    with open(path, "rb") as f:
        magic = f.read(8)
        if magic != MAGIC:
            raise SystemExit(f"{path}: bad magic {magic!r}, expected {MAGIC!r}")
        n, m = np.frombuffer(f.read(16), dtype="<u8")
        n, m = int(n), int(m)
        unary = np.frombuffer(f.read(8 * n), dtype="<i4").reshape(n, 2)
        pairs = np.frombuffer(f.read(24 * m), dtype="<i4").reshape(m, 6)
    if unary.shape[0] != n or pairs.shape[0] != m:
        raise SystemExit(f"{path}: truncated (n={n}, m={m})")
    return n, unary, pairs


def run_qpbo(thinqpbo, n, unary, pairs):
    t0 = time.perf_counter()
    q = thinqpbo.QPBOInt(n, pairs.shape[0])
    q.add_node(n)
    add_u = q.add_unary_term
    for start in range(0, n, CHUNK):
        chunk = unary[start:start + CHUNK].tolist()
        for k, (e0, e1) in enumerate(chunk):
            add_u(start + k, e0, e1)
    add_p = q.add_pairwise_term
    for start in range(0, pairs.shape[0], CHUNK):
        for i, j, a, b, c, d in pairs[start:start + CHUNK].tolist():
            add_p(i, j, a, b, c, d)
    t1 = time.perf_counter()
    c1 = time.thread_time()
    q.solve()
    c2 = time.thread_time()
    t2 = time.perf_counter()
    return q, t2 - t0, t2 - t1, c2 - c1


def qpbo_answer(q, n):
    get = q.get_label
    labelled = sum(1 for i in range(n) if get(i) >= 0)
    twice_energy = int(q.compute_twice_energy(0))
    return {
        "energy": twice_energy // 2,
        "twice_energy": twice_energy,
        "labelled": labelled,
        "twice_lower_bound": int(q.compute_twice_lower_bound()),
    }


def run_maxflow(maxflow, n, unary, pairs):
    t0 = time.perf_counter()
    g = maxflow.Graph[int](n, pairs.shape[0])
    nodes = g.add_nodes(n)
    g.add_grid_tedges(nodes, np.ascontiguousarray(unary[:, 1]), np.ascontiguousarray(unary[:, 0]))
    g.add_edges(
        np.ascontiguousarray(pairs[:, 0]),
        np.ascontiguousarray(pairs[:, 1]),
        np.ascontiguousarray(pairs[:, 3]),
        np.ascontiguousarray(pairs[:, 4]),
    )
    t1 = time.perf_counter()
    c1 = time.thread_time()
    flow = g.maxflow()
    c2 = time.thread_time()
    t2 = time.perf_counter()
    sink = int(np.count_nonzero(g.get_grid_segments(nodes)))
    return {"flow": int(flow), "sink_nodes": sink}, t2 - t0, t2 - t1, c2 - c1


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("instances", nargs="+", help="instance .bin files")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--json-out", required=True)
    args = ap.parse_args()

    thinqpbo = ensure("thinqpbo", "thinqpbo")
    maxflow = ensure("maxflow", "PyMaxflow")

    results = {}
    for path in args.instances:
        n, unary, pairs = load(path)
        cut_form = bool(
            np.all(pairs[:, 2] == 0) and np.all(pairs[:, 5] == 0)
            and np.all(pairs[:, 3] >= 0) and np.all(pairs[:, 4] >= 0)
        )
        entry = {"n": n, "m": int(pairs.shape[0])}
        best_total, best_solve, best_cpu, answer = float("inf"), float("inf"), float("inf"), None
        for _ in range(max(1, args.repeat)):
            q, total, solve, cpu = run_qpbo(thinqpbo, n, unary, pairs)
            best_total, best_solve = min(best_total, total), min(best_solve, solve)
            best_cpu = min(best_cpu, cpu)
            answer = qpbo_answer(q, n)
            del q
        entry["qpbo"] = dict(answer, total_s=best_total, solve_s=best_solve, solve_cpu_s=best_cpu)
        print(
            f"thinqpbo  {path}: build+solve {best_total:.3f} s, solve {best_solve:.3f} s "
            f"(CPU {best_cpu:.3f} s)",
            flush=True,
        )
        if cut_form:
            best_total, best_solve, best_cpu = float("inf"), float("inf"), float("inf")
            for _ in range(max(1, args.repeat)):
                answer, total, solve, cpu = run_maxflow(maxflow, n, unary, pairs)
                best_total, best_solve = min(best_total, total), min(best_solve, solve)
                best_cpu = min(best_cpu, cpu)
            entry["maxflow"] = dict(answer, total_s=best_total, solve_s=best_solve, solve_cpu_s=best_cpu)
            print(
                f"PyMaxflow {path}: build+solve {best_total:.3f} s, solve {best_solve:.3f} s "
                f"(CPU {best_cpu:.3f} s)",
                flush=True,
            )
        results[path] = entry
    with open(args.json_out, "w") as f:
        json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
