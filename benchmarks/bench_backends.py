"""Benchmark: what Ray adds over the local worker processes on this machine, on one quick grid.

The same work three ways, each from a fresh output folder: the grid's trainings as jobs of the
local worker pool (``jobs.workers.run_jobs``), the same jobs as Ray tasks
(``jobs.ray_backend.run_jobs``), and the same grid as a ``sweep --backend ray`` (Ray Tune,
an actor per running trial, ASHA ending some trials early: less training, more machinery).
Before them, empty jobs measure the cost of jobs alone, and ``ray.init`` the cost of starting a
local Ray. Every call of the local pool starts its worker processes (each imports torch); Ray's
workers, once started, serve every later call: the last two rows compare the whole, start
included. Every ratio is to the local pool measured in the same run. Wall-clock numbers move with
the machine's load. Run by hand:
``.venv/bin/python benchmarks/bench_backends.py [--trials 8] [--epochs 2] [--workers 2]``.
"""

from __future__ import annotations

import argparse
import itertools
import tempfile
import time
from pathlib import Path

from rich.console import Console
from rich.table import Table

from sensorimotor.jobs import ray_backend, workers
from sensorimotor.jobs.workers import Job
from sensorimotor.pipeline.sweep import _trial_job, read_sweep, run_sweep
from sensorimotor.sim.database import generate, save_database
from sensorimotor.sim.world import load_world

LRS = (3e-4, 1e-3, 3e-3, 1e-2)
BATCHES = (32, 64, 128, 256)


def _nothing(x: int) -> int:
    return x


def _grid(folder: Path, trials: int, epochs: int, model: str) -> Path:
    pairs = list(itertools.product(LRS, BATCHES))[:trials]
    lrs = sorted({lr for lr, _ in pairs})
    batches = sorted({b for _, b in pairs})
    path = folder / "grid.toml"
    path.write_text(
        f'data = "db.npz"\n[train]\nmodel = "{model}"\nmax_epochs = {epochs}\n'
        f"[space]\nlr = {list(lrs)}\nbatch_size = {list(batches)}\n"
    )
    return path


def _train_jobs(spec: Path, out: Path) -> list[Job]:
    sweep = read_sweep(spec)
    (out / "runs").mkdir(parents=True)
    return [
        Job(t.name, _trial_job, (t.name, t.data, str(out / "runs" / t.name), t.config))
        for t in sweep.trials
    ]


def _timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def _epochs(out: Path) -> int:
    return sum(len(p.read_text().splitlines()) - 1 for p in out.glob("runs/*/history.csv"))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--trials", type=int, default=8, help="grid points (lr x batch size)")
    parser.add_argument("--epochs", type=int, default=2, help="epochs per trial")
    parser.add_argument("--steps", type=int, default=20_000, help="database rows")
    parser.add_argument("--model", default="s", help="s, sm, rec-s or rec-sm")
    parser.add_argument("--workers", type=int, default=2, help="jobs at a time")
    parser.add_argument("--empty", type=int, default=64, help="empty jobs")
    args = parser.parse_args()
    console = Console()
    ray = ray_backend.import_ray()
    folder = Path(tempfile.mkdtemp(prefix="bench_backends_"))
    save_database(generate(load_world("square"), args.steps, seed=0), folder / "db.npz")
    spec = _grid(folder, args.trials, args.epochs, args.model)
    n = len(read_sweep(spec).trials)
    w = args.workers
    empty = [Job(str(i), _nothing, (i,)) for i in range(args.empty)]
    rows = []
    local_empty = _timed(lambda: workers.run_jobs(empty, w))
    local_grid = _timed(lambda: workers.run_jobs(_train_jobs(spec, folder / "local"), w))
    start = _timed(lambda: ray.init(num_cpus=w, include_dashboard=False, logging_level="ERROR"))
    ray_empty = _timed(lambda: ray_backend.run_jobs(empty, w))
    ray_grid = _timed(lambda: ray_backend.run_jobs(_train_jobs(spec, folder / "ray"), w))
    tune = _timed(lambda: run_sweep(spec, folder / "tune", "ray", workers=w, log=lambda _: None))
    ray.shutdown()
    rows = [
        ("local pool", f"{args.empty} empty jobs", local_empty, local_empty, None),
        ("Ray tasks", f"{args.empty} empty jobs", ray_empty, local_empty, None),
        ("local pool", f"{n} trainings", local_grid, local_grid, _epochs(folder / "local")),
        ("Ray tasks", f"{n} trainings", ray_grid, local_grid, _epochs(folder / "ray")),
        ("Ray Tune + ASHA", f"{n} trials", tune, local_grid, _epochs(folder / "tune")),
        ("ray.init", "a local Ray started", start, None, None),
        (
            "local pool",
            "empty + trainings",
            local_empty + local_grid,
            local_empty + local_grid,
            None,
        ),
        (
            "Ray tasks",
            "ray.init + empty + trainings",
            start + ray_empty + ray_grid,
            local_empty + local_grid,
            None,
        ),
    ]
    table = Table(
        title=f"{n} x {args.model} for {args.epochs} epochs on {args.steps:,} rows, "
        f"{w} workers ({folder})"
    )
    for col in ("backend", "work", "wall s", "x local", "epochs trained"):
        table.add_column(col, justify="right")
    for backend, work, seconds, ref, epochs in rows:
        ratio = "" if ref is None else f"{seconds / ref:.2f}"
        table.add_row(backend, work, f"{seconds:.2f}", ratio, "" if epochs is None else str(epochs))
    console.print(table)


if __name__ == "__main__":
    main()
