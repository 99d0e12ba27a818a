"""Training by sensorimotor prediction: Adam, batch 64, the paper's early stopping, TBPTT.

Feed-forward models (S, SM) see the train split's transitions (s_t, m_t) -> s_{t+1} shuffled,
every one once per epoch. Recurrent models see the train split cut into 64 contiguous streams;
each batch is the next 20 steps of every stream, the LSTM state carried (detached) from one
batch to the next and reset at each epoch (truncated back-propagation through time).

The data live as tensors and are gathered once per epoch so that each batch is a view; Adam is
fused; nothing in the step loop talks to the host. What a run is and what its folder holds is in
``runs.py``.
"""

from __future__ import annotations

import contextlib
import time
from collections.abc import Callable, Iterator
from dataclasses import asdict
from pathlib import Path

import torch

from sensorimotor import cuda_graphs
from sensorimotor.data import Database, database_file, load_database
from sensorimotor.errors import InputError
from sensorimotor.evaluate import model_error, split_tensors
from sensorimotor.models import ModelConfig, build_model
from sensorimotor.runs import (
    EarlyStopping,
    EpochRecord,
    TrainConfig,
    TrainResult,
    check_device,
    check_run_dir,
    finish_run,
    load_checkpoint,
    open_run_dir,
    run_meta,
    save_epoch,
    stored_result,
)


def stream_layout(n: int, streams: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Cut ``n`` steps into ``streams`` contiguous streams: (index (streams, L), mask (streams, L)).

    Stream k holds steps ``index[k, :]`` in order; lengths differ by at most one (the first
    ``n % streams`` are one longer) and the shorter ones are padded at the end with mask False,
    so every step appears exactly once.
    """
    if n < streams:
        raise ValueError(f"{n} steps cannot fill {streams} streams")
    base, extra = divmod(n, streams)
    length = base + (extra > 0)
    lengths = torch.full((streams,), base)
    lengths[:extra] += 1
    starts = torch.cumsum(lengths, 0) - lengths
    offsets = torch.arange(length)
    mask = offsets[None, :] < lengths[:, None]  # (streams, L)
    index = torch.where(mask, starts[:, None] + offsets[None, :], 0)  # (streams, L)
    return index, mask


def epoch_generator(seed: int, epoch: int) -> torch.Generator:
    """The data order of one epoch depends on (seed, epoch) alone, so --resume repeats it."""
    return torch.Generator().manual_seed(seed * 1_000_003 + epoch)


def train_epoch_feedforward(model, opt, s, m, batch: int, gen: torch.Generator) -> float:
    """One epoch over shuffled transitions; returns the mean training error.

    The plain autograd loop: ``train`` runs S and SM through ``stacked`` instead, which tests and
    ``benchmarks/bench_train.py`` check against this, to float32 rounding and in speed.
    """
    n = len(s) - 1
    perm = torch.randperm(n, generator=gen).to(s.device)
    xs, xm, y = s[:-1][perm], m[:-1][perm], s[1:][perm]  # (n, 5), (n, 2), (n, 5) gathered once
    total = torch.zeros((), device=s.device)
    for i in range(0, n, batch):
        pred, _, _ = model(xs[i : i + batch], xm[i : i + batch])  # (b, 5)
        loss = ((pred - y[i : i + batch]) ** 2).sum(-1).mean()
        opt.zero_grad()
        loss.backward()
        opt.step()
        total += loss.detach() * len(pred)
    return float(total) / n


def train_epoch_recurrent(model, opt, s, m, streams: int, horizon: int) -> float:
    """One epoch of truncated BPTT over ``streams`` contiguous streams; mean training error.

    On CUDA the chunks that no stream's end pads run as one replayed graph each
    (``cuda_graphs``): the same arithmetic, a fraction of the launches."""
    n = len(s) - 1
    index, mask = stream_layout(n, streams)
    graphed = 0  # leading steps of every stream run by the graph
    if cuda_graphs.enabled(s):
        unmasked = int(mask.all(0).long().cumprod(0).sum())  # columns before the first pad
        graphed = unmasked // horizon * horizon
    w = None if bool(mask.all()) else mask.float().to(s.device)  # (streams, L)
    index = index.to(s.device)
    xs, xm, y = s[:-1][index], m[:-1][index], s[1:][index]  # (streams, L, 5|2|5)
    total = torch.zeros((), device=s.device)
    state = None
    if graphed:
        step = cuda_graphs.recurrent_step(model, opt, streams, horizon)
        step.h.zero_()
        step.c.zero_()
        total = step.total.zero_()
        for j in range(0, graphed, horizon):
            for buf, src in ((step.x, xs), (step.xm, xm), (step.y, y)):
                buf.copy_(src[:, j : j + horizon])
            cuda_graphs.run_recurrent(step, model, opt)
        state = (step.h.clone(), step.c.clone())
    for j in range(graphed, index.shape[1], horizon):
        pred, _, state = model(xs[:, j : j + horizon], xm[:, j : j + horizon], state)
        state = tuple(t.detach() for t in state)  # carry, but stop gradients (truncation)
        err = ((pred - y[:, j : j + horizon]) ** 2).sum(-1)  # (streams, h)
        if w is None:
            loss = err.mean()
            total += loss.detach() * err.numel()
        else:
            wj = w[:, j : j + horizon]
            loss = (err * wj).sum() / wj.sum()
            total += (err * wj).sum().detach()
        opt.zero_grad()
        loss.backward()
        opt.step()
    return float(total) / n


def check_trainable(db: Database, config: TrainConfig) -> None:
    """Refuse a database too small to give every split at least one batch."""
    model = ModelConfig(kind=config.model)
    n_train = len(db.take("train"))
    need_train = config.batch_size * config.horizon if model.recurrent else config.batch_size
    for split, need in (
        ("train", need_train),
        ("val", config.batch_size),
        ("test", config.batch_size),
    ):
        have = len(db.take(split))
        if have < need + 1:
            raise InputError(
                f"{db.source}: too small to train {config.model}: the {split} split has {have} steps, "
                f"needs at least {need + 1} (database of {len(db):,} steps, train {n_train:,})"
            )


class FusedAdam:
    """Adam as ``torch.optim.Adam(fused=True)`` computes it, minus its per-step Python work.

    With a few thousand weights a step is bound by per-call overhead, and the stock optimiser's
    bookkeeping costs about as much as the model's backward pass. This calls the same fused
    kernel directly on lists built once. A test checks it matches ``torch.optim.Adam`` exactly.
    """

    def __init__(self, params, lr: float = 1e-3, betas=(0.9, 0.999), eps: float = 1e-8):
        self.params = [p for p in params if p.requires_grad]
        self.lr, self.betas, self.eps = lr, betas, eps
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]
        self.steps = [torch.zeros((), dtype=torch.float32, device=p.device) for p in self.params]
        self.graphs: dict = {}  # CUDA graphs of steps with these parameters (cuda_graphs)

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        torch._foreach_add_(self.steps, 1)
        torch._fused_adam_(
            self.params,
            [p.grad for p in self.params],
            self.exp_avg,
            self.exp_avg_sq,
            [],
            self.steps,
            lr=self.lr,
            beta1=self.betas[0],
            beta2=self.betas[1],
            weight_decay=0.0,
            eps=self.eps,
            amsgrad=False,
            maximize=False,
        )

    def state_dict(self) -> dict:
        return {"exp_avg": self.exp_avg, "exp_avg_sq": self.exp_avg_sq, "steps": self.steps}

    def load_state_dict(self, state: dict) -> None:
        for name in ("exp_avg", "exp_avg_sq", "steps"):
            for dst, src in zip(getattr(self, name), state[name], strict=True):
                dst.copy_(src)


def make_optimizer(model: torch.nn.Module, config: TrainConfig) -> FusedAdam:
    return FusedAdam(model.parameters(), lr=config.lr)


def keep_freed_memory() -> bool:
    """Keep freed memory in the process's heap instead of handing it back to the kernel.

    An LSTM step allocates and frees workspaces of a few MB; by default glibc maps each afresh
    and the kernel zero-fills its pages on first touch, 10-20 % of a recurrent step with one
    process and more with two (``benchmarks/bench_train.py`` measures it). No effect on the
    numbers. Returns whether it took effect (glibc only; elsewhere a no-op).
    """
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3
        return bool(
            libc.mallopt(m_mmap_threshold, 32 << 20) and libc.mallopt(m_trim_threshold, 1 << 30)
        )
    except (OSError, AttributeError):
        return False


@contextlib.contextmanager
def flush_subnormals() -> Iterator[None]:
    """Within the block, this thread's float arithmetic treats subnormal numbers (below
    1.2e-38 in float32) as zero; on leaving it, the mode it found is restored.

    Adam's moments of a weight whose gradient is 0 (a dead ReLU unit) decay geometrically
    through the subnormal range, and on some x86 CPUs every operation on a subnormal takes a
    slow path: on an Intel Xeon, S and SM epochs slowed by 1.7x as training went on. Flushed,
    they do not; the weights stay the same bit for bit (8 epochs of three SM seeds on the 1 M
    Square, checked with ``torch.equal``), as a number that small moves no weight in float32.
    """
    was = _flushing()
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(was)


def _flushing() -> bool:
    """Whether this thread flushes subnormals: 1e-39 (subnormal in float32) times 1 is 0."""
    return float(torch.tensor(1e-39) * 1.0) == 0.0


def resolve_device(device: str) -> str:
    """The device to train on ("cpu" or "cuda") for "auto", "cpu" or "cuda". On CUDA every
    product is float32, as on the CPU: cuDNN's LSTM would otherwise run in TF32 (gradients
    3e-4 off the CPU's, against 7e-6)."""
    check_device(device)
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda":
        if not torch.cuda.is_available():
            raise InputError("--device cuda: no CUDA device is available here")
        torch.backends.cudnn.allow_tf32 = False
        torch.backends.cuda.matmul.allow_tf32 = False
    return device


def stop_reason(config: TrainConfig, stopper: EarlyStopping, epoch: int, elapsed: float):
    """Why training stops before ``epoch`` (None: it goes on), checked before every epoch."""
    if stopper.should_stop:
        return "early stopping"
    if config.max_epochs is not None and epoch >= config.max_epochs:
        return "max epochs"
    if config.max_minutes is not None and elapsed >= 60 * config.max_minutes:
        return "time cap"
    return None


@flush_subnormals()
def train(
    data: str | Path | Database,
    out: str | Path,
    config: TrainConfig,
    resume: bool = False,
    on_epoch: Callable[[EpochRecord, EarlyStopping], None] | None = None,
) -> TrainResult:
    """Train one model on ``data`` (a database file, or a Database loaded from one) into run
    folder ``out``; resumable after every epoch.

    On the CPU every model goes through ``stacked.train_runs`` (a stack of one, hand-written
    backward pass): S and SM give the numbers of ``train_epoch_feedforward`` with autograd,
    Rec-S and Rec-SM those of ``train_epoch_recurrent`` (``nn.LSTM``, ``stacked_lstm``), both
    to float32 rounding. The loop below runs those two with autograd: the recurrent models on
    CUDA, and any model of ``models.py`` that the hand-written passes do not compute
    (``stacked.computes_models_py``: an edited model trains as edited, only slower).
    """
    from sensorimotor.stacked import train_runs, trains_stacked

    data = database_file(data)
    device = resolve_device(config.device)
    if trains_stacked(config.model, device):
        callback = None if on_epoch is None else (lambda _seed, r, st: on_epoch(r, st))
        return train_runs(data, [(config.seed, out)], config, resume, callback)[0]
    out = Path(out)
    config = TrainConfig(**{**asdict(config), "device": device})
    db = load_database(data)
    check_trainable(db, config)
    model_config = ModelConfig(kind=config.model)
    meta = run_meta(data, db, config)
    check_run_dir(out, meta, resume)
    open_run_dir(out, meta)

    torch.set_num_threads(config.threads)
    keep_freed_memory()
    model = build_model(model_config, seed=config.seed).to(device)
    opt = make_optimizer(model, config)
    stopper = EarlyStopping(config.patience, config.min_ratio)
    history: list[EpochRecord] = []
    start_epoch, elapsed = 0, 0.0
    if resume and (out / "checkpoint.pt").exists():
        stopper, history, start_epoch, elapsed = load_checkpoint(out, device, model, opt)
        done = stored_result(out, history)
        if done is not None:
            return done

    s, m = split_tensors(db, "train", device)
    vs, vm = split_tensors(db, "val", device)
    n = len(s) - 1
    epoch = start_epoch
    while (stopped := stop_reason(config, stopper, epoch, elapsed)) is None:
        t0 = time.perf_counter()
        model.train()
        if model_config.recurrent:
            train_error = train_epoch_recurrent(model, opt, s, m, config.batch_size, config.horizon)
        else:
            order = epoch_generator(config.seed, epoch)
            train_error = train_epoch_feedforward(model, opt, s, m, config.batch_size, order)
        seconds = time.perf_counter() - t0
        val_error = model_error(model, vs, vm)
        improved, best = stopper.update(epoch, val_error)
        elapsed += time.perf_counter() - t0
        record = EpochRecord(
            epoch, train_error, val_error, improved, best, seconds, n / seconds, elapsed
        )
        history.append(record)
        save_epoch(out, model, opt.state_dict(), epoch, elapsed, stopper, history)
        if on_epoch is not None:
            on_epoch(record, stopper)
        epoch += 1
    return finish_run(out, stopper, history, stopped, elapsed)
