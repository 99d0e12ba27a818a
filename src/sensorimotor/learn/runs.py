"""A training run: its early stopping, its records, and its folder (its settings,
``TrainConfig``, are in ``config``).

A run folder holds ``config.json`` (model, training config, data hash, version), ``model.pt``
(the best weights, a ``state_dict`` read with ``torch.load(weights_only=True)``),
``checkpoint.pt`` (after every epoch, for ``--resume``), ``history.csv`` and, once finished,
``result.json``. Every file is written to a temporary name and renamed.
"""

from __future__ import annotations

import csv
import io
import math
import numbers
import warnings
import zipfile
import zlib
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Protocol

import torch

from sensorimotor.errors import InputError
from sensorimotor.files import (
    atomic_path,
    check_input,
    check_writable,
    file_hash,
    lock_folder,
    read_json,
    write_json_atomic,
)
from sensorimotor.files import write_text_atomic as _write_text
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.models import ModelConfig
from sensorimotor.sim.database import Database
from sensorimotor.version import __version__

RUN_FILES = ("config.json", "model.pt", "checkpoint.pt", "history.csv", "result.json")


class Optimizer(Protocol):
    """What a checkpoint restores of an optimiser (``engine.FusedAdam``)."""

    params: list[torch.Tensor]

    def load_state_dict(self, state: dict) -> None: ...


SETTABLE = (
    "lr",
    "batch_size",
    "horizon",
    "ahead",
    "ahead_every",
    "slow_dims",
    "slow_weight",
    "patience",
    "min_ratio",
)
"""TrainConfig settings that ``train --set KEY=VALUE`` changes (the others have options)."""
SIZES = (
    "z_sensors",
    "z_motors",
    "rec_hidden",
    "lstm_size",
    "lstm_layers",
    "predictor_hidden",
    "transition_hidden",
)
"""ModelConfig sizes that ``train --set KEY=VALUE`` changes (default: the paper's)."""
SWITCHES = ("memory_motors",)
"""ModelConfig switches that ``train --set KEY=true|false`` changes (ablations)."""


def _switch(text: str) -> bool:
    if text.lower() not in ("true", "false"):
        raise ValueError(text)
    return text.lower() == "true"


def parse_settings(pairs: list[str]) -> dict:
    """``["lr=0.003", "lstm_size=64"]`` -> ``{"lr": 0.003, "lstm_size": 64}``, each value of
    its field's type (``SETTABLE`` and ``SIZES``); InputError naming the pair on an unknown key
    or an unreadable value (the range is TrainConfig's and ``model_config``'s to check)."""
    numbers = ("lr", "slow_weight", "min_ratio")
    kinds = {k: float if k in numbers else int for k in SETTABLE}
    kinds |= dict.fromkeys(SIZES, int) | dict.fromkeys(SWITCHES, _switch)
    settings = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        key = key.strip()
        if not sep or key not in kinds:
            raise InputError(f"--set {pair!r}: use KEY=VALUE with KEY one of {', '.join(kinds)}")
        try:
            settings[key] = kinds[key](text.strip())
        except ValueError:
            kind = {int: "an integer", float: "a number"}.get(kinds[key], "true or false")
            raise InputError(f"--set {pair!r}: {key} must be {kind}") from None
    return settings


def apply_settings(config: TrainConfig, pairs: list[str]) -> tuple[TrainConfig, ModelConfig | None]:
    """``train --set KEY=VALUE ...``: ``config`` with its settings changed, and the model's
    sizes (None: none given, the paper's)."""
    settings = parse_settings(pairs)
    sizes = {key: settings.pop(key) for key in SIZES + SWITCHES if key in settings}
    model = model_config(config.model, sizes) if sizes else None
    return replace(config, **settings), model


def model_config(kind: str, sizes: dict) -> ModelConfig:
    """The paper's ``kind`` encoder with ``sizes`` (some of ``SIZES``) changed; InputError on
    another key or a size that is not a positive integer."""
    for key, value in sizes.items():
        if key in SWITCHES:
            if not isinstance(value, bool):
                raise InputError(f"ModelConfig.{key} must be true or false, got {value!r}")
            continue
        if key not in SIZES:
            raise InputError(f"ModelConfig.{key}: not a size, use one of {', '.join(SIZES)}")
        if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < 1:
            raise InputError(f"ModelConfig.{key} must be an integer >= 1, got {value!r}")
    sizes = {k: v if k in SWITCHES else int(v) for k, v in sizes.items()}
    try:
        return ModelConfig(kind=kind, **sizes)
    except ValueError as err:
        raise InputError(f"ModelConfig: {err}") from None


@dataclass
class EarlyStopping:
    """The paper's rule: improve = below ``min_ratio`` x the best counted error; stop after
    ``patience`` epochs without. The kept weights are those of the lowest error seen."""

    patience: int = 10
    min_ratio: float = 0.95
    reference: float = math.inf  # error of the last counted improvement
    lowest: float = math.inf  # lowest error seen (its weights are kept)
    best_epoch: int = -1
    waited: int = 0

    def update(self, epoch: int, error: float) -> tuple[bool, bool]:
        """Record one epoch's validation error; returns (counts as improvement, new lowest)."""
        improved = error < self.min_ratio * self.reference
        if improved:
            self.reference = error
            self.waited = 0
        else:
            self.waited += 1
        lowest = error < self.lowest
        if lowest:
            self.lowest, self.best_epoch = error, epoch
        return improved, lowest

    @property
    def should_stop(self) -> bool:
        return self.waited >= self.patience


@dataclass(frozen=True)
class EpochRecord:
    epoch: int
    train_error: float
    val_error: float
    improved: bool
    best: bool
    seconds: float
    samples_per_s: float
    elapsed: float = 0.0  # training seconds of the whole run so far


@dataclass
class TrainResult:
    run_dir: Path
    best_epoch: int
    best_val_error: float
    epochs: int
    stopped: str  # "early stopping" | "max epochs" | "time cap"
    seconds: float
    history: list[EpochRecord] = field(default_factory=list)

    @property
    def ending(self) -> str:
        """How it ended, for a progress line: "early stopping after 12 epochs"."""
        return f"{self.stopped} after {count(self.epochs, 'epoch')}"


def epoch_label(epoch: int, max_epochs: int | None) -> str:
    """An epoch (0-based, as run folders count them) in a progress line, with how many of its
    cap it is: "epoch  19 (20 of 80)"; the cap left out where early stopping alone ends it."""
    return f"epoch {epoch:3d}" + (f" ({epoch + 1} of {max_epochs})" if max_epochs else "")


def count(n: int, noun: str) -> str:
    """``n`` and the noun, plural unless one: "1 epoch", "3 epochs"."""
    return f"{n} {noun}" if n == 1 else f"{n} {noun}s"


def run_name(world: str, model: str, seed: int) -> str:
    """The name of a run folder (CleanRL style): ``{world}__{model}__s{seed}``."""
    return f"{world}__{model}__s{seed}"


def _torch_save(obj, path: Path) -> None:
    # Through a file object: torch.save(path) names the archive's root after the (random)
    # temporary file, which would make the same weights different bytes.
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        torch.save(obj, f)


def check_archive(path: Path) -> None:
    """InputError naming ``path`` unless it is a whole archive whose every CRC checks."""
    try:
        with zipfile.ZipFile(path) as archive:
            damaged = archive.testzip()
    except (zipfile.BadZipFile, OSError, EOFError, zlib.error) as err:
        raise InputError(f"{path}: corrupt checkpoint (not a readable archive: {err})") from None
    if damaged is not None:
        raise InputError(f"{path}: corrupt checkpoint ({damaged} fails its CRC check)")


def torch_load(path: Path, device: str | torch.device = "cpu"):
    """``torch.load(weights_only=True)`` of a file this package wrote, checked first: torch does
    not test its archive's CRCs, so a flipped byte would load as wrong weights. InputError
    naming the file on any damage; load the result into a model with ``load_weights_into``."""
    check_input(path, "checkpoint")
    check_archive(path)
    try:
        with warnings.catch_warnings():  # torch's advice to load unsafely is not for our users
            warnings.simplefilter("ignore")
            return torch.load(path, map_location=device, weights_only=True)
    except Exception as err:  # torch raises many kinds on corrupt files
        raise InputError(f"{path}: corrupt checkpoint ({_first_lines(err)})") from None


def load_weights_into(model: torch.nn.Module, state, path: Path) -> None:
    """``model.load_state_dict(state)``, refusing weights of another shape or non-finite ones
    with an InputError naming ``path``."""
    try:
        model.load_state_dict(state)
    except Exception as err:
        raise InputError(
            f"{path}: weights do not fit the run's model ({_first_lines(err)})"
        ) from None
    bad = [name for name, t in model.state_dict().items() if not torch.isfinite(t).all()]
    if bad:
        raise InputError(f"{path}: non-finite weights in {', '.join(bad[:3])}")


def _first_lines(err: Exception) -> str:
    """The gist of an exception in one line (load_state_dict puts its details on line 2)."""
    lines = [line.strip() for line in str(err).splitlines() if line.strip()]
    return " ".join(lines[:2])[:300] if lines else err.__class__.__name__


def _history_csv(history: list[EpochRecord]) -> str:
    buf = io.StringIO()
    writer = csv.writer(buf)
    writer.writerow(
        [
            "epoch",
            "train_error",
            "val_error",
            "improved",
            "best",
            "seconds",
            "samples_per_s",
            "elapsed",  # training seconds so far, over every session of a resumed run
        ]
    )
    for r in history:
        writer.writerow(
            [
                r.epoch,
                f"{r.train_error:.8g}",
                f"{r.val_error:.8g}",
                int(r.improved),
                int(r.best),
                f"{r.seconds:.3f}",
                f"{r.samples_per_s:.0f}",
                f"{r.elapsed:.3f}",
            ]
        )
    return buf.getvalue()


def run_meta(
    data: Path,
    db: Database,
    config: TrainConfig,
    sha256: str | None = None,
    model: ModelConfig | None = None,
) -> dict:
    """What a run folder's ``config.json`` records: model (default: the paper's sizes),
    training config, data, version."""
    return {
        "model": (model or ModelConfig(kind=config.model, n_sensors=db.sensors.shape[1])).to_dict(),
        "train": {k: v for k, v in asdict(config).items() if k != "device"},
        "data": {
            "path": str(data),
            "sha256": sha256 or file_hash(data),
            "world": db.meta["world"]["name"],
            "steps": len(db),
            "seed": db.meta.get("seed"),
            "sensor_layout": db.meta.get("sensor_layout"),
        },
        "version": __version__,
    }


def check_run_dir(out: Path, meta: dict, resume: bool) -> None:
    """Refuse an ``out`` that is a file, that holds a run without ``resume``, or (with
    ``resume``) a run of another model, training config or data."""
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: exists and is not a folder")
    for name in RUN_FILES if out.is_dir() else []:  # before anything is written, not midway
        check_writable(out / name)
    cfg_path = out / "config.json"
    present = [name for name in RUN_FILES if (out / name).exists()]
    if present and not resume:
        raise InputError(
            f"{out}: already holds a run; pass --resume to continue it, or another --out"
        )
    if resume and present and not cfg_path.exists():
        raise InputError(
            f"{out}: holds {', '.join(present)} but no config.json, so what it was trained on is "
            "unknown; refusing to resume into it (move it away, or use another --out)"
        )
    trained = [name for name in ("model.pt", "result.json") if (out / name).exists()]
    if resume and trained and not (out / "checkpoint.pt").exists():
        raise InputError(
            f"{out}: checkpoint.pt is missing; resuming would start again at epoch 0 and replace "
            f"the trained {' and '.join(trained)} (move the run away, or use another --out)"
        )
    if resume and cfg_path.exists():
        old = read_json(cfg_path, "run config")
        if not isinstance(old, dict) or not all(
            isinstance(old.get(k), dict) for k in ("model", "train", "data")
        ):
            raise InputError(
                f"{cfg_path}: corrupt run config (missing its model, train or data table)"
            )
        was = old["data"]
        if was.get("sha256") != meta["data"]["sha256"]:
            raise InputError(
                f"{out}: --resume with other data: {meta['data']['path']} is not the database "
                f"the run was started with ({was.get('path')}, {was.get('steps')} steps; the "
                "contents differ, sha256)"
            )
        for key in ("model", "train"):
            # the caps may change between sessions; the algorithm may not
            # a setting added since the run began ran at its default
            was = {**setting_defaults(key, meta["model"]["kind"]), **old.get(key, {})}
            changed = setting_changes(was, meta[key], ("max_epochs", "max_minutes"))
            if changed:
                raise InputError(
                    f"{out}: --resume with another {key} setting than the run was started with "
                    f"({changed})"
                )
        if (out / "checkpoint.pt").exists():
            check_archive(out / "checkpoint.pt")  # before the run's config is rewritten


def setting_defaults(key: str, kind: str) -> dict:
    """The defaults of a ``config.json`` table (``model`` or ``train``) of a ``kind`` run, for
    the settings that a run written before they existed does not record: it ran at them."""
    if key == "model":
        return ModelConfig(kind=kind).to_dict()
    return {f.name: f.default for f in fields(TrainConfig) if f.name != "device"}


def lock_run_dir(out: Path):
    """Hold ``out``'s lock while a process trains into it (a second process is refused at
    once); a folder made here and left empty by a refusal is removed again."""
    return lock_folder(out, "run folder")


def setting_changes(a: dict, b: dict, ignore: tuple[str, ...] = ()) -> str:
    """``key: a -> b`` for each setting in which two configs differ, but those in ``ignore``;
    empty if none."""
    keys = sorted((a.keys() | b.keys()) - set(ignore))
    return ", ".join(f"{k}: {a.get(k)!r} -> {b.get(k)!r}" for k in keys if a.get(k) != b.get(k))


def open_run_dir(out: Path, meta: dict) -> None:
    """Create the run folder and write its ``config.json``."""
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{out}: cannot create run folder ({err.strerror})") from None
    write_json_atomic(out / "config.json", meta)


def load_checkpoint(
    out: Path, device: str, model: torch.nn.Module, opt: Optimizer
) -> tuple[EarlyStopping, list[EpochRecord], int, float]:
    """Restore ``model`` and ``opt`` from ``out/checkpoint.pt``; returns (stopper, history,
    next epoch, training seconds so far). InputError naming the file if it is corrupt."""
    ckpt_path = out / "checkpoint.pt"
    ckpt = torch_load(ckpt_path, device)
    if not isinstance(ckpt, dict) or not isinstance(ckpt.get("model"), dict):
        raise InputError(f"{ckpt_path}: corrupt checkpoint (no model weights in it)")
    load_weights_into(model, ckpt["model"], ckpt_path)
    try:
        stopper, history, epoch, seconds = _checked_progress(ckpt)
        _check_moments(ckpt["optimizer"], opt)
        opt.load_state_dict(ckpt["optimizer"])
    except Exception as err:
        raise InputError(f"{ckpt_path}: corrupt checkpoint ({_first_lines(err)})") from None
    if history[-1].best and not _holds(out / "model.pt", model):
        _torch_save(model.state_dict(), out / "model.pt")  # killed before it: written now
    return stopper, history, epoch + 1, seconds


def _holds(path: Path, model: torch.nn.Module) -> bool:
    """Whether ``path`` holds ``model``'s weights exactly."""
    if not path.is_file():
        return False
    try:
        saved = torch.load(path, map_location="cpu", weights_only=True)
        return all(torch.equal(saved[k], v.cpu()) for k, v in model.state_dict().items())
    except Exception:  # unreadable or another model: the checkpoint's weights replace it
        return False


def _checked_progress(ckpt: dict) -> tuple[EarlyStopping, list[EpochRecord], int, float]:
    """A checkpoint's epoch, seconds, early stopping and history, each within its range and
    consistent with the others (a hand-edited checkpoint is not trusted field by field)."""
    epoch, seconds = ckpt["epoch"], ckpt["seconds"]
    if isinstance(epoch, bool) or not isinstance(epoch, int) or epoch < 0:
        raise ValueError(f"epoch must be an integer >= 0, got {epoch!r}")
    if not isinstance(seconds, int | float) or not math.isfinite(seconds) or seconds < 0:
        raise ValueError(f"seconds must be a finite number >= 0, got {seconds!r}")
    stopper = EarlyStopping(**ckpt["stopper"])
    for name in ("patience", "waited", "best_epoch"):
        if not isinstance(getattr(stopper, name), int) or getattr(stopper, name) < -1:
            raise ValueError(f"stopper.{name} is {getattr(stopper, name)!r}")
    history = [EpochRecord(**r) for r in ckpt["history"]]
    if [r.epoch for r in history] != list(range(epoch + 1)):
        raise ValueError(f"its history does not hold epochs 0..{epoch} in order")
    for r in history:
        numbers = (r.train_error, r.val_error, r.seconds, r.samples_per_s, r.elapsed)
        if not all(isinstance(v, int | float) and math.isfinite(v) for v in numbers):
            raise ValueError(f"history of epoch {r.epoch} holds a value that is not a number")
    return stopper, history, epoch, float(seconds)


def _check_moments(state: dict, opt: Optimizer) -> None:
    """Adam's moments: one finite tensor per parameter, of its shape (a wrong shape would
    broadcast silently and train on nonsense)."""
    for name in ("exp_avg", "exp_avg_sq", "steps"):
        tensors = state[name]
        if not isinstance(tensors, list) or len(tensors) != len(opt.params):
            raise ValueError(f"optimizer.{name} must hold {len(opt.params)} tensors")
        for i, (t, p) in enumerate(zip(tensors, opt.params, strict=True)):
            shape = () if name == "steps" else p.shape
            if not isinstance(t, torch.Tensor) or t.shape != shape or not torch.isfinite(t).all():
                raise ValueError(
                    f"optimizer.{name}[{i}] is not a finite tensor of shape {tuple(shape)}"
                )


def stored_result(out: Path, history: list[EpochRecord]) -> TrainResult | None:
    """The result of a run that early stopping has finished for good (its ``result.json``);
    None if it has none or was stopped by a cap, which a resumed session may lift."""
    result_path = out / "result.json"
    if not result_path.exists():
        return None
    try:
        res = read_json(result_path, "run result")
        if res["stopped"] != "early stopping":
            return None
    except (InputError, KeyError, TypeError):
        return None  # unreadable: the checkpoint decides (the run goes on from it)
    return TrainResult(
        out,
        res["best_epoch"],
        res["best_val_error"],
        res["epochs"],
        res["stopped"],
        res["seconds"],
        history,
    )


def save_epoch(
    out: Path,
    model: torch.nn.Module,
    opt_state: dict,
    epoch: int,
    elapsed: float,
    stopper: EarlyStopping,
    history: list[EpochRecord],
) -> None:
    """After an epoch: ``checkpoint.pt``, then ``model.pt`` if it is the best so far, then
    ``history.csv``. A kill after the checkpoint leaves ``model.pt`` an epoch behind, which
    ``load_checkpoint`` mends (the checkpoint holds that epoch's weights); the other order left
    a first epoch's ``model.pt`` without a checkpoint, a run resume must refuse."""
    _torch_save(
        {
            "model": model.state_dict(),
            "optimizer": opt_state,
            "epoch": epoch,
            "seconds": elapsed,
            "stopper": asdict(stopper),
            "history": [asdict(r) for r in history],
        },
        out / "checkpoint.pt",
    )
    if history[-1].best:
        _torch_save(model.state_dict(), out / "model.pt")
    _write_text(out / "history.csv", _history_csv(history))


def finish_run(
    out: Path, stopper: EarlyStopping, history: list[EpochRecord], stopped: str, elapsed: float
) -> TrainResult:
    """Write ``result.json``: the run is finished. ``history.csv`` is rewritten from the
    checkpoint's history first: a kill between the checkpoint and it left it an epoch short."""
    _write_text(out / "history.csv", _history_csv(history))
    result = TrainResult(
        out, stopper.best_epoch, stopper.lowest, len(history), stopped, elapsed, history
    )
    write_json_atomic(
        out / "result.json",
        {
            "best_epoch": result.best_epoch,
            "best_val_error": result.best_val_error,
            "epochs": result.epochs,
            "stopped": stopped,
            "seconds": elapsed,
        },
    )
    return result
