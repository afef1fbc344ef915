#!/usr/bin/env python3
"""Fails when sibling modules of a crate import each other in a circle.

For every crate under crates/ and every module folder in it (the crate root, src/X/, …),
each child module (X.rs or X/**) is a node; a reference to a sibling Y (`crate::…::Y`, or
`super::Y` from the child's own file) in non-test code of X is an edge X -> Y. Test code (`#[cfg(test)] mod …` to the end of the file, the usual layout
here) is left out: tests may use anything. Any strongly connected component with more than
one module is printed and the script exits with 1.
"""

import os
import re
import sys

ROOT = os.path.join(os.path.dirname(os.path.abspath(__file__)), "..")
REF = re.compile(r"\bcrate::([a-z_][a-z0-9_]*)")
# `use crate::{a, b::c}` names several modules at once.
GROUP = re.compile(r"\buse\s+crate::\{([^;]*)\}", re.S)


def strip_tests(text):
    m = re.search(r"#\[cfg\(test\)\]\s*(pub(\([a-z]+\))?\s+)?mod\s", text)
    text = text[: m.start()] if m else text
    # Comments and doc comments do not import anything.
    return re.sub(r"//[^\n]*", "", text)


def module_files(folder, name):
    """Files of module `name` under `folder`: name.rs and everything under name/."""
    files = []
    if os.path.isfile(os.path.join(folder, name + ".rs")):
        files.append(os.path.join(folder, name + ".rs"))
    d = os.path.join(folder, name)
    if os.path.isdir(d):
        for root, _, names in os.walk(d):
            files += [os.path.join(root, n) for n in names if n.endswith(".rs")]
    return files


def level_edges(src, path):
    """Edges between the child modules of the module at `path` (a list of names; [] is the
    crate root). A child refers to a sibling Y as `crate::<path>::Y`, or, from the file that
    is the child itself, as `super::Y`."""
    folder = os.path.join(src, *path)
    modules = set()
    for name in os.listdir(folder):
        if name.endswith(".rs") and name not in ("lib.rs", "main.rs", "mod.rs"):
            modules.add(name[:-3])
        elif os.path.isdir(os.path.join(folder, name)):
            modules.add(name)
    prefix = "crate::" + "".join(p + "::" for p in path)
    ref = re.compile(r"\b" + re.escape(prefix) + r"([a-z_][a-z0-9_]*)")
    group = re.compile(r"\buse\s+" + re.escape(prefix) + r"\{([^;]*)\}", re.S)
    edges = {m: set() for m in modules}
    for m in modules:
        for f in module_files(folder, m):
            with open(f, encoding="utf-8") as fh:
                text = strip_tests(fh.read())
            targets = set(ref.findall(text))
            for g in group.findall(text):
                for item in g.split(","):
                    head = item.strip().split("::")[0].strip("{} \n")
                    if head:
                        targets.add(head)
            # `super::Y` from the child's own file (m.rs or m/mod.rs) names a sibling.
            own = os.path.normpath(f) in (
                os.path.normpath(os.path.join(folder, m + ".rs")),
                os.path.normpath(os.path.join(folder, m, "mod.rs")),
            )
            if own and path is not None:
                targets |= set(re.findall(r"\bsuper::([a-z_][a-z0-9_]*)", text))
            for t in targets:
                if t in modules and t != m:
                    edges[m].add(t)
    return edges


def module_paths(src):
    """Every module folder of the crate, as a path of names ([] is the root)."""
    out = [[]]
    for root, dirs, _ in os.walk(src):
        rel = os.path.relpath(root, src)
        if rel != ".":
            out.append(rel.split(os.sep))
    return out


def cycles(edges):
    """Tarjan's strongly connected components with more than one node."""
    index, low, stack, on, out = {}, {}, [], set(), []
    counter = [0]

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def main():
    bad = 0
    crates_dir = os.path.join(ROOT, "crates")
    checked = 0
    for crate in sorted(os.listdir(crates_dir)):
        src = os.path.join(crates_dir, crate, "src")
        if not any(os.path.isfile(os.path.join(src, r)) for r in ("lib.rs", "main.rs")):
            continue
        checked += 1
        for path in module_paths(src):
            edges = level_edges(src, path)
            where = "::".join([crate] + path)
            for comp in cycles(edges):
                bad = 1
                detail = "; ".join(
                    f"{a} -> {', '.join(sorted(edges[a] & set(comp)))}" for a in comp
                )
                print(f"{where}: modules import each other in a circle: {detail}")
    if not bad:
        print(f"no module circles in {checked} crates")
    return bad


if __name__ == "__main__":
    sys.exit(main())
