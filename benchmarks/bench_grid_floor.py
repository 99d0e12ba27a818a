"""The arithmetic floor of the paper grid (issue 38): the least time this CPU needs for
``reproduce --scale paper --seeds 5 --workers 2``'s trainings, whatever the implementation.

Each kind's training costs its seed-epochs (the shipped paper-scale runs' ``result.json``,
``docs/results/runs``: early stopping decides them, a stacked seed leaves its stack when it
stops) times 800,000 samples an epoch times its matrix-product flops a sample
(``bench_train.train_flops``: element-wise work, validation, evaluation and analysis not
counted). Divided by two cores at one thread's matrix-product peak, measured in this run in
float32 (what training runs in) and in bfloat16 (the reduced precision the issue allows; on
AVX512-BF16 or AMX hardware), it is a floor: no schedule and no kernel trains the grid faster
in that precision. Beside each goal the share of the peak the grid would have to sustain.

Then what bfloat16 could buy the heaviest paper kind: every matrix product of a chunk of
Rec-SM's stacked training (five seeds, 64 streams x 20 steps; shapes and calls from
a wrapper of ``torch.bmm`` and ``torch.baddbmm``) timed alone, operands laid out as recorded, in float32 and in bfloat16, and the chunk's time if each ran in
the faster of the two with its conversions free: an upper bound on the candidate, measured
before writing it.

Run by hand: ``.venv/bin/python benchmarks/bench_grid_floor.py [--runs DIR] [--measured MIN]``
(``--measured``: a timed grid's minutes, to print the share of the peak it reached).
"""

from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path
from unittest import mock

import torch
from rich.console import Console
from rich.table import Table

from bench_train import BATCH, HORIZON, NAMES, sgemm_peak, timed, train_flops, train_split
from sensorimotor.learn.fast.cpu import keep_freed_memory
from sensorimotor.learn.fast.stacked import StackedEncoders
from sensorimotor.learn.fast.stacked_lstm import train_epoch_stacked_recurrent
from sensorimotor.learn.models import build_model

EPOCH_STEPS = 800_000  # train split of the paper's 1,000,000-step databases
CORES = 2
GOALS = {
    "the paper's four kinds": (("s", "sm", "rec-s", "rec-sm"), 20.0),
    "with Rec-SMA": (("s", "sm", "rec-s", "rec-sm", "rec-sma"), 30.0),
}  # issue 38: minutes on the 2-core CPU


def seed_epochs(runs: Path) -> dict[str, int]:
    """Epochs trained by every shipped paper-scale seed, summed per kind (each run folder's
    ``config.json`` and ``result.json``)."""
    out: dict[str, int] = defaultdict(int)
    for result in sorted(runs.glob("*/result.json")):
        kind = json.loads((result.parent / "config.json").read_text())["model"]["kind"]
        out[kind] += json.loads(result.read_text())["epochs"]
    return dict(out)


def best_time(fn, calls: int = 200, repeats: int = 5) -> float:
    """Best seconds a call of ``fn`` (``bench_train.timed`` over ``calls`` calls), warmed up."""
    for _ in range(10):
        fn()
    return timed(lambda i: [fn() for _ in range(calls)], repeats)[0] / calls


def chunk_products(kind: str = "rec-sm", k: int = 5, chunks: int = 50):
    """A stacked chunk's seconds, and {(op, operands' shapes and strides): calls a chunk} of
    its products, recorded by wrapping ``torch.bmm`` and ``torch.baddbmm`` for one epoch."""
    s, m = train_split(BATCH * HORIZON * chunks)
    net = StackedEncoders.from_models([build_model(kind, seed=sd) for sd in range(k)])
    warm = 4 * BATCH * HORIZON + 1
    train_epoch_stacked_recurrent(net, s[:warm], m[:warm], BATCH, HORIZON)
    chunk = best_time(lambda: train_epoch_stacked_recurrent(net, s, m, BATCH, HORIZON), 1, 3)
    calls: dict = defaultdict(float)

    def recording(op):
        def call(*args, **kwargs):
            operands = tuple((tuple(a.shape), a.stride()) for a in args if torch.is_tensor(a))
            calls[(op.__name__, operands)] += 1 / chunks
            return op(*args, **kwargs)

        return call

    with (
        mock.patch.object(torch, "bmm", recording(torch.bmm)),
        mock.patch.object(torch, "baddbmm", recording(torch.baddbmm)),
    ):
        train_epoch_stacked_recurrent(net, s, m, BATCH, HORIZON)
    return chunk / chunks, dict(calls)


def product_seconds(op: str, operands, dtype: torch.dtype) -> float:
    """One call of ``op`` on fresh operands of the recorded shapes and strides in ``dtype``."""
    args = [
        torch.randn(
            1 + sum((n - 1) * d for n, d in zip(sh, st, strict=True)), dtype=dtype
        ).as_strided(sh, st)
        for sh, st in operands
    ]  # a stride 0 (an operand broadcast over the seeds) stays one
    fn = getattr(torch, op)
    return best_time(lambda: fn(*args))


def contiguous(shape: tuple[int, ...]) -> tuple[int, ...]:
    """The strides of a contiguous tensor of ``shape``."""
    return torch.empty(shape).stride()


def bf16_bound(console: Console) -> None:
    """The table of Rec-SM's chunk products in float32 and bfloat16, and the bound."""
    chunk, calls = chunk_products()
    table = Table(title="Rec-SM, 5 stacked seeds: the products of one chunk (64 x 20 steps)")
    for col in (
        "product",
        "operands (T: not contiguous)",
        "calls",
        "float32 us",
        "bfloat16 us",
        "faster",
    ):
        table.add_column(
            col, justify="right" if col in ("calls",) or "us" in col or col == "faster" else "left"
        )
    rows = []
    for (op, shapes), n in calls.items():
        a, b = (product_seconds(op, shapes, dt) for dt in (torch.float32, torch.bfloat16))
        rows.append((n * a, op, shapes, n, a, b))
    f32 = sum(r[0] for r in rows)
    f16 = sum(n * min(a, b) for _, _, _, n, a, b in rows)
    for _, op, shapes, n, a, b in sorted(rows, key=lambda r: -r[0]):
        operands = " x ".join(
            f"{list(sh)}{'' if st == contiguous(sh) else ' T'}" for sh, st in shapes
        )
        table.add_row(op, operands, f"{n:g}", f"{a * 1e6:.1f}", f"{b * 1e6:.1f}", f"{a / b:.2f}x")
    console.print(table)
    console.print(
        f"a chunk {chunk * 1e3:.1f} ms, its products timed alone {f32 * 1e3:.1f} ms in float32, "
        f"{f16 * 1e3:.1f} ms each in the faster precision: with free conversions at most "
        f"{chunk / (chunk - f32 + f16):.2f}x on Rec-SM"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, default=Path("docs/results/runs"))
    parser.add_argument("--measured", type=float, default=None, help="a timed grid, minutes")
    args = parser.parse_args()
    torch.set_num_threads(1)
    torch.set_flush_denormal(True)  # as training runs (fast.cpu.flush_subnormals)
    keep_freed_memory()
    epochs = seed_epochs(args.runs)
    if not epochs:
        raise SystemExit(f"error: no run folders with a result.json in {args.runs}")
    peaks = {"float32": sgemm_peak(), "bfloat16": sgemm_peak(dtype=torch.bfloat16)}
    console = Console(width=140)
    console.print(
        f"torch {torch.__version__}, {torch.backends.cpu.get_cpu_capability()}; one thread's "
        f"matrix-product peak: float32 {peaks['float32'] / 1e9:.0f} GFLOP/s, "
        f"bfloat16 {peaks['bfloat16'] / 1e9:.0f} GFLOP/s (measured now); runs from {args.runs}"
    )
    table = Table(title=f"Training flops of the paper grid and their floor on {CORES} cores")
    for col in ("kind", "seed-epochs", "kFLOP a sample", "TFLOP", "float32 floor", "bf16 floor"):
        table.add_column(col, justify="left" if col == "kind" else "right")
    tflop = {}
    for kind in NAMES:
        if kind not in epochs:
            continue
        tflop[kind] = epochs[kind] * EPOCH_STEPS * train_flops(kind) / 1e12
        floors = [f"{tflop[kind] * 1e12 / p / CORES / 60:.1f} min" for p in peaks.values()]
        row = [NAMES[kind], f"{epochs[kind]:,}", f"{train_flops(kind) / 1e3:.1f}"]
        table.add_row(*row, f"{tflop[kind]:.1f}", *floors)
    console.print(table)
    for name, (kinds, goal) in GOALS.items():
        if not all(k in tflop for k in kinds):
            continue
        total = sum(tflop[k] for k in kinds) * 1e12
        floor32, floor16 = (total / p / CORES / 60 for p in peaks.values())
        console.print(
            f"{name}: floor {floor32:.1f} min in float32 ({floor16:.1f} in bfloat16); the goal "
            f"of {goal:.0f} min asks {floor32 / goal:.0%} of the float32 peak "
            f"({floor16 / goal:.0%} of the bfloat16 one), sustained through every training"
        )
        if args.measured and kinds == GOALS["the paper's four kinds"][0]:
            console.print(
                f"  the timed grid, {args.measured:.1f} min, ran at {floor32 / args.measured:.0%} "
                "of the float32 peak, its evaluation and analysis counted as time"
            )
    bf16_bound(console)


if __name__ == "__main__":
    main()
