#!/usr/bin/env python3
"""pracmln (SAMaxWalkSAT and exact WCSPInference) beside urbansem, on the same ground problems.

For each problem the script converts the Alchemy/Tuffy/RockIt files to pracmln's syntax, runs
pracmln MAP in a child process per method (killed with its toulbar2 child after --timeout
seconds, parsing and grounding included), writes pracmln's true atoms one per line, re-scores
them with `urbansem mln score` (our evaluator, eq. 3.1 cost) and runs `urbansem mln infer` on
the same files in the same run. Prints one table row per problem (or --json).

    python3 scripts/bench_mln_pracmln.py [--urbansem target/release/urbansem] [--timeout 600]
        [--problems smoke,smoke-pracmln,fs-10,...] [--data ../shared/data/mln] [--json]

Installs pracmln 1.2.4 itself into a venv (default target/pracmln-venv): the PyPI sdist,
with the two fixes it needs on Python 3.11 (`import distutils.command.install` in setup.py,
`from tkinter import StringVar` in mlnquery.py), then `pip install --no-build-isolation .`;
its data files (the shipped toulbar2 binary that WCSPInference calls) go to
<venv>/share/pracmln through XDG_DATA_DIRS.

Conversion conventions (urbansem's reading of the files → pracmln), see convert():
- `*P(...)` (Tuffy: closed-world evidence predicate) → plain declaration `P(...)`, listed as
  closed world. pracmln has no `*`: its `cw=True` closes every predicate that is not queried.
- The atoms pracmln infers (its `queries`) are exactly urbansem's unknown atoms: the query
  predicates of the query file or `-q`, plus, in programs that use `*` at all, every
  predicate without `*` (Tuffy/RockIt read those open world; so does urbansem). A query file
  that lists ground atoms (canopy) passes those atoms as pracmln queries; with `cw=True`
  every other atom is false, as in urbansem.
- Every other atom not in the evidence is false (closed world) in both.
- Quoted constants whose text is an identifier (`"Level500"`) lose their quotes: urbansem
  stores constants without quotes, so `"Level500"` and `Level500` are one constant in both.
- Weights, `.` for hard formulas, `! ^ v => <=>`, `EXIST`, domains `t = {A, B}` and
  evidence lines `P(A)`, `!P(A)` have the same syntax; formulas are kept whole (one ground
  formula = one factor in both engines; pracmln does not split them into CNF clauses).
- Tuffy's `@w` (fixed weight) becomes `w`; a formula line without weight gets weight 0.
"""
import argparse
import json
import os
import re
import signal
import subprocess
import sys
import tarfile
import time
import urllib.request

PRACMLN_VERSION = "1.2.4"

# name -> (kind, data folder or generator, size, query option)
REAL = {
    "smoke": ("smoke/tuffy", "prog.mln", "evidence.db", "query.db", None),
    "smoke-pracmln": ("smoke/pracmln", "wts.pybpll.smoking-train-smoking.mln", "smoking-test.db",
                      None, "Smokes,Cancer"),
    "lp": ("lp/rockit", "prog.mln", "evidence.db", "query.db", None),
    "rc": ("rc/rockit", "prog.mln", "evidence.db", "query.db", None),
    "kb": ("kb/mlcnn", "prog.mln", "evidence.db", "query.db", None),
    "er": ("er/rockit", "prog.mln", "evidence.db", "query.db", None),
    "pr": ("pr/rockit", "prog.mln", "evidence.db", "query.db", None),
}
DEFAULT_PROBLEMS = ("smoke,smoke-pracmln,fs-6,fs-10,fs-20,fs-200,neg-fs-6,neg-fs-10,neg-fs-20,"
                    "neg-fs-200,id-6,id-10,id-20,id-90,lp,rc,kb,er")

# The child that runs pracmln (executed by the venv's python).
RUNNER = r'''
import json, random, resource, sys, time
t0 = time.time()
args = json.load(open(sys.argv[1]))
if args["mem_gb"] > 0:
    lim = int(args["mem_gb"] * 2**30)
    resource.setrlimit(resource.RLIMIT_AS, (lim, lim))
random.seed(args["seed"])
from pracmln import MLN, Database, MLNQuery
mln = MLN(grammar="StandardGrammar", logic="FirstOrderLogic", mlnfile=args["mln"])
db = Database(mln, dbfile=args["db"], ignore_unknown_preds=False)
params = {}
if args["method"] in ("SAMaxWalkSAT", "MC-SAT") and args["maxsteps"] > 0:
    params["maxsteps"] = args["maxsteps"]
q = MLNQuery(mln=mln, db=db, method=args["method"], queries=args["queries"], cw=True,
             multicore=False, verbose=False, **params)
res = q.run()
t1 = time.time()
with open(args["answer"], "w") as f:
    if args.get("marginal"):
        json.dump({a: v for a, v in res.results.items() if v is not None}, f)
    else:
        for atom, value in sorted(res.results.items()):
            if value is not None and value >= 0.5:
                f.write(atom + "\n")
unknown = sum(1 for q in res.queries if res.mrf.evidence[q.gndatom.idx] is None)
print(json.dumps({"seconds": t1 - t0, "unknown_atoms": unknown}))
'''


LOG = sys.stdout  # progress and install steps; stderr under --json


def say(msg):
    print(msg, file=LOG, flush=True)


def ensure_pracmln(venv, work):
    """Create the venv and install pracmln's patched sdist into it unless that is done."""
    py = os.path.join(venv, "bin", "python")
    share = os.path.abspath(os.path.join(venv, "share"))
    tb2 = os.path.join(share, "pracmln", "3rdparty", "toulbar2-0.9.7.0", "x86_64", "Linux",
                       "toulbar2")
    env = dict(os.environ, XDG_DATA_DIRS=share, PYTHONHASHSEED="0")  # reproducible set order
    if os.path.exists(py) and os.access(tb2, os.X_OK) and subprocess.call(
            [py, "-c", "import pracmln"], env=env, stdout=subprocess.DEVNULL,
            stderr=subprocess.DEVNULL) == 0:
        say(f"pracmln {PRACMLN_VERSION}: already installed in {venv}")
        return py, env
    say(f"pracmln {PRACMLN_VERSION}: creating venv {venv}")
    subprocess.check_call([sys.executable, "-m", "venv", venv])
    subprocess.check_call([py, "-m", "pip", "install", "-q", "wheel", "setuptools"])
    src = os.path.join(work, "pracmln-src")
    os.makedirs(src, exist_ok=True)
    # `pip download` cannot fetch it: it runs the unpatched setup.py. PyPI's JSON names the sdist.
    meta = json.load(urllib.request.urlopen("https://pypi.org/pypi/pracmln/json"))
    url = next(u["url"] for u in meta["releases"][PRACMLN_VERSION] if u["packagetype"] == "sdist")
    tgz = os.path.join(src, os.path.basename(url))
    say(f"pracmln: downloading the sdist {url}")
    urllib.request.urlretrieve(url, tgz)
    with tarfile.open(tgz) as t:
        t.extractall(src)
    root = os.path.join(src, f"pracmln-{PRACMLN_VERSION}")
    say("pracmln: fix 1, setup.py: `import distutils.command.install` (its install command "
        "subclasses distutils.command.install.install)")
    patch(os.path.join(root, "setup.py"), "import distutils\n",
          "import distutils\nimport distutils.command.install\n")
    say("pracmln: fix 2, python3/pracmln/mlnquery.py: `from tkinter import StringVar` "
        "(it imported StringVar from tkinter.filedialog)")
    patch(os.path.join(root, "python3", "pracmln", "mlnquery.py"),
          "from tkinter.filedialog import askopenfilename, asksaveasfilename, StringVar\n",
          "from tkinter.filedialog import askopenfilename, asksaveasfilename\n"
          "from tkinter import StringVar\n")
    say(f"pracmln: pip install --no-build-isolation . (data files to {share}/pracmln)")
    subprocess.check_call([py, "-m", "pip", "install", "-q", "--no-build-isolation", "."],
                          cwd=root, env=env, stdout=sys.stderr)
    if not os.access(tb2, os.X_OK):
        sys.exit(f"pracmln installed but its toulbar2 is not at {tb2}")
    return py, env


def patch(path, old, new):
    with open(path) as f:
        text = f.read()
    if new in text:
        return
    if old not in text:
        sys.exit(f"{path}: expected line not found: {old.strip()}")
    with open(path, "w") as f:
        f.write(text.replace(old, new, 1))


# ---------------------------------------------------------------------------------------------
# Conversion

IDENT = re.compile(r'^[A-Za-z0-9_]+$')
QUOTED = re.compile(r'"([^"\\]*)"')
DECL = re.compile(r'^(\*?)\s*([A-Za-z_][A-Za-z0-9_]*)\s*\(([^()]*)\)\s*$')
WEIGHT = re.compile(r'^@?([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)\s+(.*)$')
DOMAIN = re.compile(r'^([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(\{.*\})\s*$')
ATOM = re.compile(r'^(!?)\s*([A-Za-z_][A-Za-z0-9_]*)\s*\((.*)\)\s*$')


def unquote(text):
    """`"Level500"` → `Level500` where the text is an identifier (one constant in urbansem)."""
    def repl(m):
        s = m.group(1)
        return s if IDENT.match(s) and s[0].isupper() or s.isdigit() else m.group(0)
    return QUOTED.sub(repl, text)


def strip_comment(line):
    out, inq = [], False
    i = 0
    while i < len(line):
        c = line[i]
        if c == '"':
            inq = not inq
        if not inq and line.startswith("//", i):
            break
        out.append(c)
        i += 1
    return "".join(out).strip()


def convert(prog, evidence, query_file, queries, out_dir):
    """Write pracmln's prog.mln and evidence.db; return (pracmln queries, notes)."""
    os.makedirs(out_dir, exist_ok=True)
    declared, starred, lines = {}, set(), []
    in_block = False
    for raw in open(prog):
        line = raw.rstrip("\n")
        if in_block:
            if "*/" in line:
                in_block = False
                line = line.split("*/", 1)[1]
            else:
                continue
        if "/*" in line:
            before, after = line.split("/*", 1)
            if "*/" in after:
                line = before + after.split("*/", 1)[1]
            else:
                in_block, line = True, before
        line = strip_comment(line)
        if not line:
            continue
        m = DECL.match(line)
        if m and not WEIGHT.match(line):
            args = [a.strip() for a in m.group(3).split(",")]
            if all(IDENT.match(a) for a in args) and (m.group(1) or m.group(2) not in declared):
                declared[m.group(2)] = args
                if m.group(1):
                    starred.add(m.group(2))
                lines.append(("decl", m.group(2), args))
                continue
        d = DOMAIN.match(line)
        if d:
            lines.append(("domain", d.group(1), unquote(d.group(2))))
            continue
        w = WEIGHT.match(line)
        if w:
            lines.append(f"{w.group(1)} {unquote(w.group(2))}")
        elif line.endswith("."):
            lines.append(unquote(line))
        else:
            lines.append(f"0 {unquote(line)}")
    # pracmln's parser wants domain (type) names in lower case: `Person` → `person`.
    types = {t for _, _, args in (x for x in lines if x[0] == "decl") for t in args}
    types |= {x[1] for x in lines if x[0] == "domain"}
    rename = {}
    for t in sorted(types):
        n = t[0].lower() + t[1:]
        rename[t] = n if n == t or n not in types else "dom_" + t
    with open(os.path.join(out_dir, "prog.mln"), "w") as f:
        f.write("// converted for pracmln by scripts/bench_mln_pracmln.py\n")
        for x in lines:
            if isinstance(x, str):
                f.write(x + "\n")
            elif x[0] == "decl":
                f.write(f"{x[1]}({', '.join(rename[t] for t in x[2])})\n")
            else:
                f.write(f"{rename[x[1]]} = {x[2]}\n")
    # Evidence: same syntax, quotes as above.
    n_ev = 0
    with open(os.path.join(out_dir, "evidence.db"), "w") as f:
        for ev in evidence:
            for raw in open(ev):
                line = strip_comment(raw)
                if not line:
                    continue
                f.write(unquote(line) + "\n")
                n_ev += 1
    # Unknown atoms: query predicates (+ unstarred predicates in Tuffy-style programs).
    qatoms = []
    if query_file:
        for raw in open(query_file):
            line = strip_comment(raw)
            if line:
                qatoms.append(unquote(line))
    else:
        qatoms = [q.strip() for q in queries.split(",")]
    pq, ground = [], []
    for q in qatoms:
        m = ATOM.match(q)
        name = m.group(2) if m else q
        args = [a.strip() for a in m.group(3).split(",")] if m else []
        if args and all(a[0].isupper() or a[0].isdigit() or a[0] == '"' for a in args):
            ground.append(q)
        elif name not in pq:
            pq.append(name)
    if starred:
        for p in declared:
            if p not in starred and p not in pq:
                pq.append(p)
    pq_all = pq + [g for g in ground if ATOM.match(g).group(2) not in pq]
    return pq_all, {"evidence_lines": n_ev, "closed_world": sorted(starred),
                    "open": pq, "canopy_atoms": len(ground)}


# ---------------------------------------------------------------------------------------------
# Running

def run_pracmln(py, env, work, conv, queries, method, timeout, seed, maxsteps, mem_gb,
                marginal=False):
    answer = os.path.join(work, f"pracmln-{method}.answer")
    if os.path.exists(answer):
        os.remove(answer)
    cfg = os.path.join(work, f"pracmln-{method}.json")
    with open(cfg, "w") as f:
        json.dump({"mln": os.path.join(conv, "prog.mln"), "db": os.path.join(conv, "evidence.db"),
                   "queries": queries, "method": method, "answer": answer, "seed": seed,
                   "maxsteps": maxsteps, "mem_gb": mem_gb, "marginal": marginal}, f)
    runner = os.path.join(work, "..", "pracmln_runner.py")
    with open(runner, "w") as f:
        f.write(RUNNER)
    t0 = time.time()
    log = open(os.path.join(work, f"pracmln-{method}.log"), "w")
    child = subprocess.Popen([py, runner, cfg], env=env, cwd=work, stdout=subprocess.PIPE,
                             stderr=log, start_new_session=True, text=True)
    try:
        out, _ = child.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(child.pid, signal.SIGKILL)  # pracmln and its toulbar2 child
        child.communicate()
        return {"status": "timeout", "seconds": time.time() - t0}
    seconds = time.time() - t0
    if child.returncode != 0 or not os.path.exists(answer):
        log.close()
        tail = open(log.name).read().strip().splitlines()
        err = next((l for l in reversed(tail) if l.strip()), f"exit {child.returncode}")
        if child.returncode < 0:
            err = f"killed by signal {-child.returncode}"
        return {"status": "error", "seconds": seconds, "error": err[-200:]}
    inner = json.loads(out.strip().splitlines()[-1])
    return {"status": "ok", "seconds": seconds, "pracmln_seconds": inner["seconds"],
            "unknown_atoms": inner["unknown_atoms"],
            "answer": answer}


def qargs(files):
    prog, evidence, query_file, queries = files
    a = ["-i", prog, "-e", ",".join(evidence)]
    return a + (["--query-file", query_file] if query_file else ["-q", queries])


def ours(urbansem, files, seed, extra=()):
    """`urbansem mln infer … --json` (MAP, or with extra `--marginal …`)."""
    out = subprocess.check_output([urbansem, "mln", "infer", *qargs(files), "--seed", str(seed),
                                   *extra, "--json"], stderr=subprocess.DEVNULL)
    return json.loads(out)


def prepare(name, args):
    """A problem's files, its work folder, and its conversion to pracmln (folder, queries,
    notes)."""
    files = problem_files(name, args)
    pw = os.path.join(args.work, name)
    os.makedirs(pw, exist_ok=True)
    conv = os.path.join(pw, "pracmln")
    pq, notes = convert(files[0], files[1], files[2], files[3], conv)
    return files, pw, conv, pq, notes


def max_diff(a, b):
    """Largest |a − b| over the atoms both give (names compared without spaces)."""
    norm = lambda d: {k.replace(" ", "").replace('"', ""): v for k, v in d.items()}
    a, b = norm(a), norm(b)
    common = set(a) & set(b)
    return (max((abs(a[k] - b[k]) for k in common), default=float("nan")), len(common))


def marginal_main(args, py, env):
    """Marginal inference: urbansem's MC-SAT beside pracmln's MC-SAT and, where it finishes,
    pracmln's exact EnumerationAsk."""
    methods = args.methods.split(",")
    rows = []
    if not args.json:
        say("| problem | unknown atoms | urbansem s | " +
            " | ".join(f"pracmln {m}: max abs. diff. from urbansem | s" for m in methods) +
            " | urbansem's / pracmln MC-SAT's max error vs exact |")
        say("|---|---|---|" + "---|---|" * len(methods) + "---|")
    for name in args.problems.split(","):
        files, pw, conv, pq, notes = prepare(name, args)
        mine = ours(args.urbansem, files, args.seed,
                    ("--marginal", "--samples", str(args.samples)))
        row = {"problem": name, "urbansem_seconds": mine["seconds"]["total"],
               "ground_atoms": mine["ground_atoms"], "conversion": notes}
        for method in methods:
            r = run_pracmln(py, env, pw, conv, pq, method, args.timeout, args.seed,
                            args.samples if method == "MC-SAT" else 0, args.mem_gb,
                            marginal=True)
            if r["status"] == "ok":
                theirs = json.load(open(r["answer"]))
                r["max_abs_diff"], r["atoms_compared"] = max_diff(mine["marginals"], theirs)
                r["marginals"] = theirs
            row[method] = r
        exact = row.get("EnumerationAsk")
        if exact and exact["status"] == "ok":
            row["urbansem_max_error"] = exact["max_abs_diff"]
            mc = row.get("MC-SAT")
            if mc and mc["status"] == "ok":
                row["pracmln_mcsat_max_error"] = max_diff(mc["marginals"], exact["marginals"])[0]
        for m in methods:
            row[m].pop("marginals", None)
        rows.append(row)
        with open(os.path.join(args.work, "marginal-results.jsonl"), "a") as f:
            f.write(json.dumps(row) + "\n")
        if not args.json:
            cells = [name, str(mine["ground_atoms"]), f"{mine['seconds']['total']:.2f}"]
            for m in methods:
                r = row[m]
                if r["status"] == "ok":
                    cells += [f"{r['max_abs_diff']:.3f} ({r['atoms_compared']} atoms)",
                              f"{r['seconds']:.1f}"]
                else:
                    cells += fmt(r)
            if "urbansem_max_error" in row:
                cells.append(f"{row['urbansem_max_error']:.3f} / "
                             f"{row.get('pracmln_mcsat_max_error', float('nan')):.3f}")
            else:
                cells.append("–")
            say("| " + " | ".join(cells) + " |")
    if args.json:
        print(json.dumps({"problems": rows}, indent=2))


def score(urbansem, files, answer):
    out = subprocess.check_output([urbansem, "mln", "score", *qargs(files), "--answer", answer,
                                   "--json"], stderr=subprocess.STDOUT)
    return json.loads(out)


def problem_files(name, args):
    if name in REAL:
        rel, prog, ev, qf, q = REAL[name]
        d = os.path.join(args.data, rel)
        return (os.path.join(d, prog), [os.path.join(d, ev)],
                os.path.join(d, qf) if qf else None, q)
    m = re.match(r"^(fs|neg-fs|id)-(\d+)$", name)
    if not m:
        sys.exit(f"unknown problem {name}")
    d = os.path.join(args.work, "gen", name)
    subprocess.check_call([args.urbansem, "mln", "generate", m.group(1), "--size", m.group(2),
                           "--seed", str(args.seed), "--out", d], stdout=subprocess.DEVNULL)
    return (os.path.join(d, "prog.mln"), [os.path.join(d, "evidence.db")],
            os.path.join(d, "query.db"), None)


def same(a, b):
    """Equal up to float summation noise."""
    return abs(a - b) <= 1e-6 + 1e-9 * abs(b)


def fmt(r):
    if r["status"] == "ok":
        return f"{r['cost']:.4f}", f"{r['seconds']:.2f}"
    if r["status"] == "timeout":
        return "timeout", f">{r['seconds']:.0f}"
    return "error", f"{r['seconds']:.1f}"


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--urbansem", default="target/release/urbansem")
    ap.add_argument("--data", default="../shared/data/mln")
    ap.add_argument("--work", default="target/bench-data/mln-pracmln")
    ap.add_argument("--venv", default="target/pracmln-venv")
    ap.add_argument("--problems", default=DEFAULT_PROBLEMS)
    ap.add_argument("--methods", default=None,
                    help="pracmln methods (default SAMaxWalkSAT,WCSPInference; with "
                         "--marginal MC-SAT,EnumerationAsk)")
    ap.add_argument("--marginal", action="store_true",
                    help="marginal inference: urbansem's MC-SAT beside pracmln's MC-SAT and "
                         "exact EnumerationAsk")
    ap.add_argument("--samples", type=int, default=5000,
                    help="--marginal: samples per chain for urbansem, MC-SAT steps for pracmln")
    ap.add_argument("--timeout", type=float, default=600.0,
                    help="seconds per problem and pracmln method, parsing and grounding included")
    ap.add_argument("--maxsteps", type=int, default=0,
                    help="SAMaxWalkSAT steps (0: pracmln's default, 500)")
    ap.add_argument("--mem-gb", type=float, default=6.0, help="address-space limit of pracmln")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", action="store_true")
    args = ap.parse_args()
    global LOG
    LOG = sys.stderr if args.json else sys.stdout
    args.work = os.path.abspath(args.work)
    args.urbansem = os.path.abspath(args.urbansem)
    args.venv = os.path.abspath(args.venv)
    os.makedirs(args.work, exist_ok=True)
    py, env = ensure_pracmln(args.venv, args.work)
    if args.methods is None:
        args.methods = ("MC-SAT,EnumerationAsk" if args.marginal
                        else "SAMaxWalkSAT,WCSPInference")
    if args.marginal:
        return marginal_main(args, py, env)
    methods = args.methods.split(",")
    rows = []
    if not args.json:
        say("| problem | unknown atoms | urbansem cost | s | " +
            " | ".join(f"pracmln {m} cost | s" for m in methods) + " |")
        say("|---|---|---|---|" + "---|---|" * len(methods))
    for name in args.problems.split(","):
        files, pw, conv, pq, notes = prepare(name, args)
        mine = ours(args.urbansem, files, args.seed)
        row = {"problem": name, "urbansem_cost": mine["cost"],
               "urbansem_lower_bound": mine["lower_bound"],
               "urbansem_seconds": mine["seconds"]["total"],
               "ground_atoms": mine["ground_atoms"], "pracmln_queries": pq, "conversion": notes}
        for method in methods:
            r = run_pracmln(py, env, pw, conv, pq, method, args.timeout, args.seed,
                            args.maxsteps, args.mem_gb)
            if r["status"] == "ok":
                s = score(args.urbansem, files, r["answer"])
                r.update(cost=s["cost"], violated_weight=s["violated_weight"],
                         hard_violations=s["hard_violations"],
                         answer_atoms_not_unknown=s["answer_atoms_not_unknown"])
            row[method] = r
        optimal = same(mine["cost"], mine["lower_bound"])
        w = row.get("WCSPInference")
        if optimal and w and w["status"] == "ok":
            row["wcsp_equals_proven_optimum"] = same(w["cost"], mine["cost"])
        known = {row[m]["unknown_atoms"] for m in methods if row[m]["status"] == "ok"}
        if known:
            row["same_unknown_atoms"] = known == {mine["ground_atoms"]}
        rows.append(row)
        with open(os.path.join(args.work, "results.jsonl"), "a") as f:  # survives an interrupt
            f.write(json.dumps(row) + "\n")
        if not args.json:
            cells = [name, str(mine["ground_atoms"]) + (
                         "" if row.get("same_unknown_atoms", True) else f" (pracmln {known})"),
                     f"{mine['cost']:.4f}" + (" (opt)" if optimal else ""),
                     f"{mine['seconds']['total']:.2f}"]
            for m in methods:
                cells += fmt(row[m])
            say("| " + " | ".join(cells) + " |")
    if args.json:
        print(json.dumps({"problems": rows}, indent=2))
    else:
        say("\ncosts: eq. 3.1 by `urbansem mln score` on each engine's true atoms (lower is "
            "better); (opt) = urbansem's lower bound equals its cost; pracmln seconds include "
            "its parsing and grounding (child process, wall clock); timeout = killed after "
            f"{args.timeout:.0f} s.")
        for r in rows:
            if "wcsp_equals_proven_optimum" in r:
                say(f"{r['problem']}: pracmln WCSP optimum re-scored "
                    + ("= urbansem's proven optimum" if r["wcsp_equals_proven_optimum"]
                       else f"{r['WCSPInference']['cost']:.6f} != urbansem's proven optimum "
                            f"{r['urbansem_cost']:.6f}"))
            for m in methods:
                if r[m]["status"] == "error":
                    say(f"{r['problem']}: pracmln {m} error: {r[m]['error']}")


if __name__ == "__main__":
    main()
