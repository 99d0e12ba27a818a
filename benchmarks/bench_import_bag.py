"""Benchmark of ``import-bag``: scans per second of ``sim.rosbag.import_bag`` on a generated bag of
360-beam LaserScans and Odometry at 10 Hz, beside two references measured in the same run on the
same bag: reading the raw messages (what no importer can beat) and decoding every message with
``rosbags`` (what a plain importer would do before it picks 5 beams a scan). The target: a
1,000,000-scan bag in under a minute on one core, extrapolated from ``--scans``, in CPU seconds
(the import runs on one thread; on a shared machine its wall time says more about the load).

Run by hand: ``.venv/bin/python benchmarks/bench_import_bag.py [--scans N] [--format F]``
(needs the ``[ros]`` extra).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from sensorimotor.sim.bagcodec import FORMATS, write_bag
from sensorimotor.sim.database import generate
from sensorimotor.sim.rosbag import import_bag
from sensorimotor.sim.world import load_world
from sensorimotor.version import __version__

TARGET_S = 60.0  # seconds for 1,000,000 scans, one core
MILLION = 1_000_000


def read_raw(bag: Path) -> int:
    """Reference: every message's bytes, nothing decoded."""
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([bag]) as reader:
        for _ in reader.messages():
            n += 1
    return n


def decode_all(bag: Path) -> int:
    """Reference: every message decoded by rosbags, nothing kept."""
    from rosbags.highlevel import AnyReader

    n = 0
    with AnyReader([bag]) as reader:
        for conn, _, raw in reader.messages():
            reader.deserialize(raw, conn.msgtype)
            n += 1
    return n


def timed(fn) -> tuple[float, float]:
    """(wall, CPU) seconds of ``fn()``: one thread, so the CPU time is what one idle core takes
    however busy the machine is (the wall time says how busy it was)."""
    t0, c0 = time.perf_counter(), time.process_time()
    fn()
    return time.perf_counter() - t0, time.process_time() - c0


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scans", type=int, default=100_000, help="scans in the generated bag")
    parser.add_argument("--format", default="rosbag2/sqlite3", choices=FORMATS)
    args = parser.parse_args()
    db = generate(load_world("rooms1"), args.scans, seed=0)
    with tempfile.TemporaryDirectory() as tmp:
        bag = Path(tmp) / ("run.bag" if args.format == "rosbag1" else "run")
        write_s = timed(lambda: write_bag(db, bag, args.format, beams=360))[0]
        size = sum(p.stat().st_size for p in bag.rglob("*")) if bag.is_dir() else bag.stat().st_size
        rows = []
        for name, fn in [
            ("read raw messages (reference)", lambda: read_raw(bag)),
            ("decode every message (reference)", lambda: decode_all(bag)),
            ("import_bag", lambda: import_bag(bag)),
        ]:
            rows.append((name, *timed(fn)))
    t = Table(
        title=f"import-bag, {args.scans:,} scans of 360 beams + odometry, {args.format} "
        f"({size / 2**20:,.0f} MiB, written in {write_s:.1f} s), sensorimotor {__version__}"
    )
    for col in ("stage", "wall s", "CPU s", "scans/CPU s", "1,000,000 scans (CPU s)", "x raw"):
        t.add_column(col, justify="right")
    raw_cpu = rows[0][2]
    for name, wall, cpu in rows:
        t.add_row(
            name,
            f"{wall:.2f}",
            f"{cpu:.2f}",
            f"{args.scans / cpu:,.0f}",
            f"{cpu * MILLION / args.scans:,.1f}",
            f"{cpu / raw_cpu:.1f}",
        )
    Console(width=130).print(t)
    million = rows[-1][2] * MILLION / args.scans
    verdict = "meets" if million < TARGET_S else "misses"
    print(
        f"import of 1,000,000 scans: {million:.1f} CPU s on one core"
        f"{', extrapolated' if args.scans != MILLION else ''}; {verdict} "
        f"the target of under {TARGET_S:.0f} s"
    )


if __name__ == "__main__":
    main()
