"""Benchmark of training throughput at batch 64 on the CPU (or a GPU), one torch thread per process.

For S and SM: the plain eager loop (``engine.train_epoch_feedforward``: nn.Module, autograd,
``adam.FusedAdam``) beside the stacked path (``fast.stacked.train_epoch_stacked``) with K = 1, 5
and 10 seeds at once, and the candidate that derives the stacked passes from ``models.py``
with ``torch.func`` (K = 1 and 5). For Rec-S and Rec-SM, in worker processes of one thread: the
plain loop (``engine.train_epoch_recurrent``, nn.LSTM) with glibc's default allocator and with
``fast.cpu.keep_freed_memory`` (as training runs), the stacked LSTM (``stacked_lstm``) with K = 1
and 5 seeds, and two processes at once (as ``reproduce`` runs them). Rec-SMA (its memory reads
the commands; trained open loop with its kind's settings, ``TrainConfig.of``) has the plain loop
alone, its ratio to Rec-SM's plain loop of the same run. Every other ratio is to the plain
loop measured in the same run (for the recurrent models, with glibc's default allocator); the
time of one epoch over an 800,000-step train split (a 1 M-step database) is extrapolated from
the samples/s.

Every measure starts from fresh weights, so it does not see what late epochs meet: Adam
moments decaying through the subnormal range, which slowed S and SM epochs by up to 1.7x on an
Intel Xeon until training flushed them (``fast.cpu.flush_subnormals``; the bench flushes too).

The data are a generated Square database. Each measurement is the best of a few repeats of a
fixed number of batches after a warm-up. Wall-clock numbers move with the machine's load,
printed above and below the table; the cpu-time column (this process's own CPU seconds) moves
less. Run by hand: ``.venv/bin/python benchmarks/bench_train.py [--quick]``.

``--device cuda`` measures the same loops with the data on the GPU, as training runs them
there (CUDA graphs, ``cuda_graphs``): S and SM as above, Rec-S and Rec-SM through ``nn.LSTM``
(cuDNN) in 1, 2 and 4 processes; the stacked LSTM is for the CPU and left out.
"""

from __future__ import annotations

import argparse
import multiprocessing as mp
import os
import time

import torch
from rich.console import Console
from rich.table import Table
from torch import nn

from sensorimotor.learn.batches import epoch_generator, epoch_orders
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import train_epoch_feedforward, train_epoch_recurrent
from sensorimotor.learn.fast import cuda_graphs
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.fast.cpu import keep_freed_memory
from sensorimotor.learn.fast.private import adam_
from sensorimotor.learn.fast.stacked import StackedEncoders, train_epoch_stacked
from sensorimotor.learn.fast.stacked_lstm import train_epoch_stacked_recurrent
from sensorimotor.learn.fast.stacked_open_loop import train_epoch_stacked_open_loop
from sensorimotor.learn.models import build_model
from sensorimotor.sim.database import generate, scale_motors, scale_sensors
from sensorimotor.sim.world import load_world
from sensorimotor.version import __version__

BATCH, HORIZON = 64, 20
EPOCH_STEPS = 800_000  # train split of a 1 M-step database
TARGETS = {"s": 190e3, "sm": 130e3, "rec-s": 320e3, "rec-sm": 320e3}  # samples/s
STACK_TARGET = 3.0  # five stacked seeds: total samples/s over one seed's plain loop
NAMES = {"s": "S", "sm": "SM", "rec-s": "Rec-S", "rec-sm": "Rec-SM", "rec-sma": "Rec-SMA"}
STACKED_LSTM_GOAL = 4.0  # issue 38: five stacked seeds over the plain nn.LSTM loop
PAPER_SEED_MINUTES = 30  # issue 32: one paper-scale Rec-SMA seed on one core


def train_split(n: int, device: str = "cpu") -> tuple[torch.Tensor, torch.Tensor]:
    """Scaled sensors (n + 1, 5) and motors (n + 1, 2) of a generated Square database, resident
    on ``device``."""
    db = generate(load_world("square"), n + 1, seed=0)
    s = torch.from_numpy(scale_sensors(db.sensors, db.max_range))
    return s.to(device), torch.from_numpy(scale_motors(db.motors)).to(device)


def train_flops(kind: str) -> float:
    """Floating-point operations of one training sample (one step of one stream): 6 per
    multiply-add of the forward pass (2 forward, 4 backward: the input's and the weight's
    gradients). The element-wise work (gates, activations, Adam) is not counted. A motor
    memory's open-loop head predicts ``ahead`` readings from every ``ahead_every``-th step: its
    predictor runs ahead / every times a sample, its transition (ahead - 1) / every times."""
    c = TrainConfig.of(kind)
    repeats = {"predictor": c.ahead / c.ahead_every, "transition": (c.ahead - 1) / c.ahead_every}
    model = build_model(kind)
    macs = 0
    for name, mod in model.named_modules():
        if isinstance(mod, nn.Linear):
            times = repeats.get(name.split(".")[0], 1) if model.config.motor_memory else 1
            macs += mod.in_features * mod.out_features * times
        elif isinstance(mod, nn.LSTM):
            h = mod.hidden_size
            for layer in range(mod.num_layers):
                macs += 4 * h * ((mod.input_size if layer == 0 else h) + h)
    return 6.0 * macs


def sgemm_peak(size: int = 1024, repeats: int = 5, dtype: torch.dtype = torch.float32) -> float:
    """FLOP/s of one thread's matrix product (MKL or oneDNN through ``torch.mm``; float32 unless
    ``dtype``) on square matrices large enough to run at the core's arithmetic speed: the
    reference the training passes are measured against."""
    a, b = torch.randn(size, size, dtype=dtype), torch.randn(size, size, dtype=dtype)
    out = torch.empty(size, size, dtype=dtype)
    torch.mm(a, b, out=out)
    best = min(timed(lambda i: torch.mm(a, b, out=out), repeats)[0] for _ in range(2))
    return 2.0 * size**3 / best


def sync(device) -> None:
    if torch.device(device).type == "cuda":
        torch.cuda.synchronize()


def timed(fn, repeats: int, device: str = "cpu") -> tuple[float, float]:
    """Best wall and best CPU seconds of ``repeats`` calls of ``fn(i)``."""
    walls, cpus = [], []
    for i in range(repeats):
        sync(device)
        t0, c0 = time.perf_counter(), time.process_time()
        fn(i)
        sync(device)
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus)


def bench_plain_ff(kind, s, m, warm, repeats):
    model = build_model(kind, seed=0).to(s.device)
    opt = FusedAdam(model.parameters())
    train_epoch_feedforward(model, opt, *warm, BATCH, epoch_generator(0, 99))
    return timed(
        lambda i: train_epoch_feedforward(model, opt, s, m, BATCH, epoch_generator(0, i)),
        repeats,
        s.device,
    )


def bench_stacked(kind, k, s, m, warm, repeats):
    seeds = list(range(k))
    models = [build_model(kind, seed=sd).to(s.device) for sd in seeds]
    net = StackedEncoders.from_models(models)
    train_epoch_stacked(net, *warm, seeds, 99, BATCH)
    return timed(lambda i: train_epoch_stacked(net, s, m, seeds, i, BATCH), repeats, s.device)


def bench_func(kind, k, s, m, warm, repeats):
    """The candidate that derives the stacked passes from ``models.py`` itself: each step is
    ``torch.func.vmap(grad(loss))`` over the seeds' stacked weights, the loss calling the
    ``nn.Module`` through ``functional_call``, then the stacked Adam step. Same data order and
    batches as ``train_epoch_stacked`` (no 64-byte alignment of the seeds' slabs)."""
    from torch.func import functional_call, grad, vmap

    seeds = list(range(k))
    models = [build_model(kind, seed=sd).to(s.device) for sd in seeds]
    names = [name for name, _ in models[0].named_parameters()]
    params = [
        torch.stack([dict(mm.named_parameters())[n].detach() for mm in models]) for n in names
    ]
    exp_avg = [torch.zeros_like(p) for p in params]
    exp_avg_sq = [torch.zeros_like(p) for p in params]
    step = torch.zeros((), device=s.device)

    def loss(ps, xs, xm, y):
        pred, _, _ = functional_call(models[0], dict(zip(names, ps, strict=True)), (xs, xm))
        return ((pred - y) ** 2).sum(-1).mean()

    grads_of = vmap(grad(loss))

    def epoch(s, m, e):
        order = epoch_orders(len(s) - 1, seeds, e).to(s.device)  # (K, n)
        for i in range(0, order.shape[1], BATCH):
            idx = order[:, i : i + BATCH]  # (K, b)
            grads = grads_of(params, s[idx], m[idx], s[idx + 1])  # each (K, ...)
            step.add_(1)
            adam_(params, grads, exp_avg, exp_avg_sq, [step] * len(params), 1e-3)

    epoch(*warm, 99)
    return timed(lambda i: epoch(s, m, i), repeats, s.device)


def _rec_worker(kind, k, n, warm_n, keep, barrier, results, device="cpu", graphs=True):
    """One of the parallel processes, one thread: ``k`` = 0 the plain loop (nn.LSTM; on CUDA
    replayed as graphs unless ``graphs`` is False), else a stack of ``k`` seeds
    (``stacked_lstm``); timed from a start common to all processes."""
    torch.set_num_threads(1)
    torch.set_flush_denormal(True)  # as training runs (fast.cpu.flush_subnormals)
    cuda_graphs.ENABLED = graphs
    if keep:
        keep_freed_memory()
    s, m = train_split(n, device)
    warm = (s[: warm_n + 1], m[: warm_n + 1])
    if k == 0:
        model = build_model(kind, seed=0).to(device)
        opt = FusedAdam(model.parameters())

        c = TrainConfig.of(kind, batch_size=BATCH, horizon=HORIZON)
        if model.config.motor_memory:  # its own streams, horizon and open loop
            c = TrainConfig.of(kind)

        def epoch(s, m):
            train_epoch_recurrent(
                model, opt, s, m, c.batch_size, c.horizon, c.ahead, c.ahead_every
            )
    elif build_model(kind).config.motor_memory:  # its own streams, horizon and open loop
        net = StackedEncoders.from_models([build_model(kind, seed=sd) for sd in range(k)])
        c = TrainConfig.of(kind)

        def epoch(s, m):
            train_epoch_stacked_open_loop(
                net, s, m, c.batch_size, c.horizon, c.ahead, c.ahead_every
            )
    else:
        net = StackedEncoders.from_models([build_model(kind, seed=sd) for sd in range(k)])

        def epoch(s, m):
            train_epoch_stacked_recurrent(net, s, m, BATCH, HORIZON)

    epoch(*warm)
    sync(device)
    barrier.wait()
    t0, c0 = time.perf_counter(), time.process_time()
    epoch(s, m)
    sync(device)
    results.put((n * max(k, 1), time.perf_counter() - t0, time.process_time() - c0))


def bench_rec(
    kind,
    k,
    n,
    warm_n,
    workers: int,
    repeats: int,
    keep: bool = True,
    device: str = "cpu",
    graphs: bool = True,
):
    """Total samples/s (wall, cpu) of ``workers`` spawned processes training at once, each a
    stack of ``k`` seeds (0: the plain loop); ``keep``: with ``fast.cpu.keep_freed_memory``, as
    training runs, else glibc's default allocator."""
    ctx = mp.get_context("spawn")
    best, best_cpu = 0.0, 0.0
    for _ in range(repeats):
        barrier, results = ctx.Barrier(workers), ctx.Queue()
        procs = [
            ctx.Process(
                target=_rec_worker,
                args=(kind, k, n, warm_n, keep, barrier, results, device, graphs),
            )
            for _ in range(workers)
        ]
        for p in procs:
            p.start()
        done = [results.get() for _ in procs]
        for p in procs:
            p.join()
        best = max(best, sum(d[0] for d in done) / max(d[1] for d in done))
        best_cpu = max(best_cpu, sum(d[0] for d in done) / sum(d[2] for d in done) * workers)
    return best, best_cpu


def load() -> str:
    one, five, _ = os.getloadavg()
    return f"load average {one:.2f} (1 min), {five:.2f} (5 min) on {os.cpu_count()} cores"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="short run: fewer batches, 1 repeat")
    parser.add_argument("--batches", type=int, default=None, help="timed batches per measure")
    parser.add_argument("--repeats", type=int, default=None, help="repeats; the best counts")
    parser.add_argument(
        "--device",
        default="cpu",
        choices=("cpu", "cuda"),
        help="cuda: the data resident on the GPU; the stacked LSTM (CPU only) is left out",
    )
    args = parser.parse_args()
    device = args.device
    if device == "cuda" and not torch.cuda.is_available():
        parser.error("--device cuda: no CUDA device here")
    batches = args.batches or (300 if args.quick else 1500)
    repeats = args.repeats or (1 if args.quick else 3)
    torch.set_num_threads(1)
    keep_freed_memory()  # as train.train_runs does
    torch.set_flush_denormal(True)  # likewise (fast.cpu.flush_subnormals)
    console = Console(width=150)
    where = torch.backends.cpu.get_cpu_capability()
    if device == "cuda":
        where = f"{torch.cuda.get_device_name(0)} (CUDA {torch.version.cuda}), CPU {where}"
    console.print(
        f"sensorimotor {__version__}, torch {torch.__version__}, batch {BATCH}, 1 thread, "
        f"{batches} batches a measure (best of {repeats}), {device}: {where}"
    )
    console.print(f"before: {load()}")

    peak = sgemm_peak()  # on the CPU; a GPU row's share of it says nothing
    flops = {kind: train_flops(kind) for kind in NAMES}
    console.print(
        f"peak: one thread's float32 matrix product (MKL, 1024 x 1024 x 1024): "
        f"{peak / 1e9:.0f} GFLOP/s"
    )
    n = batches * BATCH
    s, m = train_split(n, device)
    warm = (s[: 20 * BATCH + 1], m[: 20 * BATCH + 1])
    table = Table(title=f"Training throughput on {device} (samples/s; wall clock unless marked)")
    for col in (
        "model",
        "path",
        "per seed",
        "total",
        "total (cpu time)",
        "vs plain",
        "800k epoch",
        "GFLOP/s",
        "of peak",
        "target",
    ):
        table.add_column(col, justify="left" if col in ("model", "path", "target") else "right")

    def row(kind, path, per_seed, total, cpu_total, plain, target=""):
        table.add_row(
            NAMES[kind],
            path,
            f"{per_seed / 1e3:,.0f} k",
            f"{total / 1e3:,.0f} k",
            "" if cpu_total is None else f"{cpu_total / 1e3:,.0f} k",
            f"{total / plain:.2f}x",
            f"{EPOCH_STEPS / per_seed:.1f} s",
            f"{total * flops[kind] / 1e9:.0f}",
            f"{total * flops[kind] / peak:.0%}",
            target,
        )

    for kind in ("s", "sm"):
        wall, cpu = bench_plain_ff(kind, s, m, warm, repeats)
        plain = n / wall
        row(kind, "plain loop (autograd)", plain, plain, n / cpu, plain)
        one = None
        for k in (1, 5, 10):
            wall, cpu = bench_stacked(kind, k, s, m, warm, repeats)
            per_seed = n / wall
            total = k * per_seed
            if k == 1:
                one = total
                met = "met" if total >= TARGETS[kind] else "NOT met"
                target = f">= {TARGETS[kind] / 1e3:.0f} k: {met}"
            elif k == 5:  # the "one" is a seed trained the plain way
                met = "met" if total / plain >= STACK_TARGET else "NOT met"
                target = f">= {STACK_TARGET:.0f}x plain: {met}; {total / one:.2f}x K = 1"
            else:
                target = f"{total / one:.2f}x K = 1"
            row(kind, f"stacked, K = {k}", per_seed, total, k * n / cpu, plain, target)
            if k == 5:
                ours = total
        for k in (1, 5):  # the candidate derived from models.py, against the passes by hand
            wall, cpu = bench_func(kind, k, s, m, warm, repeats)
            total = k * n / wall
            ref = one if k == 1 else ours
            target = f"{total / ref:.2f}x stacked K = {k}"
            row(
                kind,
                f"torch.func from models.py, K = {k}",
                n / wall,
                total,
                k * n / cpu,
                plain,
                target,
            )
        console.print(f"  {kind} done ({load()})")

    bounds = {}  # recurrent kind: (plain, five stacked) samples/s
    rec_n = max(batches, 200) * BATCH  # at least 10 chunks of 20 steps in every stream
    warm_n = 2 * HORIZON * BATCH
    for kind in ("rec-s", "rec-sm"):
        if device == "cuda":  # nn.LSTM runs cuDNN; the stacked LSTM is for the CPU
            args = (kind, 0, rec_n, warm_n)
            plain, cpu = bench_rec(*args, 1, repeats, device=device, graphs=False)
            row(kind, "plain loop (nn.LSTM, cuDNN), eager", plain, plain, cpu, plain)
            one = None
            for workers in (1, 2, 4):
                total, cpu = bench_rec(*args, workers, repeats, device=device)
                one = one or total
                path = f"{workers} process{'es' if workers > 1 else ''}, CUDA graphs"
                row(kind, path, total / workers, total, cpu, plain, f"{total / one:.2f}x one")
            console.print(f"  {kind} done ({load()})")
            continue
        plain, cpu = bench_rec(kind, 0, rec_n, warm_n, 1, repeats, keep=False)
        row(kind, "plain loop (nn.LSTM), glibc default", plain, plain, cpu, plain)
        total, cpu = bench_rec(kind, 0, rec_n, warm_n, 1, repeats)
        row(kind, "plain loop (nn.LSTM)", total, total, cpu, plain)
        one = None
        for k in (1, 5):
            total, cpu = bench_rec(kind, k, rec_n, warm_n, 1, repeats)
            one = one or total
            target = "" if k == 1 else f"{total / one:.2f}x K = 1"
            row(kind, f"stacked LSTM, K = {k}", total / k, total, cpu, plain, target)
            stacked_five = total
        total, cpu = bench_rec(kind, 0, rec_n, warm_n, 2, repeats)
        row(kind, "2 processes, plain loop", total / 2, total, cpu, plain)
        total, cpu = bench_rec(kind, 5, rec_n, warm_n, 2, repeats)
        met = "met" if total >= TARGETS[kind] else "NOT met"
        target = f">= {TARGETS[kind] / 1e3:.0f} k: {met}"
        row(kind, "2 processes, stacked K = 5", total / 10, total, cpu, plain, target)
        console.print(f"  {kind} done ({load()})")
        rec_sm_plain = plain
        bounds[kind] = (plain, stacked_five)
    if device == "cpu":
        c = TrainConfig.of("rec-sma")
        total, cpu = bench_rec("rec-sma", 0, rec_n, warm_n, 1, repeats)
        epochs = PAPER_SEED_MINUTES * 60 * total / EPOCH_STEPS
        path = f"plain loop, {c.ahead} ahead from every {c.ahead_every}, BPTT {c.horizon}"
        target = f"vs Rec-SM's plain; {epochs:.0f} paper epochs in {PAPER_SEED_MINUTES} min"
        row("rec-sma", path, total, total, cpu, rec_sm_plain, target)
        plain = total
        for k, workers in ((1, 1), (5, 1), (5, 2)):  # issue 38 item 2: stacked seeds
            total, cpu = bench_rec("rec-sma", k, rec_n, warm_n, workers, repeats)
            path = f"stacked, K = {k}" + (f", {workers} processes" if workers > 1 else "")
            target = f"{total / plain:.2f}x Rec-SMA's plain loop"
            row("rec-sma", path, total / (k * workers), total, cpu, rec_sm_plain, target)
        console.print(f"  rec-sma done ({load()})")

    console.print(table)
    console.print(f"after: {load()}")
    for kind, (plain, five) in bounds.items():  # issue 38: five stacked seeds at 4x the plain loop
        need = STACKED_LSTM_GOAL * plain * flops[kind]
        console.print(
            f"{NAMES[kind]}: {STACKED_LSTM_GOAL:.0f}x the plain loop would be "
            f"{need / 1e9:.0f} GFLOP/s of products alone, {need / peak:.0%} of the peak; "
            f"five stacked seeds run at {five / plain:.2f}x ({five * flops[kind] / peak:.0%})"
        )
    console.print(
        "per seed: samples/s of each seed; total: of all seeds (or processes) together; "
        "800k epoch: one epoch of every seed over 800,000 steps at the per-seed rate; "
        "GFLOP/s: the total's matrix-product arithmetic (train_flops), of peak: its share of "
        "one thread's float32 matrix product measured above (Rec-SMA's open loop counted as "
        "one-step samples)."
    )


if __name__ == "__main__":
    main()
