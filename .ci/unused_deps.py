#!/usr/bin/env python3
"""Unused dependencies, the way cargo-machete finds them, without installing it on every
fresh CI machine: a dependency of a crate that no Rust file of that crate names (as
`name::`, `use name`, `extern crate name` or `name!`, with `-` read as `_`) is reported.
Exit 1 when one is found. Dependencies a crate uses only through another name can be
listed under `[package.metadata.cargo-machete] ignored = [...]`, as for cargo-machete."""
import pathlib
import re
import sys
import tomllib

root = pathlib.Path(__file__).resolve().parent.parent
workspace = tomllib.loads((root / "Cargo.toml").read_text())
members = workspace["workspace"]["members"]
unused = []
for member in members:
    crate = root / member
    manifest = tomllib.loads((crate / "Cargo.toml").read_text())
    ignored = set(
        manifest.get("package", {})
        .get("metadata", {})
        .get("cargo-machete", {})
        .get("ignored", [])
    )
    text = "\n".join(
        p.read_text(errors="replace") for p in crate.rglob("*.rs") if "target" not in p.parts
    )
    for table in ("dependencies", "dev-dependencies", "build-dependencies"):
        for name, spec in manifest.get(table, {}).items():
            if name in ignored:
                continue
            package = spec.get("package", name) if isinstance(spec, dict) else name
            ident = name.replace("-", "_")
            pattern = rf"\b{re.escape(ident)}(::|!|\s*;)|use\s+{re.escape(ident)}\b|extern\s+crate\s+{re.escape(ident)}\b"
            if not re.search(pattern, text):
                unused.append(f"{member}: [{table}] {name}" + (f" (package {package})" if package != name else ""))
if unused:
    print("unused dependencies (no Rust file of the crate names them):")
    for u in unused:
        print("  " + u)
    sys.exit(1)
print(f"no unused dependencies in {len(members)} crates")
