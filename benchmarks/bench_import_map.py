"""Benchmark of ``world import`` on the shipped Malaga campus grid (2,048 x 2,048 cells of an
MRPT gridmap, 19,948 walls once cropped): wall time and peak memory of the command in a process
of its own, beside a reference measured in the same run: the same command on a tiny grid (a
10 x 12 m room: what every import costs to start, Python, numpy, the package). The targets: 30 s
and 1 GB of the import's own (the numba compile of a cold cache, a fresh clone's, measured
0.7-0.8 GB on top, and is shown apart: the first run here is cold only on a fresh clone).

Run by hand: ``.venv/bin/python benchmarks/bench_import_map.py``.
"""

from __future__ import annotations

import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from sensorimotor.sim.mrpt import CAMPUS_MAP, gridmap_bytes
from sensorimotor.version import __version__

TARGET_S = 30.0
TARGET_GB = 1.0
CODE = """import resource, runpy, sys
sys.argv = ['sensorimotor', 'world', 'import', {src!r}, '--out', {out!r}]
try:
    runpy.run_module('sensorimotor', run_name='__main__')
except SystemExit as end:
    assert not end.code, end.code
print(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss)
"""


def measured(src: Path, out: Path) -> tuple[float, float]:
    """(wall seconds, peak GB) of ``world import SRC --out OUT`` in a process of its own."""
    t = time.perf_counter()
    proc = subprocess.run([sys.executable, "-c", CODE.format(src=str(src), out=str(out))],
                          capture_output=True, text=True, check=True)  # fmt: skip
    return time.perf_counter() - t, int(proc.stdout.split()[-1]) / 2**20


def main() -> None:
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        free = np.full((10, 12), 0.5)  # unknown around, cells of 1 m
        free[1:9, 1:11] = 0.99  # a 10 x 8 m room
        tiny = Path(tmp) / "room.gridmap"
        tiny.write_bytes(gridmap_bytes(free, 1.0))
        for name, src in (("a tiny grid (reference)", tiny), ("campus gridmap", CAMPUS_MAP),
                          ("campus gridmap, again", CAMPUS_MAP)):  # fmt: skip
            out = Path(tmp) / f"{len(rows)}.toml"
            rows.append((name, *measured(src, out)))
    ref_s, ref_gb = rows[0][1], rows[0][2]
    t = Table(title=f"world import, sensorimotor {__version__}")
    for col in ("input", "wall s", "x reference", "peak GB", "x reference", "target"):
        t.add_column(col)
    for name, s, gb in rows:
        target = "" if "reference" in name else (
            f"{'met' if s <= TARGET_S and gb <= TARGET_GB else 'missed'}: "
            f"<= {TARGET_S:g} s, <= {TARGET_GB:g} GB")  # fmt: skip
        t.add_row(name, f"{s:.2f}", f"{s / ref_s:.1f}", f"{gb:.2f}", f"{gb / ref_gb:.1f}", target)
    Console().print(t)


if __name__ == "__main__":
    main()
