"""The README's Python example runs as printed (from the repository root, with the shared data
beside it) and finds the scan where the ground truth says it was taken."""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest


def test_readme_python_example_runs(root: Path, data: Path, tmp_path: Path) -> None:
    pytest.importorskip("matplotlib", reason="pip install matplotlib (.ci/run installs it)")
    import matplotlib

    matplotlib.use("Agg")
    readme = (root / "README.md").read_text()
    section = readme[readme.index("\n## Python\n"):]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    picture = tmp_path / "mcd.png"
    code = code.replace('"mcd.png"', repr(str(picture)))
    namespace: dict = {}
    cwd = os.getcwd()
    os.chdir(root)  # the example's paths are relative to the checkout
    try:
        exec(compile(code, "README.md", "exec"), namespace)
    finally:
        os.chdir(cwd)
    assert picture.stat().st_size > 10_000
    import urbansem

    best = namespace["result"].best
    truth = urbansem.localize.load_mcd_scan(
        data / "lidar" / "mcd_kth_day_06", namespace["osm"], namespace["frame"]
    ).truth
    assert abs(best.x - truth[0]) < 4.0 and abs(best.y - truth[1]) < 4.0
