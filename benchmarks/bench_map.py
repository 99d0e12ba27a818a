"""Benchmark of the map (``analysis.chmm``): EM iterations per second of the numba kernels
(forward + backward with expected counts, on the clones of the observed cells only) beside the
plain-numpy forward-backward over every state (``tests/reference_chmm.py``) measured in the
same run, and the wall time and peak memory of fitting a 20-cell, 20-clone map (EM, then
Viterbi) on an 800,000-step training split (the split of a 1,000,000-step database), plain and
as ``sensorimotor map`` fits it by default: each clone split by 4 slow contexts, the contexts'
k-means included.

The sequence is synthetic, so that the benchmark needs no database: a random walk on a 20 x 20
torus of places, 4 actions (stay-and-turn, and three moves), each place showing one of 20
aliased cells. Target: the plain fit under 2 minutes on one core, under 2 GB (the issue's); the
split fit is held to the same.

Run by hand: ``.venv/bin/python benchmarks/bench_map.py [--steps N] [--ref-steps N]``.
"""

from __future__ import annotations

import os

os.environ["NUMBA_NUM_THREADS"] = "1"  # before numba is imported: one thread

import argparse
import resource
import sys
import time
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.table import Table

from sensorimotor.analysis.map.chmm import _backward_counts, _forward, fit_chmm
from sensorimotor.analysis.map.context import N_CONTEXTS, slow_context
from sensorimotor.version import __version__

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
import reference_chmm as ref  # the oracle lives in tests/

K, C, A = 20, 20, 4
TARGET_SECONDS = 120.0
TARGET_GB = 2.0


def walk(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(cells, actions) of a random walk on a 20 x 20 torus with aliased observations."""
    rng = np.random.default_rng(seed)
    side = 20
    look = rng.integers(0, K, side * side)  # the cell each place shows
    actions = rng.integers(0, A, n)
    moves = np.array([[0, 0], [1, 0], [0, 1], [-1, 0]])
    xy = np.cumsum(moves[actions], axis=0) % side
    xy = np.roll(xy, 1, axis=0)
    xy[0] = 0
    return look[xy[:, 0] * side + xy[:, 1]], actions


def em_rate(T, cells, actions, repeats: int = 3) -> float:
    """Steps per second of one EM iteration's passes (best of ``repeats``)."""
    alpha = np.empty((len(cells), C))
    counts = np.zeros_like(T)
    _forward(T, cells[:100], actions[:100], C, alpha)  # compile or load from the cache
    _backward_counts(T, cells[:100], actions[:100], C, alpha, counts)
    best = np.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        _forward(T, cells, actions, C, alpha)
        _backward_counts(T, cells, actions, C, alpha, counts)
        best = min(best, time.perf_counter() - t0)
    return len(cells) / best


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=800_000, help="training steps to fit")
    parser.add_argument("--ref-steps", type=int, default=2_000, help="steps for the reference")
    args = parser.parse_args()
    cells, actions = walk(args.steps)
    rng = np.random.default_rng(0)
    T = rng.random((A, K * C, K * C))
    T /= T.sum(axis=2, keepdims=True)
    fast = em_rate(T, cells, actions)
    n_ref = args.ref_steps
    t0 = time.perf_counter()
    ref.forward_backward(T, cells[:n_ref], actions[:n_ref], C)
    slow = n_ref / (time.perf_counter() - t0)
    t0 = time.perf_counter()
    model = fit_chmm(cells, actions, K, C, A, seed=0)
    fit = time.perf_counter() - t0
    peak_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # Linux: kB
    t0 = time.perf_counter()
    context = slow_context(cells, K, N_CONTEXTS, seed=0)
    split = fit_chmm(cells, actions, K, C, A, seed=0, context=context, n_contexts=N_CONTEXTS)
    fit_split = time.perf_counter() - t0
    peak_split_gb = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20  # the peak so far
    iters = len(model.history["em"]) + len(model.history["viterbi"])

    console = Console(width=110)
    table = Table(title=f"sensorimotor {__version__}: the map ({K} cells x {C} clones), one thread")
    for col in ("what", "value", "reference / target", "ratio"):
        table.add_column(col, justify="left" if col == "what" else "right")
    table.add_row(
        "EM passes, steps/s",
        f"{fast:,.0f}",
        f"{slow:,.0f} (numpy, all states)",
        f"{fast / slow:,.0f} x",
    )
    table.add_row(
        "EM iterations/s",
        f"{fast / args.steps:.2f}",
        f"on {args.steps:,} steps",
        "",
    )
    table.add_row(
        f"fit ({len(model.history['em'])} EM + {len(model.history['viterbi'])} Viterbi)",
        f"{fit:.1f} s",
        f"{TARGET_SECONDS:.0f} s",
        f"{fit / TARGET_SECONDS:.2f}",
    )
    table.add_row(
        "peak memory", f"{peak_gb:.2f} GB", f"{TARGET_GB:.0f} GB", f"{peak_gb / TARGET_GB:.2f}"
    )
    table.add_row(
        f"fit split by {N_CONTEXTS} contexts (+{len(split.history['split'])} Viterbi)",
        f"{fit_split:.1f} s",
        f"{TARGET_SECONDS:.0f} s",
        f"{fit_split / TARGET_SECONDS:.2f}",
    )
    table.add_row(
        "peak memory, split",
        f"{peak_split_gb:.2f} GB",
        f"{TARGET_GB:.0f} GB",
        f"{peak_split_gb / TARGET_GB:.2f}",
    )
    console.print(table)
    console.print(
        f"{int(model.active.sum())} active states of {K * C} ({int(split.active.sum())} of "
        f"{split.n_states} split); {iters} iterations; "
        f"cpus: {os.cpu_count()}"
    )


if __name__ == "__main__":
    main()
