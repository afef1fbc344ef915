#!/usr/bin/env python3
"""Mutation check of every reader on the shared data (issue 16, "Done when", second line).

The claim it checks: no truncated, bit-flipped or header-inflated variant of any file in
../shared/data makes an urbansem command panic, hang past 10x its normal time, or use more
memory than 4x the file size plus the normal working set.

For every file under ../shared/data (or --data) it picks the command a user would run on it:

  point clouds (.pcd, KITTI/MCD .bin)   `cloud info FILE --json`
  per-point label files (gt_labels/*.bin) `cloud convert SCAN.bin OUT.ply --labels FILE --label-set S`
  OSM XML / PBF                          `osm info FILE --json`
  MLN programs, evidence, queries        `mln infer` on the file's set (the other files of the set
                                         stay original), MaxWalkSAT with 1000 flips on one chain so
                                         a run is mostly parsing and grounding
  MAP answers of other engines           `mln score --answer FILE` on their set
  IE facts of mfoilp, KB labels          `mln generate ie|kb3` (on a copy of the data folder)
  lidar poses and calibration            `map eval-labels --max-scans 1` (on a copy of lidar/)
  anything else                          skipped, with a counted reason

For each (file, command) it runs the original once (baseline wall time and peak RSS, from
os.wait4), then variants, each written under the file's own name so that extension-based format
detection still works:

  truncations   at 0 and 1 byte, at the header end -1/0/+1 (PCD `DATA` line, PLY `end_header`,
                the `<osm>` tag, the PBF OSMHeader blob), at 25, 50 and 99 % of the length
  bit flips     8 single-bit flips from a seeded generator (3 of them inside the header for formats
                with one); 4 for files over 5 MB
  inflations    each integer of the header replaced by 4294967295 and by 99999999999999, one field
                at a time: PCD SIZE/COUNT/WIDTH/HEIGHT/POINTS, PLY element counts, OPB
                `#variable=`, OSM XML ids/refs/version/uid/changeset, PBF blob header length,
                `datasize` and `raw_size`; the first numbers of text formats without a header
                (MLN weights, pose frame numbers); for binary arrays the first value
                (a KITTI x coordinate, a label id)

Verdicts:
  PASS          exit 0, 1 or 2, and stderr says neither "panicked" nor "internal error"
                (an exit 2 is also listed as suspicious: content errors must exit 1)
  FAIL-PANIC    exit 101, or "panicked" / "internal error" on stderr
  FAIL-HANG     still running after max(10 x baseline, 2 s): killed
  FAIL-MEMORY   peak RSS above 4 x file size + baseline RSS + slack (64 MB + 10 % of the
                baseline RSS: the same command on the same file varies by that much, e.g.
                1 094-1 160 MB for `mln infer` on pr/rockit, whose parallel grounding
                allocates in a different order each run), or an allocation refused by the
                address-space cap (--as-limit-gb) and aborted
  FAIL-CRASH    killed by another signal, or an exit code outside 0/1/2/101

Sets whose baseline takes longer than 5 s run a reduced plan (truncation at 0 and 50 %, two
flips). Failing variants are saved under target/mutate-shared/ (with the file name kept) and
every failure goes to target/mutate-shared.json with the command that reproduces it.

Usage:  python3 scripts/mutate_shared.py [--only SUBSTRING] [--max-variants N] [--seed S]
        [--binary PATH] [--out PATH] [--data DIR]
Standard library only; runs everything sequentially at nice 10.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import os
import random
import re
import resource
import shlex
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_DATA = (ROOT / ".." / "shared" / "data").resolve()
DEFAULT_BINARY = ROOT / "target" / "release" / "urbansem"

HUGE_VALUES = (4294967295, 99999999999999)
SLACK_MB = 64
# Share of the baseline RSS added to the slack: a run's peak RSS varies this much.
SLACK_SHARE = 0.10
HANG_FACTOR = 10
HANG_MIN_S = 2.0
MEMORY_FACTOR = 4
MEMORY_RULE = f"{MEMORY_FACTOR} x file size + baseline RSS + {SLACK_MB} MB + {SLACK_SHARE:.0%} of baseline RSS slack"
BIG_FILE_BYTES = 5 * 1024 * 1024
SLOW_BASELINE_S = 5.0
BASELINE_TIMEOUT_S = 300.0
VERDICTS = ("FAIL-PANIC", "FAIL-HANG", "FAIL-MEMORY", "FAIL-CRASH")


# --------------------------------------------------------------------------------------------
# What to run on each file
# --------------------------------------------------------------------------------------------

@dataclass
class Job:
    """One command over one file. `argv` holds {BIN}, {FILE} (the file or its variant),
    {ROOT} (the copy of `overlay` with the variant in place) and {OUT} (a scratch folder)."""
    fmt: str
    argv: list[str]
    header: str | None = None        # pcd, ply, osm-xml, osm-pbf, yaml-os-sensor, text, none
    values: str = "text"             # which inflation family: pcd, ply, opb, osm-xml, osm-pbf,
                                     # text, f32-first, u32-labels, none
    overlay: str | None = None       # folder (relative to data) copied as {ROOT}
    note: str = ""


# Every MLN set: folder, program, evidence files, query file, -q predicates.
MLN_SETS = [
    ("smoke/tuffy", "prog.mln", ["evidence.db"], "query.db", None),
    ("smoke/alchemy2", "model.mln", ["evidence.db"], None, "Cancer"),
    ("smoke/lomrf", "smoking.mln", ["smoking-train.db"], None, "Cancer"),
    ("smoke/lomrf", "smoking.mln", ["smoking-test.db"], None, "Cancer"),
    ("smoke/pracmln", "smoking.mln", ["smoking-train.db"], None, "Cancer"),
    ("smoke/pracmln", "wts.pybpll.smoking-train-smoking.mln", ["smoking-test.db"], None, "Cancer"),
    ("smoke/pracmln", "smoking.mln", ["smoking-test-smaller.db"], None, "Smokes"),
    ("lp/tuffy", "prog.mln", ["evidence.db"], "query.db", None),
    ("lp/rockit", "prog.mln", ["evidence.db"], "query.db", None),
    ("rc/tuffy-class", "prog.mln", ["evidence.db"], "query.db", None),
    ("rc/tuffy-rc1000", "prog.mln", ["evidence.db"], "query.db", None),
    ("rc/rockit", "prog.mln", ["evidence.db"], "query.db", None),
    ("kb/mlcnn", "prog.mln", ["evidence.db"], "query.db", None),
    ("kb/mlcnn", "prog_cw.mln", ["evidence.db"], "query.db", None),
    ("kb/mlcnn", "prog.mln", ["test_original.txt"], "query.db", None),
    ("kb/alchemy2-toy", "webkb.mln", [], None, "PageClass"),
    ("er/rockit", "prog.mln", ["evidence.db"], "query.db", None),
    ("pr/rockit", "prog.mln", ["evidence.db"], "query.db", None),
    # IE's evidence is not in the shared data; `mln generate ie` rebuilds it from mfoilp's facts.
    ("ie/tuffy", "prog.mln", ["@IE_EVIDENCE"], "query.db", None),
    ("ie/rockit", "prog.mln", [], "query.db", None),
]

# Other engines' MAP answers, scored on a set (index into MLN_SETS by folder and program).
MLN_ANSWERS = {
    "lp/reference_outputs/tuffy_map_output_from_xeggora.db": ("lp/tuffy", "prog.mln"),
    "er/reference_outputs/tuffy_map_output_from_xeggora.db": ("er/rockit", "prog.mln"),
    "kb/reference_outputs/tuffy_map_output_from_mlcnn.txt": ("kb/mlcnn", "prog.mln"),
    "kb/mlcnn/labels.db": ("kb/mlcnn", "prog.mln"),
    "ie/reference_outputs/tuffy_map_output_from_xeggora.db": ("ie/tuffy", "prog.mln"),
}

MLN_SKIPS = {
    "pr/reference_outputs/tuffy_map_output_from_xeggora.db":
        "MAP answer of a set whose grounding stops at the 20M-groundings limit before "
        "`mln score` reads the answer",
    "ie/partial-evidence-mfoilp/weights":
        "mfoilp field weights: no urbansem command reads them (`mln generate ie` reads tokens, "
        "similartitles, jntinfcandidates)",
    "kb/mlcnn/query_preds.txt":
        "a list of predicate names for -q, not a file any command reads",
}

MLN_INFER_TAIL = ["--method", "maxwalksat", "--flips", "1000", "--chains", "1", "--json"]


def mln_set_argv(data: Path, s, mutated: str | None, ie_evidence: Path | None,
                 command: str = "infer", answer: str | None = None) -> list[str] | None:
    """argv of `mln infer`/`mln score` on set `s`, with {FILE} in place of the file `mutated`
    (a path relative to the set folder or to data)."""
    folder, prog, evidence, query, preds = s

    def path(name: str) -> str:
        rel = f"{folder}/{name}"
        return "{FILE}" if rel == mutated else str(data / "mln" / rel)

    argv = ["{BIN}", "mln", command, "-i", path(prog)]
    ev = []
    for e in evidence:
        if e == "@IE_EVIDENCE":
            if ie_evidence is None:
                return None
            ev.append(str(ie_evidence))
        else:
            ev.append(path(e))
    if ev:
        argv += ["-e", ",".join(ev)]
    if query:
        argv += ["--query-file", path(query)]
    if preds:
        argv += ["-q", preds]
    if command == "infer":
        argv += MLN_INFER_TAIL
    else:
        answer_arg = "{FILE}" if answer == mutated else str(data / "mln" / answer)
        argv += ["--answer", answer_arg, "--json"]
    return argv


def plan_file(data: Path, rel: str, ie_evidence: Path | None) -> list[Job] | str:
    """The jobs for one file (path relative to data), or the reason it is skipped."""
    name = rel.rsplit("/", 1)[-1]
    parts = rel.split("/")
    if name.startswith("SOURCES") or name.startswith("SHA256SUMS"):
        return "documentation (sources, checksums)"
    if rel.startswith("pcd-pcl/") and name.endswith(".pcd"):
        return [Job("pcd", ["{BIN}", "cloud", "info", "{FILE}", "--json"], header="pcd", values="pcd")]
    if name.endswith(".ply"):
        return [Job("ply", ["{BIN}", "cloud", "info", "{FILE}", "--json"], header="ply", values="ply")]
    if name.endswith(".las") or name.endswith(".laz"):
        return [Job("las/laz", ["{BIN}", "cloud", "info", "{FILE}", "--json"], values="none")]
    if name.endswith(".opb"):
        return [Job("opb", ["{BIN}", "pbo", "solve", "{FILE}", "--json"], header="text", values="opb")]
    if name.endswith(".osm.pbf"):
        return [Job("osm-pbf", ["{BIN}", "osm", "info", "{FILE}", "--json"], header="osm-pbf",
                    values="osm-pbf")]
    if name.endswith(".osm"):
        fmt = "osm-xml (osm-testdata)" if rel.startswith("osm-testdata/") else "osm-xml"
        return [Job(fmt, ["{BIN}", "osm", "info", "{FILE}", "--json"], header="osm-xml",
                    values="osm-xml")]
    if rel.startswith("osm-testdata/") and name == "test.json":
        return ("osm-testdata expected areas: read only by the test "
                "crates/geodata/tests/osm_testdata.rs, no command reads it")
    if parts[0] == "lidar":
        return plan_lidar(data, rel, parts, name)
    if parts[0] == "mln":
        return plan_mln(data, rel[len("mln/"):], ie_evidence)
    return "no urbansem reader for this file"


def plan_lidar(data: Path, rel: str, parts: list[str], name: str) -> list[Job] | str:
    seq = parts[1] if len(parts) > 1 else ""
    if seq.startswith("kitti_raw"):
        if name.endswith(".bin") and parts[2] == "velodyne_points":
            return [Job("kitti .bin points", ["{BIN}", "cloud", "info", "{FILE}", "--json"],
                        values="f32-first")]
        return ("KITTI raw OXTS / calibration / timestamps: no command reads them "
                "(geodata::datasets::kitti_raw is used by tests only)")
    label_set = "kitti360" if seq.startswith("kitti360") else "mcd" if seq.startswith("mcd") else None
    if name.endswith(".bin") and parts[2] in ("velodyne_points", "lidar_bin"):
        return [Job("kitti .bin points", ["{BIN}", "cloud", "info", "{FILE}", "--json"],
                    values="f32-first")]
    if name.endswith(".bin") and parts[2] == "gt_labels" and label_set:
        scans = "velodyne_points" if label_set == "kitti360" else "lidar_bin"
        scan = data / "lidar" / seq / scans / name
        if not scan.exists():
            return f"label file without its scan {scan}"
        return [Job("label .bin (uint32)",
                    ["{BIN}", "cloud", "convert", str(scan), "{OUT}/out.ply", "--labels", "{FILE}",
                     "--label-set", label_set],
                    values="u32-labels")]
    eval_labels = ["{BIN}", "map", "eval-labels", "--data", "{ROOT}", "--max-scans", "1", "--json"]
    if name.startswith("velodyne_poses") and name.endswith(".txt"):
        return [Job("poses (KITTI-360 txt)", eval_labels, overlay="lidar")]
    if name == "pose_inW.csv":
        return [Job("poses (MCD csv)", eval_labels, overlay="lidar")]
    if name.endswith(".yaml"):
        return [Job("calibration (MCD yaml)", eval_labels, header="yaml-os-sensor", overlay="lidar")]
    return "no urbansem reader for this lidar file"


def plan_mln(data: Path, rel: str, ie_evidence: Path | None) -> list[Job] | str:
    if rel in MLN_SKIPS:
        return MLN_SKIPS[rel]
    if "/reference_outputs/" in f"/{rel}" and rel not in MLN_ANSWERS:
        return "reference run logs and result tables of other engines: no command reads them"
    jobs: list[Job] = []
    if rel.startswith("ie/partial-evidence-mfoilp/"):
        jobs.append(Job("mfoilp facts", ["{BIN}", "mln", "generate", "ie", "--data", "{ROOT}",
                                         "--out", "{OUT}/gen"], overlay="mln"))
    if rel in MLN_ANSWERS:
        folder, prog = MLN_ANSWERS[rel]
        s = next(x for x in MLN_SETS if x[0] == folder and x[1] == prog)
        argv = mln_set_argv(data, s, rel, ie_evidence, command="score", answer=rel)
        if argv is None:
            return "the answer's set needs the rebuilt IE evidence, which could not be generated"
        jobs.append(Job("mln answer (score)", argv))
    if rel in ("kb/mlcnn/evidence.db", "kb/mlcnn/labels.db"):
        jobs.append(Job("mln kb3 facts", ["{BIN}", "mln", "generate", "kb3", "--data", "{ROOT}",
                                          "--out", "{OUT}/gen"], overlay="mln"))
    # The first set that uses the file as program, evidence or query.
    for s in MLN_SETS:
        folder, prog, evidence, query, _ = s
        if not rel.startswith(folder + "/"):
            continue
        local = rel[len(folder) + 1:]
        role = ("mln program" if local == prog else
                "mln evidence" if local in evidence else
                "mln query" if local == query else None)
        if role is None or rel in MLN_ANSWERS:
            continue
        argv = mln_set_argv(data, s, rel, ie_evidence)
        if argv is None:
            continue
        jobs.append(Job(role, argv))
        break
    if jobs:
        return jobs
    return "in no MLN set urbansem can run (not a program, evidence, query or answer file)"


# --------------------------------------------------------------------------------------------
# Variants
# --------------------------------------------------------------------------------------------

@dataclass
class Variant:
    kind: str                # truncate, flip, inflate
    desc: str                # how to make it, in words
    recipe: dict             # how to make it, as data (see apply)


def apply(recipe: dict, data: bytes) -> bytes:
    op = recipe["op"]
    if op == "truncate":
        return data[: recipe["length"]]
    if op == "flip":
        b = bytearray(data)
        b[recipe["offset"]] ^= 1 << recipe["bit"]
        return bytes(b)
    if op == "splice":
        new = bytes.fromhex(recipe["new_hex"])
        return data[: recipe["start"]] + new + data[recipe["end"]:]
    raise ValueError(op)


def header_end(kind: str | None, data: bytes) -> int | None:
    """Byte offset just past the header, for formats with one."""
    if kind == "pcd":
        m = re.search(rb"(?m)^DATA[^\n]*\n", data[:65536])
        return m.end() if m else None
    if kind == "ply":
        i = data.find(b"end_header", 0, 65536)
        if i < 0:
            return None
        j = data.find(b"\n", i)
        return j + 1 if j >= 0 else None
    if kind == "osm-xml":
        i = data.find(b"<osm", 0, 65536)
        j = data.find(b">", i) if i >= 0 else -1
        return j + 1 if j >= 0 else None
    if kind == "osm-pbf":
        blobs = pbf_blobs(data, 1)
        return blobs[0]["end"] if blobs else None
    if kind == "yaml-os-sensor":
        i = data.find(b"os_sensor")
        return i if i > 0 else None
    return None


def read_varint(b: bytes, i: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        if i >= len(b):
            raise ValueError("varint runs past the end")
        c = b[i]
        i += 1
        value |= (c & 0x7F) << shift
        shift += 7
        if not c & 0x80:
            return value, i


def varint(v: int) -> bytes:
    out = bytearray()
    while True:
        c = v & 0x7F
        v >>= 7
        if v:
            out.append(c | 0x80)
        else:
            out.append(c)
            return bytes(out)


def pb_fields(b: bytes) -> list[tuple[int, int, int, int, int]]:
    """(field number, wire type, value or length, start, end) of a protobuf message."""
    out, i = [], 0
    while i < len(b):
        start = i
        key, i = read_varint(b, i)
        no, wt = key >> 3, key & 7
        if wt == 0:
            v, i = read_varint(b, i)
        elif wt == 2:
            v, i = read_varint(b, i)
            i += v
        elif wt == 1:
            v, i = 0, i + 8
        elif wt == 5:
            v, i = 0, i + 4
        else:
            raise ValueError(f"wire type {wt}")
        out.append((no, wt, v, start, i))
    return out


def pbf_blobs(data: bytes, count: int) -> list[dict]:
    """The first `count` blobs of a PBF: offsets of the length prefix, BlobHeader and Blob."""
    out, off = [], 0
    while len(out) < count and off + 4 <= len(data):
        hl = int.from_bytes(data[off:off + 4], "big")
        hdr = data[off + 4: off + 4 + hl]
        try:
            fields = pb_fields(hdr)
        except ValueError:
            break
        ds = next((f for f in fields if f[0] == 3 and f[1] == 0), None)
        if ds is None:
            break
        blob_start = off + 4 + hl
        out.append({"off": off, "hl": hl, "hdr": hdr, "hdr_fields": fields, "datasize": ds[2],
                    "blob_start": blob_start, "end": blob_start + ds[2]})
        off = blob_start + ds[2]
    return out


def replace_pb_varint(msg: bytes, field_no: int, value: int) -> bytes | None:
    for no, wt, _, start, end in pb_fields(msg):
        if no == field_no and wt == 0:
            return msg[:start] + varint((field_no << 3) | 0) + varint(value) + msg[end:]
    return None


def with_datasize(blob: dict, new_datasize: int) -> bytes:
    """The length prefix and BlobHeader of `blob` with `datasize` replaced."""
    hdr = replace_pb_varint(blob["hdr"], 3, new_datasize)
    return len(hdr).to_bytes(4, "big") + hdr


def pbf_inflations(data: bytes) -> list[Variant]:
    out = []
    blobs = pbf_blobs(data, 2)
    if not blobs:
        return out
    out.append(Variant("inflate", "PBF blob 1 BlobHeader length prefix (u32 BE at byte 0) = 4294967295",
                       {"op": "splice", "start": 0, "end": 4, "new_hex": (4294967295).to_bytes(4, "big").hex()}))
    for k, b in enumerate(blobs, 1):
        for v in HUGE_VALUES:
            new = with_datasize(b, v)
            out.append(Variant("inflate", f"PBF blob {k} BlobHeader datasize = {v} (header re-encoded)",
                               {"op": "splice", "start": b["off"], "end": b["blob_start"], "new_hex": new.hex()}))
        blob = data[b["blob_start"]: b["end"]]
        try:
            has_raw = any(f[0] == 2 and f[1] == 0 for f in pb_fields(blob))
        except ValueError:
            has_raw = False
        if not has_raw:
            continue
        for v in HUGE_VALUES:
            new_blob = replace_pb_varint(blob, 2, v)
            new = with_datasize(b, len(new_blob)) + new_blob
            out.append(Variant("inflate", f"PBF blob {k} Blob raw_size = {v} (headers re-encoded)",
                               {"op": "splice", "start": b["off"], "end": b["end"], "new_hex": new.hex()}))
    return out


def token_inflations(data: bytes, spans: list[tuple[int, int, str]]) -> list[Variant]:
    """Each (start, end, label) token replaced by each huge value, one at a time."""
    out = []
    for start, end, label in spans:
        old = data[start:end].decode("latin-1")
        for v in HUGE_VALUES:
            out.append(Variant("inflate", f"{label}: `{old}` -> `{v}` at byte {start}",
                               {"op": "splice", "start": start, "end": end, "new_hex": str(v).encode().hex()}))
    return out


def inflations(values: str, header: str | None, data: bytes) -> list[Variant]:
    if values == "none":
        return []
    if values == "osm-pbf":
        return pbf_inflations(data)
    if values == "f32-first":
        if len(data) < 4:
            return []
        import struct
        return [Variant("inflate", f"x of point 0 (f32 at byte 0) = {v}",
                        {"op": "splice", "start": 0, "end": 4, "new_hex": struct.pack("<f", float(v)).hex()})
                for v in HUGE_VALUES]
    if values == "u32-labels":
        n = len(data) // 4
        if n == 0:
            return []
        return [Variant("inflate", f"label {i} (u32 at byte {4 * i}) = 4294967295",
                        {"op": "splice", "start": 4 * i, "end": 4 * i + 4, "new_hex": "ffffffff"})
                for i in sorted({0, n // 2})]
    spans: list[tuple[int, int, str]] = []
    if values in ("pcd", "ply", "opb"):
        end = header_end(header, data) or min(len(data), 4096)
        keys = {"pcd": (b"SIZE", b"COUNT", b"WIDTH", b"HEIGHT", b"POINTS"),
                "ply": (b"element",), "opb": (b"*",)}[values]
        for m in re.finditer(rb"(?m)^([^\n]*)\n?", data[:end]):
            line = m.group(1)
            if not line.lstrip().startswith(keys):
                continue
            for t in re.finditer(rb"(?<![\w.\-])\d+(?![\w.])", line):
                spans.append((m.start() + t.start(), m.start() + t.end(),
                              f"header `{line.split()[0].decode('latin-1')}` field"))
    elif values == "osm-xml":
        seen = set()
        pat = rb"<(node|way|nd|relation|member)\b[^>]*?\b(id|ref|version|uid|changeset)=\"(-?\d+)\""
        for m in re.finditer(pat, data[:1_000_000]):
            key = (m.group(1), m.group(2))
            if key in seen:
                continue
            seen.add(key)
            spans.append((m.start(3), m.end(3), f"first <{m.group(1).decode()}> {m.group(2).decode()}"))
            if len(seen) >= 6:
                break
    else:  # text: the first numbers of the file (or of its header block)
        start = header_end(header, data) if header == "yaml-os-sensor" else 0
        start = start or 0
        region = data[start:start + 8192]
        for t in re.finditer(rb"(?<![\w.\-])-?\d+(?:\.\d+)?(?:[eE][-+]?\d+)?(?![\w.])", region):
            line_start = region.rfind(b"\n", 0, t.start()) + 1
            if region[line_start:t.start()].lstrip().startswith((b"//", b"#")):
                continue
            spans.append((start + t.start(), start + t.end(), "number"))
            if len(spans) >= 4:
                break
    return token_inflations(data, spans)


def make_variants(job: Job, data: bytes, seed: int, rel: str, reduced: bool) -> list[Variant]:
    n = len(data)
    hend = header_end(job.header, data) if job.header else None
    cuts: list[tuple[int, str]] = [(0, "0 bytes"), (1, "1 byte")]
    # Flips aimed at the part of the file the reader looks at first: the header, or for the
    # MCD calibration the `os_sensor` block (the only one urbansem reads).
    focus = (0, hend) if hend else None
    if job.header == "yaml-os-sensor":
        focus = (hend, min(n, hend + 400)) if hend else None
        if hend:
            cuts.append((hend + 200, "inside the os_sensor block"))
        hend = None
    if hend is not None:
        cuts += [(hend - 1, "header end - 1"), (hend, "header end"), (hend + 1, "header end + 1")]
    cuts += [(n * 25 // 100, "25 %"), (n * 50 // 100, "50 %"), (n * 99 // 100, "99 %")]
    trunc, seen = [], set()
    for length, why in cuts:
        if 0 <= length < n and length not in seen:
            seen.add(length)
            trunc.append(Variant("truncate", f"truncated to {length} bytes ({why})",
                                 {"op": "truncate", "length": length}))
    rng = random.Random(f"{seed}:{rel}:{job.fmt}")
    nflips = 4 if n > BIG_FILE_BYTES else 8
    in_focus = 0 if not focus else (2 if n > BIG_FILE_BYTES else 3)
    flips = []
    for k in range(nflips if n else 0):
        if k < in_focus:
            off = rng.randrange(focus[0], focus[1])
        else:
            off = rng.randrange(0, n)
        bit = rng.randrange(8)
        where = ""
        if focus and focus[0] <= off < focus[1]:
            where = " (os_sensor block)" if job.header == "yaml-os-sensor" else " (header)"
        flips.append(Variant("flip", f"bit {bit} of byte {off} flipped{where}",
                             {"op": "flip", "offset": off, "bit": bit}))
    infl = inflations(job.values, job.header, data)
    if reduced:
        keep = [v for v in trunc if v.recipe["length"] in (0, n // 2)]
        return keep + flips[:2]
    return trunc + flips + infl


def cap_variants(vs: list[Variant], cap: int | None) -> list[Variant]:
    """At most `cap` variants, taken round robin over the kinds so each kind is represented."""
    if cap is None or len(vs) <= cap:
        return vs
    by_kind: dict[str, list[Variant]] = {}
    for v in vs:
        by_kind.setdefault(v.kind, []).append(v)
    out: list[Variant] = []
    while len(out) < cap:
        for k in list(by_kind):
            if by_kind[k] and len(out) < cap:
                out.append(by_kind[k].pop(0))
    return out


# --------------------------------------------------------------------------------------------
# Running
# --------------------------------------------------------------------------------------------

@dataclass
class Run:
    rc: int | None
    signal: int | None
    seconds: float
    max_rss_kb: int
    killed: str | None
    stderr: str


def rss_kb(pid: int) -> int:
    try:
        with open(f"/proc/{pid}/statm") as f:
            return int(f.read().split()[1]) * (os.sysconf("SC_PAGE_SIZE") // 1024)
    except (OSError, ValueError, IndexError):
        return 0


def run(argv: list[str], cwd: Path, timeout_s: float, kill_rss_kb: int, as_limit: int,
        stderr_path: Path) -> Run:
    def limits():
        resource.setrlimit(resource.RLIMIT_CORE, (0, 0))
        resource.setrlimit(resource.RLIMIT_AS, (as_limit, as_limit))

    env = dict(os.environ, RUST_BACKTRACE="0")
    with open(stderr_path, "wb") as err:
        t0 = time.monotonic()
        p = subprocess.Popen(argv, cwd=cwd, stdin=subprocess.DEVNULL, stdout=subprocess.DEVNULL,
                             stderr=err, start_new_session=True, preexec_fn=limits, env=env)
        killed, nap = None, 0.0005
        while True:
            pid, status, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                break
            if killed is None:
                if time.monotonic() - t0 > timeout_s:
                    killed = "time"
                elif rss_kb(p.pid) > kill_rss_kb:
                    killed = "memory"
                if killed:
                    os.killpg(p.pid, signal.SIGKILL)
                    pid, status, ru = os.wait4(p.pid, 0)
                    break
            time.sleep(nap)
            nap = min(nap * 2, 0.02)
        seconds = time.monotonic() - t0
    p.returncode = 0  # reaped here; keep Popen from waiting again
    code = os.waitstatus_to_exitcode(status)
    with open(stderr_path, "rb") as f:
        text = f.read(1 << 20).decode("utf-8", "replace")
    return Run(rc=code if code >= 0 else None, signal=-code if code < 0 else None,
               seconds=seconds, max_rss_kb=ru.ru_maxrss, killed=killed, stderr=text)


def first_line(text: str) -> str:
    lines = [l for l in text.splitlines() if l.strip()]
    for l in lines:
        if "panicked" in l or "internal error" in l.lower() or "memory allocation" in l:
            return l.strip()[:300]
    return lines[0].strip()[:300] if lines else ""


def verdict(r: Run, limit_kb: int) -> str:
    low = r.stderr.lower()
    if r.killed == "time":
        return "FAIL-HANG"
    if r.killed == "memory" or r.max_rss_kb > limit_kb:
        return "FAIL-MEMORY"
    if "memory allocation of" in low and r.signal is not None:
        return "FAIL-MEMORY"
    if r.rc == 101 or "panicked" in low or "internal error" in low:
        return "FAIL-PANIC"
    if r.signal is not None or r.rc not in (0, 1, 2):
        return "FAIL-CRASH"
    return "PASS"


def fill(argv: list[str], binary: str, file: str, root: str, out: str) -> list[str]:
    return [a.replace("{BIN}", binary).replace("{FILE}", file).replace("{ROOT}", root)
             .replace("{OUT}", out) for a in argv]


def build_overlay(src_base: Path, rel_in_base: str, dest: Path) -> Path:
    """A copy of `src_base` made of symlinks, with real folders along `rel_in_base` so the file
    there can be replaced; returns the path where the variant goes."""
    if dest.exists():
        shutil.rmtree(dest)
    dest.mkdir(parents=True)
    parts = rel_in_base.split("/")
    src, dst = src_base, dest
    for depth, part in enumerate(parts):
        for child in sorted(src.iterdir()):
            if child.name != part:
                os.symlink(child, dst / child.name)
        if depth < len(parts) - 1:
            src, dst = src / part, dst / part
            dst.mkdir()
    return dst / parts[-1]


def slug(s: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "_", s).strip("_")[:80]


def rel_to_cwd(p: str) -> str:
    """`p` relative to the working folder when it is inside it or beside it (../shared/data)."""
    if not p:
        return p
    rel = os.path.relpath(p)
    return p if rel.startswith("../../") else rel


# --------------------------------------------------------------------------------------------
# Main
# --------------------------------------------------------------------------------------------

def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0],
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--binary", default=str(DEFAULT_BINARY), help="urbansem binary [%(default)s]")
    ap.add_argument("--data", default=str(DEFAULT_DATA), help="shared data folder [%(default)s]")
    ap.add_argument("--only", action="append", default=[],
                    help="only files whose path (relative to --data) contains this; repeatable")
    ap.add_argument("--max-variants", type=int, default=None, help="at most N variants per (file, command)")
    ap.add_argument("--seed", type=int, default=16, help="seed of the bit flips [%(default)s]")
    ap.add_argument("--out", default=str(ROOT / "target" / "mutate-shared.json"), help="JSON report [%(default)s]")
    ap.add_argument("--keep", default=str(ROOT / "target" / "mutate-shared"),
                    help="folder for the failing variants [%(default)s]")
    ap.add_argument("--as-limit-gb", type=float, default=8.0,
                    help="address-space cap of each run (RLIMIT_AS); an allocation refused by it is "
                         "a FAIL-MEMORY [%(default)s]")
    ap.add_argument("--list", action="store_true", help="print the command of every file (or why it is "
                    "skipped) and the number of variants, run nothing")
    ap.add_argument("--verbose", action="store_true", help="print every variant's result")
    ap.add_argument("--nice", type=int, default=10, help="niceness of the harness and its runs [%(default)s]")
    args = ap.parse_args()

    if os.nice(0) < args.nice:
        os.nice(args.nice - os.nice(0))
    data = Path(args.data).resolve()
    binary_src = Path(args.binary)
    if not binary_src.exists():
        print(f"error: {binary_src} not found; build it with `cargo build --release -p urbansem`",
              file=sys.stderr)
        return 2
    t_start = time.monotonic()
    work = Path(tempfile.mkdtemp(prefix="mutate-shared-"))
    # Run a private copy, so a rebuild of target/release during the run changes nothing.
    binary = str(work / "urbansem")
    shutil.copy2(binary_src, binary)
    sha = hashlib.sha256(Path(binary).read_bytes()).hexdigest()
    mtime = time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(binary_src.stat().st_mtime))
    as_limit = int(args.as_limit_gb * (1 << 30))
    keep = Path(args.keep)
    print(f"binary {binary_src} (built {mtime}, sha256 {sha[:16]}), data {data}")
    print(f"seed {args.seed}; hang limit max({HANG_FACTOR} x baseline, {HANG_MIN_S:g} s); memory limit "
          f"{MEMORY_RULE}; address-space cap "
          f"{args.as_limit_gb:g} GiB; nice {os.nice(0)}", flush=True)

    ie_evidence = None
    gen = work / "ie-evidence"
    r = run([binary, "mln", "generate", "ie", "--data", str(data / "mln"), "--out", str(gen)], work,
            120, 1 << 30, as_limit, work / "stderr.txt")
    if r.rc == 0 and (gen / "evidence.db").exists():
        ie_evidence = gen / "evidence.db"
    else:
        print(f"note: `mln generate ie` failed ({first_line(r.stderr)}); ie/tuffy runs without evidence")

    files = sorted(str(p.relative_to(data)) for p in data.rglob("*") if p.is_file())
    if args.only:
        files = [f for f in files if any(s in f for s in args.only)]
    skipped: dict[str, list[str]] = {}
    plans: list[tuple[str, Job]] = []
    for rel in files:
        jobs = plan_file(data, rel, ie_evidence)
        if isinstance(jobs, str):
            skipped.setdefault(jobs, []).append(rel)
        else:
            plans += [(rel, j) for j in jobs]
    print(f"{len(files)} files: {len(plans)} (file, command) pairs, "
          f"{sum(len(v) for v in skipped.values())} files skipped", flush=True)
    if args.list:
        for rel, job in plans:
            nv = len(cap_variants(make_variants(job, (data / rel).read_bytes(), args.seed, rel, False),
                                  args.max_variants))
            shown = fill(job.argv, "urbansem", rel, job.overlay or "", "OUT")
            print(f"  {job.fmt:24s} {nv:3d} variants  {' '.join(shown)}")
        for why, fs in sorted(skipped.items()):
            print(f"  skip {len(fs):3d}: {why}: {', '.join(fs[:3])}{' ...' if len(fs) > 3 else ''}")
        shutil.rmtree(work, ignore_errors=True)
        return 0

    baselines: dict[tuple, Run] = {}
    stats: dict[str, dict[str, int]] = {}
    failures: list[dict] = []
    suspicious: list[dict] = []
    baseline_problems: list[dict] = []
    vdir, outdir, stderr_path = work / "v", work / "out", work / "stderr.txt"

    def fresh(d: Path):
        if d.exists():
            shutil.rmtree(d)
        d.mkdir()

    for i, (rel, job) in enumerate(plans, 1):
        src = data / rel
        original = src.read_bytes()
        size = len(original)
        root_orig = str(data / job.overlay) if job.overlay else ""
        base_argv = fill(job.argv, binary, str(src), root_orig, str(outdir))
        key = tuple(base_argv)
        if key not in baselines:
            fresh(outdir)
            baselines[key] = run(base_argv, work, BASELINE_TIMEOUT_S, 1 << 40, as_limit, stderr_path)
        b = baselines[key]
        shown = " ".join(shlex.quote(a) for a in fill(job.argv, rel_to_cwd(str(binary_src)), rel_to_cwd(str(src)),
                                                      rel_to_cwd(root_orig), "OUT"))
        bv = verdict(b, 1 << 40)
        if bv != "PASS" or b.rc == 2:
            baseline_problems.append({"file": rel, "command": shown, "verdict": bv, "exit_code": b.rc,
                                      "signal": b.signal, "stderr": first_line(b.stderr),
                                      "seconds": round(b.seconds, 3)})
            print(f"[{i}/{len(plans)}] {job.fmt:24s} {rel}: BASELINE {bv} exit {b.rc}: "
                  f"{first_line(b.stderr)} -- variants not run", flush=True)
            continue
        hang_s = max(HANG_FACTOR * b.seconds, HANG_MIN_S)
        limit_kb = (MEMORY_FACTOR * size // 1024 + b.max_rss_kb + SLACK_MB * 1024
                    + int(SLACK_SHARE * b.max_rss_kb))
        kill_kb = min(max(2 * limit_kb, limit_kb + (1 << 20)), as_limit // 1024)
        reduced = b.seconds > SLOW_BASELINE_S
        variants = cap_variants(make_variants(job, original, args.seed, rel, reduced), args.max_variants)
        st = stats.setdefault(job.fmt, {"files": 0, "variants": 0, "PASS": 0, "exit-2": 0,
                                        **{v: 0 for v in VERDICTS}})
        st["files"] += 1
        counts: dict[str, int] = {}
        t_file = time.monotonic()
        for var in variants:
            mutated = apply(var.recipe, original)
            fresh(outdir)
            if job.overlay:
                rel_in = rel[len(job.overlay) + 1:]
                target = build_overlay(data / job.overlay, rel_in, vdir)
                root = str(vdir)
            else:
                fresh(vdir)
                target = vdir / src.name
                root = ""
            target.write_bytes(mutated)
            argv = fill(job.argv, binary, str(target), root, str(outdir))
            r = run(argv, work, hang_s, kill_kb, as_limit, stderr_path)
            v = verdict(r, limit_kb)
            st["variants"] += 1
            st[v] += 1
            counts[v] = counts.get(v, 0) + 1
            rec = {"file": rel, "format": job.fmt, "variant": var.desc, "recipe": var.recipe,
                   "verdict": v, "exit_code": r.rc, "signal": r.signal,
                   "stderr_first_line": first_line(r.stderr), "seconds": round(r.seconds, 3),
                   "max_rss_kb": r.max_rss_kb, "baseline_seconds": round(b.seconds, 3),
                   "baseline_rss_kb": b.max_rss_kb, "hang_limit_s": round(hang_s, 2),
                   "memory_limit_kb": limit_kb}
            if v != "PASS":
                # Keep the variant (and the copy of the data folder it sits in) for reproduction.
                kdir = keep / slug(rel) / slug(var.desc)
                if kdir.exists():
                    shutil.rmtree(kdir)
                kdir.parent.mkdir(parents=True, exist_ok=True)
                if job.overlay:
                    shutil.copytree(vdir, kdir, symlinks=True)
                    kept_file = kdir / rel[len(job.overlay) + 1:]
                    kept_root = str(kdir)
                else:
                    kdir.mkdir()
                    kept_file = kdir / src.name
                    shutil.copy2(target, kept_file)
                    kept_root = ""
                rec["variant_file"] = rel_to_cwd(str(kept_file))
                rec["command"] = " ".join(shlex.quote(a) for a in fill(
                    job.argv, rel_to_cwd(str(binary_src)), rel_to_cwd(str(kept_file)),
                    rel_to_cwd(kept_root), "/tmp/mutate-out"))
                failures.append(rec)
                print(f"    {v}: {rel} [{var.desc}] exit {r.rc} sig {r.signal} "
                      f"{r.seconds:.2f} s {r.max_rss_kb // 1024} MB: {rec['stderr_first_line'][:160]}",
                      flush=True)
            elif r.rc == 2:
                st["exit-2"] += 1
                rec["command"] = shown
                suspicious.append(rec)
            if args.verbose:
                print(f"    {v:11s} exit {r.rc} {r.seconds:.2f} s {r.max_rss_kb // 1024} MB [{var.desc}] "
                      f"{first_line(r.stderr)[:150]}", flush=True)
        summary = ", ".join(f"{k} {c}" for k, c in sorted(counts.items()))
        print(f"[{i}/{len(plans)}] {job.fmt:24s} {rel}: baseline {b.seconds:.2f} s "
              f"{b.max_rss_kb // 1024} MB exit {b.rc}; {len(variants)} variants{' (reduced: slow set)' if reduced else ''} "
              f"in {time.monotonic() - t_file:.1f} s: {summary}", flush=True)

    elapsed = time.monotonic() - t_start
    shutil.rmtree(work, ignore_errors=True)

    # Summary table.
    cols = ["files", "variants", "PASS", *VERDICTS, "exit-2"]
    width = max([len("format")] + [len(k) for k in stats]) + 2
    print()
    print(f"{'format':{width}s}" + "".join(f"{c:>12s}" for c in cols))
    total = {c: 0 for c in cols}
    for fmt in sorted(stats):
        print(f"{fmt:{width}s}" + "".join(f"{stats[fmt][c]:>12d}" for c in cols))
        for c in cols:
            total[c] += stats[fmt][c]
    print(f"{'total':{width}s}" + "".join(f"{total[c]:>12d}" for c in cols))
    print("(exit-2: variants that passed with exit code 2, a usage error, though only a file's "
          "content changed; runtime errors must exit 1)")
    print(f"memory limit = {MEMORY_RULE}; "
          f"hang limit = max({HANG_FACTOR} x baseline, {HANG_MIN_S:g} s)")
    print("\nskipped files:")
    for why, fs in sorted(skipped.items(), key=lambda kv: -len(kv[1])):
        print(f"  {len(fs):4d}  {why}")
    if baseline_problems:
        print("\noriginals that do not run cleanly (their variants were not run):")
        for p in baseline_problems:
            print(f"  {p['file']}: {p['verdict']} exit {p['exit_code']}: {p['stderr']}")

    # Distinct failures: same format, verdict and message up to numbers and paths.
    def norm(s: str) -> str:
        s = re.sub(r"(/[^\s:'\"`]+)+", "PATH", s)
        return re.sub(r"\d+", "N", s)

    groups: dict[tuple, list[dict]] = {}
    for f in failures:
        groups.setdefault((f["format"], f["verdict"], norm(f["stderr_first_line"])), []).append(f)
    sgroups: dict[tuple, list[dict]] = {}
    for f in suspicious:
        sgroups.setdefault((f["format"], norm(f["stderr_first_line"])), []).append(f)
    if groups:
        print(f"\n{len(failures)} failures in {len(groups)} distinct kinds:")
        for (fmt, v, _), fs in sorted(groups.items(), key=lambda kv: (kv[0][1], kv[0][0])):
            e = fs[0]
            print(f"  {v} x{len(fs)} [{fmt}] {e['stderr_first_line'][:200]}")
            print(f"      e.g. {e['file']}: {e['variant']}; exit {e['exit_code']} signal {e['signal']}, "
                  f"{e['seconds']} s (limit {e['hang_limit_s']} s), {e['max_rss_kb'] // 1024} MB "
                  f"(limit {e['memory_limit_kb'] // 1024} MB)")
            print(f"      repro: {e['command']}")
    else:
        print("\nno failures")
    if sgroups:
        print(f"\n{len(suspicious)} suspicious exit-2 runs in {len(sgroups)} kinds:")
        for (fmt, _), fs in sorted(sgroups.items()):
            e = fs[0]
            print(f"  x{len(fs)} [{fmt}] {e['stderr_first_line'][:200]}")
            print(f"      e.g. {e['file']}: {e['variant']}")
    print(f"\n{elapsed / 60:.1f} min; report in {args.out}")

    report = {
        "binary": str(binary_src), "binary_sha256": sha, "binary_mtime": mtime, "data": str(data),
        "seed": args.seed, "only": args.only, "max_variants": args.max_variants,
        "rules": {"hang": f"max({HANG_FACTOR} x baseline, {HANG_MIN_S} s)",
                  "memory": MEMORY_RULE,
                  "slack_mb": SLACK_MB, "slack_share": SLACK_SHARE, "address_space_cap_gib": args.as_limit_gb,
                  "slow_baseline_s": SLOW_BASELINE_S},
        "seconds": round(elapsed, 1),
        "summary": stats,
        "skipped": {why: fs for why, fs in skipped.items()},
        "baseline_problems": baseline_problems,
        "failures": failures,
        "suspicious_exit_2": suspicious,
    }
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(report, indent=1))
    return 1 if failures or baseline_problems else 0


if __name__ == "__main__":
    sys.exit(main())
