#!/usr/bin/env python3
"""Side-by-side: urbansem's SMO SVM (crates/streets/src/svm.rs) vs libsvm on the same bins.

Usage: scripts/bench_streets_svm.py DATASET_DIR [--train 20000] [--test 20000] [--c 4]
       [--bin target/release/urbansem]

Runs `urbansem streets bench-svm` (which trains our SVM, predicts, and exports the same
standardised train/test bins in libsvm format), then trains libsvm (PyPI `libsvm-official`,
pip-installed here if missing) with the same C, gamma, eps (0.001) and cache size, and prints
accuracy, training time and peak memory of both with ratios.
"""
import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time


def ensure_libsvm():
    try:
        import libsvm  # noqa: F401
    except ImportError:
        subprocess.check_call([sys.executable, "-m", "pip", "install", "--quiet", "libsvm-official"])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("dataset")
    ap.add_argument("--train", type=int, default=20000)
    ap.add_argument("--test", type=int, default=20000)
    ap.add_argument("--c", type=float, default=4.0)
    ap.add_argument("--cache-mb", type=int, default=100)
    ap.add_argument("--bin", default="target/release/urbansem")
    args = ap.parse_args()
    ensure_libsvm()
    from libsvm.svmutil import svm_read_problem, svm_train, svm_predict

    out = tempfile.mkdtemp(prefix="bench_streets_svm_")
    cmd = [args.bin, "streets", "bench-svm", "--dataset", args.dataset, "--train", str(args.train),
           "--test", str(args.test), "--export", out, "--svm-c", str(args.c),
           "--cache-mb", str(args.cache_mb), "--json"]
    ours = json.loads(subprocess.check_output(cmd).decode().strip().splitlines()[-1])

    ytr, xtr = svm_read_problem(os.path.join(out, "train.svm"))
    yte, xte = svm_read_problem(os.path.join(out, "test.svm"))
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    opts = "-s 0 -t 2 -c {} -g {} -e 0.001 -m {} -q".format(args.c, ours["gamma"], args.cache_mb)
    t = time.perf_counter()
    model = svm_train(ytr, xtr, opts)
    train_s = time.perf_counter() - t
    t = time.perf_counter()
    pred, (acc, _, _), _ = svm_predict(yte, xte, model, "-q")
    predict_s = time.perf_counter() - t
    rss1 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024
    theirs = {
        "train_seconds": train_s, "predict_seconds": predict_s, "accuracy": acc / 100.0,
        "support_vectors": model.get_nr_sv(), "peak_rss_bytes": rss1,
        "rss_growth_bytes": rss1 - rss0,
    }
    print(f"bins: {args.train} train, {args.test} test, {ours['features']} features, "
          f"C={args.c}, gamma={ours['gamma']:.4f}, eps=0.001, cache {args.cache_mb} MiB; "
          f"urbansem on {ours['threads']} threads, libsvm single-threaded")
    print(f"{'':26}{'urbansem':>12}{'libsvm':>12}{'ratio':>10}")
    rows = [("train s", ours["train_seconds"], theirs["train_seconds"]),
            ("predict s", ours["predict_seconds"], theirs["predict_seconds"]),
            ("accuracy", ours["accuracy"], theirs["accuracy"]),
            ("support vectors", ours["support_vectors"], theirs["support_vectors"]),
            ("peak RSS MiB (training)", (ours["peak_rss_bytes"] or 0) / 2**20, theirs["peak_rss_bytes"] / 2**20)]
    for name, a, b in rows:
        ratio = a / b if b else float("nan")
        print(f"{name:26}{a:12.4f}{b:12.4f}{ratio:10.3f}")
    diff = abs(ours["accuracy"] - theirs["accuracy"])
    print(f"accuracy difference {100 * diff:.2f} % (target ≤ 0.5 %); "
          f"training time ratio {ours['train_seconds'] / theirs['train_seconds']:.3f} (target ≤ 1)")


if __name__ == "__main__":
    main()
