"""Training by sensorimotor prediction: Adam, batch 64, the paper's early stopping, TBPTT.

One loop trains every model, one seed or many: ``train_runs`` takes (seed, run folder) pairs,
checks every folder before it writes any, and drives an engine through the epochs: the seeds'
early stopping, records and checkpoints are the loop's; the arithmetic is the engine's
(``engine.AutogradEngine``, or ``engine.StackedEngine`` where it computes what ``models.py``
does). ``train`` is the call with one seed, ``train_seeds`` names the folders of
several. What a run folder holds is in ``runs``.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import torch

from sensorimotor.errors import InputError
from sensorimotor.learn.config import TrainConfig, check_device
from sensorimotor.learn.engine import (
    AutogradEngine,
    Engine,
    FusedAdam,
    Member,
    StackedEngine,
    TrainData,
    computes_models_py,
    flush_subnormals,
    keep_freed_memory,
)
from sensorimotor.learn.evaluate import split_tensors
from sensorimotor.learn.models import ModelConfig, build_model
from sensorimotor.learn.runs import (
    EarlyStopping,
    EpochRecord,
    TrainResult,
    check_run_dir,
    finish_run,
    load_checkpoint,
    lock_run_dir,
    open_run_dir,
    run_meta,
    run_name,
    save_epoch,
    stored_result,
)
from sensorimotor.sim.database import Database, database_file, load_database

# (which run: its index in train_runs' runs, or its seed for train_seeds; record, stopper)
OnEpoch = Callable[[int, EpochRecord, EarlyStopping], None]


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


def check_seeds(seeds: Sequence[int]) -> list[int]:
    """Refuse an empty list or a repeated seed."""
    seeds = [int(s) for s in seeds]
    if not seeds:
        raise InputError("--seeds: give at least one seed, e.g. 0,1,2,3,4")
    for i, s in enumerate(seeds):
        if s in seeds[:i]:
            raise InputError(f"--seeds: seed {s} is given twice")
    return seeds


def trains_stacked(model: ModelConfig | str, device: str) -> bool:
    """Whether ``model`` (a kind, or its sizes and switches) trains on ``device`` ("auto",
    "cpu", "cuda") with the stacked engine: every model but the recurrent ones on CUDA (the
    stacked LSTM's kernels are CPU code), as long as the stack computes what ``models.py``
    does for it (``computes_models_py``)."""
    config = ModelConfig(kind=model) if isinstance(model, str) else model
    on_cpu = resolve_device(device) == "cpu"
    return (on_cpu or not config.recurrent) and computes_models_py(config)


@dataclass
class _Run:
    """One seed's run folder and where its training stands."""

    index: int  # in train_runs' runs
    out: Path
    member: Member
    stopper: EarlyStopping
    history: list[EpochRecord] = field(default_factory=list)
    epoch: int = 0  # the next epoch to train
    elapsed: float = 0.0
    result: TrainResult | None = None


@flush_subnormals()
def train_runs(
    data: str | Path | Database | Sequence[str | Path | Database],
    runs: Sequence[tuple[int, str | Path]],
    config: TrainConfig,
    resume: bool = False,
    on_epoch: OnEpoch | None = None,
    model: ModelConfig | None = None,
) -> list[TrainResult]:
    """Train one model per ``(seed, run folder)`` in ``runs``; resumable after every epoch.

    ``data``: one database (a file, or a Database loaded from one) for every run, or one per
    run (the databases' train splits of one length: a stack spans them, e.g. worlds).
    ``config.seed`` is not used: each run has its own. A run folder is the same whichever
    seeds share the call. With ``resume``, each run continues from its checkpoint; seeds left
    at different epochs (a kill between two seeds' checkpoints) train in separate engines,
    the lagging one first, and merge once caught up. ``model``: the encoder's sizes (default:
    the paper's ``config.model``), stacked where the stacked passes are checked to compute it.
    """
    if isinstance(data, (str, Path, Database)):
        data = [data] * len(runs)
    paths = [database_file(d) for d in data]
    if len(paths) != len(runs):
        raise ValueError(f"{len(paths)} databases for {len(runs)} runs")
    files = list(dict.fromkeys(paths))  # each database once, in order
    split_of = [files.index(p) for p in paths]
    device = resolve_device(config.device)
    config = replace(config, device=device)
    model_config = ModelConfig(kind=config.model) if model is None else model
    if model_config.kind != config.model:
        raise ValueError(f"a {model_config.kind} model for TrainConfig.model {config.model}")
    if config.slow_dims > model_config.z_sensors:
        raise InputError(
            f"slow_dims: z_s has {model_config.z_sensors} dimensions, got {config.slow_dims}"
        )
    stacked = trains_stacked(model_config, device)
    if stacked and model_config.recurrent and len(files) > 1:
        raise ValueError("a recurrent stack trains on one database")
    seeds = [int(seed) for seed, _ in runs]
    for f in files or [None]:  # at least one seed, and distinct ones on each database
        check_seeds([sd for sd, p in zip(seeds, paths, strict=True) if p == f])
    outs = [Path(out) for _, out in runs]
    if len(set(outs)) != len(outs):
        raise ValueError("two runs share a run folder")
    dbs = [load_database(f) for f in files]
    for db in dbs:
        check_trainable(db, config)
        if db.layout != dbs[0].layout:
            raise InputError(
                f"{db.source}: sensor layout ({db.layout.describe()}) differs from "
                f"{dbs[0].source}'s ({dbs[0].layout.describe()}): one stack reads one layout"
            )
    # the model reads as many sensors as the database records
    model_config = replace(model_config, n_sensors=dbs[0].sensors.shape[1])
    if len({len(db.take("train")) for db in dbs}) > 1:
        raise ValueError("databases trained together must have train splits of one length")
    with contextlib.ExitStack() as locks:
        sha: dict[int, str] = {}
        metas = []
        for seed, out, w in zip(seeds, outs, split_of, strict=True):
            meta = run_meta(files[w], dbs[w], replace(config, seed=seed), sha.get(w), model_config)
            sha[w] = meta["data"]["sha256"]
            locks.enter_context(lock_run_dir(out))  # one process writes a run folder
            check_run_dir(out, meta, resume)  # every folder checked before any is written
            metas.append(meta)
        state = state_of(outs, seeds, split_of, config, model_config, resume)  # checked first
        for out, meta in zip(outs, metas, strict=True):
            open_run_dir(out, meta)
        engine_type = StackedEngine if stacked else AutogradEngine
        return _epochs(dbs, state, config, engine_type, on_epoch)


def state_of(
    outs, seeds, split_of, config: TrainConfig, model_config: ModelConfig, resume: bool
) -> list[_Run]:
    """Each run's model, optimiser and early stopping, from its checkpoint where resumed."""
    state: list[_Run] = []
    for i, (seed, out, w) in enumerate(zip(seeds, outs, split_of, strict=True)):
        model = build_model(model_config, seed=seed).to(config.device)
        member = Member(seed, w, model, FusedAdam(model.parameters(), lr=config.lr))
        run = _Run(i, out, member, EarlyStopping(config.patience, config.min_ratio))
        if resume and (out / "checkpoint.pt").exists():
            run.stopper, run.history, run.epoch, run.elapsed = load_checkpoint(
                out, config.device, model, member.opt
            )
            run.result = stored_result(out, run.history)
        state.append(run)
    return state


def _epochs(
    dbs, state: list[_Run], config: TrainConfig, engine_type, on_epoch
) -> list[TrainResult]:
    """The epochs of every run in ``state``, their folders open and locked, on engines of
    ``engine_type``."""
    device = config.device
    torch.set_num_threads(config.threads)
    keep_freed_memory()
    train_splits = [split_tensors(db, "train", device) for db in dbs]
    if len(dbs) == 1:
        s, m = train_splits[0]
    else:  # (W, n + 1, .): one gather serves every database
        s, m = (torch.stack(t) for t in zip(*train_splits, strict=True))
    del train_splits
    tensors = TrainData(s, m, [split_tensors(db, "val", device) for db in dbs])
    n = s.shape[-2] - 1
    by_epoch: dict[int, list[_Run]] = {}
    for run in state:
        if run.result is None:
            by_epoch.setdefault(run.epoch, []).append(run)
    groups = [
        (members, engine_type([r.member for r in members], tensors, config))
        for members in by_epoch.values()
    ]
    while groups := _merge_same_epoch([_drop_finished(config, *g) for g in groups]):
        members, engine = min(groups, key=lambda g: g[0][0].epoch)  # the lagging one first
        epoch = members[0].epoch
        t0 = time.perf_counter()
        train_errors = engine.train_epoch(epoch)
        seconds = time.perf_counter() - t0  # training alone: the record's samples/s
        val_errors = engine.val_errors()
        engine_seconds = time.perf_counter() - t0  # charged to each seed, as its epoch's time
        _check_finite(members, epoch, train_errors, val_errors)
        for k, run in enumerate(members):
            t1 = time.perf_counter()
            improved, best = run.stopper.update(epoch, val_errors[k])
            run.elapsed += engine_seconds + time.perf_counter() - t1
            record = EpochRecord(
                epoch,
                train_errors[k],
                val_errors[k],
                improved,
                best,
                seconds,
                n / seconds,
                run.elapsed,
            )
            run.history.append(record)
            model, opt_state = engine.snapshot(k)
            save_epoch(run.out, model, opt_state, epoch, run.elapsed, run.stopper, run.history)
            run.epoch += 1
            if on_epoch is not None:
                on_epoch(run.index, record, run.stopper)
    return [run.result for run in state]


def _check_finite(members: list[_Run], epoch: int, train_errors, val_errors) -> None:
    """Stop with one line when a seed's errors are no longer numbers: its folder keeps the
    last epoch that was (nothing of this epoch is saved)."""
    for k, run in enumerate(members):
        if not (math.isfinite(train_errors[k]) and math.isfinite(val_errors[k])):
            raise InputError(
                f"{run.out}: training diverged at epoch {epoch} (train error "
                f"{train_errors[k]}, validation error {val_errors[k]}); the run folder keeps "
                f"epoch {epoch - 1} and before. Look for extreme values in the database"
            )


def _drop_finished(
    config: TrainConfig, members: list[_Run], engine: Engine
) -> tuple[list[_Run], Engine]:
    """Finish the runs that stop before their next epoch; the others stay in the engine."""
    keep = []
    for k, run in enumerate(members):
        reason = stop_reason(config, run.stopper, run.epoch, run.elapsed)
        if reason is None:
            keep.append(k)
        else:
            run.result = finish_run(run.out, run.stopper, run.history, reason, run.elapsed)
    engine.keep(keep)
    return [members[k] for k in keep], engine


def _merge_same_epoch(groups: list[tuple[list[_Run], Engine]]) -> list[tuple[list[_Run], Engine]]:
    """Drop the empty groups; those whose seeds have reached the same epoch become one."""
    by_epoch: dict[int, list] = {}
    for g in groups:
        if g[0]:
            by_epoch.setdefault(g[0][0].epoch, []).append(g)
    merged = []
    for same in by_epoch.values():
        if len(same) == 1:
            merged.append(same[0])
        else:
            engines = [e for _, e in same]
            merged.append(([r for mem, _ in same for r in mem], type(engines[0]).merge(engines)))
    return merged


def train(
    data: str | Path | Database,
    out: str | Path,
    config: TrainConfig,
    resume: bool = False,
    on_epoch: Callable[[EpochRecord, EarlyStopping], None] | None = None,
    model: ModelConfig | None = None,
) -> TrainResult:
    """Train one model, seed ``config.seed``, on ``data`` (a database file, or a Database
    loaded from one) into run folder ``out``: ``train_runs`` with one run."""
    callback = None if on_epoch is None else (lambda _i, r, st: on_epoch(r, st))
    return train_runs(data, [(config.seed, out)], config, resume, callback, model)[0]


def train_seeds(
    data: str | Path | Database,
    out: str | Path,
    config: TrainConfig,
    seeds: Sequence[int],
    resume: bool = False,
    on_epoch: OnEpoch | None = None,
    model: ModelConfig | None = None,
) -> list[TrainResult]:
    """Train one model per seed into ``out/{world}__{model}__s{seed}`` run folders, all in
    one ``train_runs`` call; ``on_epoch`` is told each record's seed."""
    seeds = check_seeds(seeds)
    data, out = database_file(data), Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    world = load_database(data).meta["world"]["name"]
    runs = [(seed, out / run_name(world, config.model, seed)) for seed in seeds]
    by_index = None if on_epoch is None else (lambda i, r, st: on_epoch(seeds[i], r, st))
    return train_runs(data, runs, config, resume, by_index, model)
