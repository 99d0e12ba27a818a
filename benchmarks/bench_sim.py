"""Benchmark of the simulation core: steps per second of ``sim.rollout`` (numba, one thread)
on each built-in world, beside the plain-Python reference measured in the same run, and the
end-to-end wall time of ``sensorimotor generate WORLD --steps 1000000``.

Run by hand: ``.venv/bin/python benchmarks/bench_sim.py [--steps N] [--ref-steps N] [--no-cli]``.
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported: one thread, as promised

import argparse
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from sensorimotor.sim import core as sim
from sensorimotor.sim.world import BUILTIN_WORLDS, load_world
from sensorimotor.version import __version__

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
import reference_sim as ref  # the oracle lives in tests/

TARGETS = {"square": 4e6, "rooms1": None, "rooms2": 2.5e6}  # steps/s the core must reach
STRETCH = 8e6


def best_of(fn, repeats: int) -> float:
    """Smallest wall time of ``repeats`` calls (seconds): the least disturbed measurement."""
    times = []
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return min(times)


def bench_core(world, steps: int, repeats: int) -> float:
    sim.rollout(world, 1_000, seed=0)  # warm-up: JIT compile or load from the cache
    return steps / best_of(lambda: sim.rollout(world, steps, seed=0), repeats)


def bench_reference(world, steps: int) -> float:
    rng = np.random.default_rng(0)
    start = sim.sample_start(world, rng)
    uniforms = rng.random((steps, 2)).tolist()
    segments = [tuple(s) for s in world.segments.tolist()]
    angles = sim.SENSOR_ANGLES.tolist()
    t0 = time.perf_counter()
    ref.rollout(segments, angles, sim.MAX_RANGE, start, uniforms)
    return steps / (time.perf_counter() - t0)


def bench_cli(name: str, steps: int) -> float:
    with tempfile.TemporaryDirectory() as folder:
        out = Path(folder) / "db.npz"
        t0 = time.perf_counter()
        proc = subprocess.run(
            [sys.executable, "-m", "sensorimotor", "generate", name, "--steps", str(steps),
             "--out", str(out)],
            capture_output=True, text=True, env={**os.environ, "NUMBA_NUM_THREADS": "1"},
        )  # fmt: skip
        elapsed = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"generate {name} failed:\n{proc.stderr}")
    return elapsed


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000, help="steps per core run")
    parser.add_argument("--ref-steps", type=int, default=20_000, help="steps of the reference")
    parser.add_argument("--repeats", type=int, default=5, help="core runs; the best counts")
    parser.add_argument("--no-cli", action="store_true", help="skip the end-to-end generate")
    args = parser.parse_args()

    console = Console(width=110)
    table = Table(title=f"sensorimotor {__version__}: simulation core, one thread")
    for col in ("world", "walls", "core steps/s", "reference steps/s", "ratio", "target",
                "stretch 8 M", "generate 1M (s)"):  # fmt: skip
        table.add_column(col, justify="right" if col != "world" else "left")
    for name in BUILTIN_WORLDS:
        world = load_world(name)
        core = bench_core(world, args.steps, args.repeats)
        reference = bench_reference(world, args.ref_steps)
        target = TARGETS[name]
        verdict = "-"
        if target is not None:
            ok = "[green]ok[/]" if core >= target else "[red]BELOW[/]"
            verdict = f">= {target / 1e6:g} M {ok}"
        stretch = "[green]yes[/]" if core >= STRETCH else "no"
        wall = f"{bench_cli(name, 1_000_000):.2f}" if not args.no_cli else "-"
        table.add_row(
            name,
            str(len(world.segments)),
            f"{core / 1e6:.2f} M",
            f"{reference / 1e3:.0f} k",
            f"{core / reference:,.0f} x",
            verdict,
            stretch,
            wall,
        )
    console.print(table)
    console.print(
        f"core: best of {args.repeats} runs of {args.steps:,} steps (sim.rollout, float64, "
        f"uniforms drawn included) after a warm-up; reference: {args.ref_steps:,} steps of "
        "tests/reference_sim.py in the same process; generate: `python -m sensorimotor generate "
        "WORLD --steps 1000000` end to end in a subprocess (imports, JIT cache, float32, .npz)."
    )
    console.print(f"numba threads: {os.environ['NUMBA_NUM_THREADS']}, cpus: {os.cpu_count()}")


if __name__ == "__main__":
    main()
