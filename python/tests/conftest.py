"""Fixtures shared by the Python tests: the repository root, the shared data beside it, and
the command-line binary the results are compared with."""

from __future__ import annotations

import json
import os
import subprocess
from pathlib import Path
from typing import Any, List

import pytest

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def root() -> Path:
    """The repository's root folder."""
    return ROOT


@pytest.fixture(scope="session")
def data() -> Path:
    """`../shared/data` beside the checkout (or $URBANSEM_DATA)."""
    d = Path(os.environ.get("URBANSEM_DATA", ROOT.parent / "shared" / "data"))
    if not d.is_dir():
        pytest.fail(f"shared data not found at {d} (set URBANSEM_DATA)")
    return d


@pytest.fixture(scope="session")
def cli(root: Path):
    """Runs the `urbansem` binary of this checkout (target/release) and returns its stdout;
    with ``json=True`` parses it. Skips when the binary is not built, unless CI requires it."""
    exe = Path(os.environ.get("URBANSEM_CLI", root / "target" / "release" / "urbansem"))
    if not exe.is_file():
        message = f"{exe} is not built (cargo build --release -p urbansem)"
        if os.environ.get("URBANSEM_CLI_REQUIRED"):
            pytest.fail(message)
        pytest.skip(message)

    def run(*args: Any, json_out: bool = False) -> Any:
        out = subprocess.run(
            [str(exe), *map(str, args)], check=True, capture_output=True, text=True
        ).stdout
        return json.loads(out) if json_out else out

    return run


def kitti_scans(data: Path) -> List[Path]:
    """The KITTI-360 drive 0009 scans in the shared data."""
    return sorted((data / "lidar" / "kitti360_2013_05_28_drive_0009" / "velodyne_points").glob("*.bin"))
