"""A training run: its configuration, its early stopping, its records, and its folder.

A run folder holds ``config.json`` (model, training config, data hash, version), ``model.pt``
(the best weights, a ``state_dict`` read with ``torch.load(weights_only=True)``),
``checkpoint.pt`` (after every epoch, for ``--resume``), ``history.csv`` and, once finished,
``result.json``. Every file is written to a temporary name and renamed.
"""

from __future__ import annotations

import csv
import io
import json
import math
import numbers
import warnings
import zipfile
import zlib
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import torch

from sensorimotor.errors import InputError
from sensorimotor.files import atomic_path, check_writable, file_hash
from sensorimotor.files import write_text_atomic as _write_text
from sensorimotor.learn.models import MODEL_KINDS, ModelConfig
from sensorimotor.sim.core import MAX_SEED
from sensorimotor.sim.database import Database
from sensorimotor.version import __version__

if TYPE_CHECKING:
    from sensorimotor.learn.adam import FusedAdam


RUN_FILES = ("config.json", "model.pt", "checkpoint.pt", "history.csv", "result.json")


def check_device(device: str) -> None:
    """Refuse a device name other than auto, cpu or cuda."""
    if device not in ("auto", "cpu", "cuda"):
        raise InputError(f"unknown device {device!r}: use auto, cpu or cuda")


@dataclass(frozen=True)
class TrainConfig:
    """How one model is trained; the defaults are the paper's (section V.A)."""

    model: str = "rec-sm"
    """s, sm, rec-s or rec-sm."""
    seed: int = 0
    """Seeds the initial weights and the data order."""
    lr: float = 1e-3
    """Adam's learning rate."""
    batch_size: int = 64
    """Transitions per step (feed-forward); streams per step (recurrent)."""
    horizon: int = 20
    """Truncation horizon of back-propagation through time (recurrent models)."""
    patience: int = 10
    """Stop after this many epochs in a row without improvement."""
    min_ratio: float = 0.95
    """An epoch improves when its validation error is below this fraction of the best so far."""
    max_epochs: int | None = None
    """Cap on epochs (None: early stopping alone)."""
    max_minutes: float | None = None
    """Cap on training wall time, checked after each epoch (None: no cap)."""
    device: str = "cpu"
    """cpu or cuda."""
    threads: int = 1
    """Torch threads (one is fastest for these tiny models; two in one process are slower)."""

    def __post_init__(self) -> None:
        """Refuse a setting that could not train, before any run folder is written; numpy
        numbers become Python's (config.json is JSON)."""
        if self.model not in MODEL_KINDS:
            kinds = ", ".join(MODEL_KINDS)
            raise InputError(f"TrainConfig.model: use one of {kinds}, got {self.model!r}")
        check_device(self.device)
        counts = {"seed": 0, "batch_size": 1, "horizon": 1, "patience": 1, "threads": 1}
        counts |= {} if self.max_epochs is None else {"max_epochs": 1}
        for name, least in counts.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least:
                raise InputError(f"TrainConfig.{name} must be an integer >= {least}, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.seed > MAX_SEED:
            raise InputError(f"TrainConfig.seed must be at most {MAX_SEED}, got {self.seed}")
        positive = {"lr": self.lr, "min_ratio": self.min_ratio}
        positive |= {} if self.max_minutes is None else {"max_minutes": self.max_minutes}
        for name, value in positive.items():
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise InputError(f"TrainConfig.{name} must be a number, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"TrainConfig.{name} must be positive and finite, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.min_ratio > 1:
            raise InputError(f"TrainConfig.min_ratio must be at most 1, got {self.min_ratio!r}")


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


def run_meta(data: Path, db: Database, config: TrainConfig, sha256: str | None = None) -> dict:
    """What a run folder's ``config.json`` records: model, training config, data, version."""
    return {
        "model": ModelConfig(kind=config.model, n_sensors=db.sensors.shape[1]).to_dict(),
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
    if cfg_path.exists() and not resume:
        raise InputError(
            f"{out}: already holds a run; pass --resume to continue it, or another --out"
        )
    if resume and cfg_path.exists():
        try:
            old = json.loads(cfg_path.read_text())
            if not all(isinstance(old.get(k), dict) for k in ("model", "train", "data")):
                raise ValueError("missing its model, train or data table")
        except (ValueError, AttributeError) as err:
            raise InputError(f"{cfg_path}: corrupt run config ({err})") from None
        except OSError as err:
            raise InputError(f"{cfg_path}: cannot read the run config ({err.strerror})") from None
        was = old["data"]
        if was.get("sha256") != meta["data"]["sha256"]:
            raise InputError(
                f"{out}: --resume with other data: {meta['data']['path']} is not the database "
                f"the run was started with ({was.get('path')}, {was.get('steps')} steps; the "
                "contents differ, sha256)"
            )
        for key in ("model", "train"):
            # the caps may change between sessions; the algorithm may not
            changed = setting_changes(old.get(key, {}), meta[key], ("max_epochs", "max_minutes"))
            if changed:
                raise InputError(
                    f"{out}: --resume with another {key} setting than the run was started with "
                    f"({changed})"
                )
        if (out / "checkpoint.pt").exists():
            check_archive(out / "checkpoint.pt")  # before the run's config is rewritten


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
    _write_text(out / "config.json", json.dumps(meta, indent=2))


def load_checkpoint(
    out: Path, device: str, model: torch.nn.Module, opt: FusedAdam
) -> tuple[EarlyStopping, list[EpochRecord], int, float]:
    """Restore ``model`` and ``opt`` from ``out/checkpoint.pt``; returns (stopper, history,
    next epoch, training seconds so far). InputError naming the file if it is corrupt."""
    ckpt_path = out / "checkpoint.pt"
    ckpt = torch_load(ckpt_path, device)
    if not isinstance(ckpt, dict) or not isinstance(ckpt.get("model"), dict):
        raise InputError(f"{ckpt_path}: corrupt checkpoint (no model weights in it)")
    load_weights_into(model, ckpt["model"], ckpt_path)
    try:
        opt.load_state_dict(ckpt["optimizer"])
        stopper = EarlyStopping(**ckpt["stopper"])
        history = [EpochRecord(**r) for r in ckpt["history"]]
        return stopper, history, ckpt["epoch"] + 1, ckpt["seconds"]
    except Exception as err:
        raise InputError(f"{ckpt_path}: corrupt checkpoint ({_first_lines(err)})") from None


def stored_result(out: Path, history: list[EpochRecord]) -> TrainResult | None:
    """The result of a run that early stopping has finished for good (its ``result.json``);
    None if it has none or was stopped by a cap, which a resumed session may lift."""
    result_path = out / "result.json"
    if not result_path.exists():
        return None
    try:
        res = json.loads(result_path.read_text())
        if res["stopped"] != "early stopping":
            return None
    except (ValueError, KeyError, TypeError):
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
    """After an epoch: ``model.pt`` if it is the best so far, ``checkpoint.pt``, ``history.csv``."""
    if history[-1].best:
        _torch_save(model.state_dict(), out / "model.pt")
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
    _write_text(out / "history.csv", _history_csv(history))


def finish_run(
    out: Path, stopper: EarlyStopping, history: list[EpochRecord], stopped: str, elapsed: float
) -> TrainResult:
    """Write ``result.json``: the run is finished."""
    result = TrainResult(
        out, stopper.best_epoch, stopper.lowest, len(history), stopped, elapsed, history
    )
    _write_text(
        out / "result.json",
        json.dumps(
            {
                "best_epoch": result.best_epoch,
                "best_val_error": result.best_val_error,
                "epochs": result.epochs,
                "stopped": stopped,
                "seconds": elapsed,
            },
            indent=2,
        ),
    )
    return result
