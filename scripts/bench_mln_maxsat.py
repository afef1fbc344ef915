#!/usr/bin/env python3
"""Exact optimum of urbansem's ground MLN problems by RC2 (PyPI python-sat), beside urbansem.

For each benchmark set: `urbansem mln infer --export-wcnf` writes the ground problem as
weighted partial MaxSAT and solves it (QSSR + tabu); RC2 then solves the WCNF in a child
process with a time limit (default 600 s, the issue's limit), and the optimum is mapped back
to our cost with the offset written in the WCNF header. Prints one line per set (or --json).

    python3 scripts/bench_mln_maxsat.py [--urbansem target/release/urbansem] [--timeout 600]
        [--sets lp,rc,kb,er,fs,neg-fs,id] [--data ../shared/data/mln] [--json]

Installs python-sat with pip if it is missing.
"""
import argparse
import json
import multiprocessing as mp
import os
import re
import subprocess
import sys
import time

SETS = {
    "lp": ("lp/rockit", False),
    "rc": ("rc/rockit", False),
    "kb": ("kb/mlcnn", False),
    "er": ("er/rockit", False),
    "fs": ("fs", True),
    "neg-fs": ("neg-fs", True),
    "id": ("id", True),
}


def ensure_pysat():
    try:
        import pysat  # noqa: F401
    except ImportError:
        subprocess.check_call([sys.executable, "-m", "pip", "install", "--user", "python-sat"],
                              stdout=sys.stderr)


def rc2_child(path, queue):
    from pysat.examples.rc2 import RC2
    from pysat.formula import WCNF
    wcnf = WCNF(from_file=path)
    with RC2(wcnf) as rc2:
        model = rc2.compute()
        queue.put(None if model is None else rc2.cost)


def rc2_optimum(path, timeout_s):
    queue = mp.Queue()
    child = mp.Process(target=rc2_child, args=(path, queue))
    t0 = time.time()
    child.start()
    child.join(timeout_s)
    if child.is_alive():
        child.terminate()
        child.join()
        return None, time.time() - t0
    return (queue.get() if not queue.empty() else None), time.time() - t0


def header(path):
    scale, offset = None, None
    with open(path) as f:
        for line in f:
            if not line.startswith("c"):
                break
            m = re.match(r"c cost = optimum / (\S+) ([+-]\S+)", line)
            if m:
                scale, offset = float(m.group(1)), float(m.group(2))
    return scale, offset


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--urbansem", default="target/release/urbansem")
    ap.add_argument("--data", default="../shared/data/mln")
    ap.add_argument("--work", default="target/bench-data/mln")
    ap.add_argument("--sets", default="lp,rc,kb,er,fs,neg-fs,id")
    ap.add_argument("--timeout", type=float, default=600.0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    ensure_pysat()
    os.makedirs(args.work, exist_ok=True)
    rows = []
    for name in args.sets.split(","):
        rel, generated = SETS[name]
        if generated:
            d = os.path.join(args.work, rel)
            subprocess.check_call([args.urbansem, "mln", "generate", name, "--out", d],
                                  stdout=subprocess.DEVNULL)
        else:
            d = os.path.join(args.data, rel)
        wcnf = os.path.join(args.work, name + ".wcnf")
        out = subprocess.check_output([
            args.urbansem, "mln", "infer", "-i", os.path.join(d, "prog.mln"),
            "-e", os.path.join(d, "evidence.db"), "--query-file", os.path.join(d, "query.db"),
            "--export-wcnf", wcnf, "--json"], stderr=subprocess.DEVNULL)
        ours = json.loads(out)
        scale, offset = header(wcnf)
        optimum, seconds = rc2_optimum(wcnf, args.timeout)
        exact = None if optimum is None else optimum / scale + offset
        row = {
            "set": name,
            "urbansem_cost": ours["cost"],
            "urbansem_lower_bound": ours["lower_bound"],
            "urbansem_seconds": ours["seconds"]["total"],
            "rc2_cost": exact,
            "rc2_seconds": seconds,
            "rc2_finished": optimum is not None,
        }
        rows.append(row)
        if not args.json:
            print(f"{name:7} urbansem {ours['cost']:.4f} in {ours['seconds']['total']:.2f} s | "
                  + (f"RC2 optimum {exact:.4f} in {seconds:.1f} s" if exact is not None
                     else f"RC2 did not finish in {args.timeout:.0f} s"), flush=True)
    if args.json:
        print(json.dumps({"sets": rows}, indent=2))


if __name__ == "__main__":
    main()
