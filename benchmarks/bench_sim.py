"""Benchmark of the simulation core: steps per second of ``sim.rollout`` (numba, one thread)
on each built-in world, beside the plain-Python reference measured in the same run, and the
end-to-end wall time of ``sensorimotor generate WORLD --steps 1000000``.

Then the grid (``sim.grid``) against the all-walls loop, both measured in this run: steps/s
of ``sim.rollout`` in worlds of 4, 100, 1,000 and 10,000 walls with 5 (the paper's), 64 and
360 rays (a full turn); target: 1,000 walls and 64 rays at 100,000 steps/s or more. With
``--baseline-src DIR`` (a checkout's ``src`` of the code before, e.g. ``/work/main/src``) the
paper's worlds are also timed with that code, in a subprocess, in the same run.

Run by hand: ``.venv/bin/python benchmarks/bench_sim.py [--steps N] [--ref-steps N] [--no-cli]
[--no-scaling] [--baseline-src DIR]``.
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


def walls_world(n: int, seed: int = 0):
    """A square world of ``n`` walls (4 outer, the rest axis-aligned, 2 to 5 units long, on
    integer points), 5 sqrt(n) units a side: about the density of an office floor."""
    from sensorimotor.sim.world import world_from_dict

    side = float(max(20, round(5 * n**0.5)))
    rng = np.random.default_rng(seed)
    walls = []
    while len(walls) < n - 4:
        x0, y0, k = int(rng.integers(0, side)), int(rng.integers(0, side)), int(rng.integers(2, 6))
        horizontal = rng.random() < 0.5
        wall = [x0, y0, min(x0 + k, side), y0] if horizontal else [x0, y0, x0, min(y0 + k, side)]
        if wall[:2] != wall[2:]:
            walls.append(wall)
    return world_from_dict({"name": f"walls{n}", "size": side, "walls": walls})


def steps_per_s(fn, budget: float = 0.5) -> float:
    """Steps/s of ``fn(steps)``: steps grown until one call takes ``budget`` s, best of 3."""
    fn(50)  # warm-up: JIT compile or load from the cache
    steps = 200
    while True:
        t = best_of(lambda k=steps: fn(k), 1)
        if t >= budget / 4 or steps >= 2_000_000:
            break
        steps *= 4
    return steps / best_of(lambda: fn(steps), 3)


def bench_scaling(console: Console) -> None:
    from sensorimotor.sim.grid import NO_GRID

    table = Table(title="grid index vs all-walls loop: sim.rollout steps/s, one thread")
    for col in ("walls", "rays", "grid steps/s", "all-walls steps/s", "ratio", "target"):
        table.add_column(col, justify="right")
    for n in (4, 100, 1_000, 10_000):
        world = walls_world(n)
        for rays in (5, 64, 360):
            layout = sim.DEFAULT_LAYOUT if rays == 5 else sim.spread_layout(rays, 2 * np.pi)
            fast = steps_per_s(lambda k, w=world, la=layout: sim.rollout(w, k, 0, la))
            plain = steps_per_s(
                lambda k, w=world, la=layout: sim.rollout(w, k, 0, la, grid=NO_GRID)
            )
            target = "-"
            if (n, rays) == (1_000, 64):
                target = ">= 100 k " + ("[green]ok[/]" if fast >= 1e5 else "[red]BELOW[/]")
            table.add_row(f"{len(world.segments):,}", str(rays), f"{fast:,.0f}", f"{plain:,.0f}",
                          f"{fast / plain:.1f} x", target)  # fmt: skip
    console.print(table)
    console.print("grid: World.grid (none below GRID_MIN_WALLS walls: the same loop); all-walls: "
                  "grid=NO_GRID; 5 rays: the paper's layout, else spread over a full turn.")  # fmt: skip


BASELINE = """
import sys, time
from sensorimotor.sim import core as sim
from sensorimotor.sim.world import load_world
w = load_world(sys.argv[1]); steps = int(sys.argv[2])
sim.rollout(w, 1000, seed=0)
best = min((lambda t0: (sim.rollout(w, steps, seed=0), time.perf_counter() - t0)[1])(time.perf_counter()) for _ in range(5))
print(steps / best)
"""


def bench_baseline(console: Console, src: str, steps: int, rounds: int = 3) -> None:
    table = Table(title=f"paper worlds: this code vs {src}, sim.rollout steps/s, one thread")
    for col in ("world", "this code", "baseline", "ratio", "within 10 %"):
        table.add_column(col, justify="right")
    for name in BUILTIN_WORLDS:
        rates = [0.0, 0.0]
        for _ in range(rounds):  # alternated, best of each: a busy machine slows both alike
            for i, path in enumerate((str(Path(__file__).resolve().parent.parent / "src"), src)):
                env = {**os.environ, "PYTHONPATH": path, "NUMBA_NUM_THREADS": "1"}
                out = subprocess.run([sys.executable, "-c", BASELINE, name, str(steps)], env=env,
                                     capture_output=True, text=True, check=True, cwd=tempfile.gettempdir())  # fmt: skip
                rates[i] = max(rates[i], float(out.stdout))
        ratio = rates[0] / rates[1]
        table.add_row(name, f"{rates[0] / 1e6:.2f} M", f"{rates[1] / 1e6:.2f} M", f"{ratio:.2f}",
                      "[green]yes[/]" if ratio >= 0.9 else "[red]NO[/]")  # fmt: skip
    console.print(table)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=1_000_000, help="steps per core run")
    parser.add_argument("--ref-steps", type=int, default=20_000, help="steps of the reference")
    parser.add_argument("--repeats", type=int, default=5, help="core runs; the best counts")
    parser.add_argument("--no-cli", action="store_true", help="skip the end-to-end generate")
    parser.add_argument("--no-scaling", action="store_true", help="skip grid vs all-walls")
    parser.add_argument("--only-scaling", action="store_true", help="only grid vs all-walls")
    parser.add_argument("--baseline-src", help="time the paper's worlds with this src too")
    args = parser.parse_args()
    console = Console(width=110)
    if args.baseline_src:
        bench_baseline(console, args.baseline_src, args.steps)
    if not args.no_scaling:
        bench_scaling(console)
    if args.only_scaling:
        return

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
