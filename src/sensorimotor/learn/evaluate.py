"""Prediction error of trained encoders, the two baselines, and the representation z_s.

The error is the paper's L2 error (Eq. 1): per step, the squared error summed over the
scaled sensors; then the mean over every predicted step of the split. Recurrent models run over
the whole split from a zero state, carrying it, as an agent would online.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from sensorimotor.errors import InputError
from sensorimotor.files import RUN_FOLDER, check_input_dir, read_json
from sensorimotor.learn.models import ModelConfig, SensorimotorEncoder, build_model
from sensorimotor.learn.runs import load_weights_into, torch_load
from sensorimotor.sim.core import SensorLayout
from sensorimotor.sim.database import Database, as_database, scale_motors, scale_sensors

CHUNK = 20_000  # steps per forward pass when running a whole split (memory bound, not a result)


def split_tensors(db: Database, split: str, device: str | torch.device = "cpu"):
    """Scaled (sensors (n, 5), motors (n, 2)) float32 tensors of one split."""
    part = db.take(split)
    s = torch.from_numpy(scale_sensors(part.sensors, db.max_range)).to(device)
    m = torch.from_numpy(scale_motors(part.motors)).to(device)
    return s, m


@torch.no_grad()
def run_model(
    model: SensorimotorEncoder, sensors: torch.Tensor, motors: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor]:
    """Run over one contiguous sequence: (n, 5), (n, 2) -> prediction (n, 5), z_s (n, 10).

    Recurrent models start from a zero state and carry it over the whole sequence (in chunks,
    which gives the same numbers as one pass), on one CPU thread: their steps are too small to
    share (a 100,000-step Rec-SM pass, quiet 2-core CPU: 1.2-1.8 s on one thread, 2.8 s on two;
    545 s against 3 s on a loaded one).
    """
    was_training, threads = model.training, torch.get_num_threads()
    model.eval()
    if model.config.recurrent and sensors.device.type == "cpu":
        torch.set_num_threads(1)
    preds, zs, state = [], [], None
    try:
        for i in range(0, len(sensors), CHUNK):
            s = sensors[None, i : i + CHUNK]  # (1, c, 5)
            m = motors[None, i : i + CHUNK]  # (1, c, 2)
            p, z, state = model(s, m, state)
            preds.append(p[0])
            zs.append(z[0])
    finally:
        torch.set_num_threads(threads)
        model.train(was_training)
    return torch.cat(preds), torch.cat(zs)


def prediction_error(pred: torch.Tensor, sensors: torch.Tensor) -> float:
    """Paper's L2 error of predictions pred[t] of sensors[t + 1]: sum over sensors, mean over t."""
    return float(((pred[:-1] - sensors[1:]) ** 2).sum(-1).mean())


@torch.no_grad()
def ahead_errors(
    model: SensorimotorEncoder, sensors: torch.Tensor, motors: torch.Tensor, steps: int
) -> torch.Tensor:
    """(K,) the paper's error of the open-loop predictions of s_{t+1} .. s_{t+K} (``ahead``)
    over one contiguous split, each k's mean over the steps whose K targets are inside it."""
    _, z = run_model(model, sensors, motors)  # (n, 10), the state carried from the start
    starts = len(sensors) - steps
    if starts < 1:
        raise ValueError(f"{len(sensors)} steps cannot score {steps} steps ahead")
    was_training = model.training
    model.eval()
    total = torch.zeros(steps, dtype=torch.float64)
    try:
        for i in range(0, starts, CHUNK):
            j = min(i + CHUNK, starts)
            pred = model.ahead(z[None, i:j], motors[None, i : j + steps - 1], steps)[:, 0]
            target = torch.stack([sensors[i + k + 1 : j + k + 1] for k in range(steps)])
            total += ((pred - target) ** 2).sum(-1).sum(-1).double()  # (K,)
    finally:
        model.train(was_training)
    return (total / starts).float()


def model_error(model: SensorimotorEncoder, sensors: torch.Tensor, motors: torch.Tensor) -> float:
    """The error of ``model`` over one contiguous split."""
    pred, _ = run_model(model, sensors, motors)
    return prediction_error(pred, sensors)


def baselines(db: Database, split: str = "test") -> dict[str, float]:
    """Errors of predicting the train-split mean reading, and of copying the last reading."""
    s, _ = split_tensors(db, split)
    train_s, _ = split_tensors(db, "train")
    mean = train_s.mean(0, keepdim=True).expand_as(s)
    return {"mean": prediction_error(mean, s), "copy_last": prediction_error(s, s)}


def baseline_warnings(name: str, errors: dict[str, float], base: dict[str, dict]) -> list[str]:
    """A line for each test world where ``name``'s error is not below copying the last reading:
    a model that predicts worse than "nothing changes" has not learned the sensorimotor
    contingencies, and no number read from it should be trusted as such."""
    lines = []
    for world, err in errors.items():
        copy = base.get(world, {}).get("copy_last")
        if copy is not None and err >= copy:
            lines.append(
                f"{name} on {world}: test error {err:.5f} is not below copying the last reading "
                f"({copy:.5f}, {err / copy:.1f} times it): the model has not learned to predict; "
                "likely causes: too few epochs, or a recording whose rate or sensor layout "
                "differs from the training database's"
            )
    return lines


@dataclass(frozen=True)
class Run:
    """A trained run folder: its best model and what it says about itself."""

    path: Path
    model: SensorimotorEncoder
    config: dict  # config.json: model, train, data, version

    @property
    def kind(self) -> str:
        return self.model.config.kind

    @property
    def trained_on(self) -> str:
        return self.config["data"]["world"]


def load_run(run_dir: str | Path, device: str | torch.device = "cpu") -> Run:
    """Load a run folder's config and best weights; InputError naming the file if anything is off."""
    run_dir = check_input_dir(run_dir, RUN_FOLDER)
    cfg_path, weights = run_dir / "config.json", run_dir / "model.pt"
    if not cfg_path.is_file():
        raise InputError(f"{cfg_path}: missing (not a run folder made by `sensorimotor train`)")
    config = read_json(cfg_path, "run config")
    try:
        model_config = ModelConfig(
            **{**config["model"], "ff_hidden": tuple(config["model"]["ff_hidden"])}
        )
        for key in ("world", "sha256"):
            if not isinstance(config["data"][key], str):
                raise TypeError(f"data.{key} is not a string")
        if not isinstance(config["train"], dict):
            raise TypeError("'train' is not a table")
    except (ValueError, KeyError, TypeError, AttributeError) as err:
        raise InputError(f"{cfg_path}: corrupt run config ({err})") from None
    if weights.exists() and not weights.is_file():
        raise InputError(f"{weights}: is not a file")
    if not weights.is_file():
        raise InputError(f"{weights}: missing checkpoint (training has not finished an epoch)")
    model = build_model(model_config).to(device)
    load_weights_into(model, torch_load(weights, device), weights)
    model.eval()
    return Run(run_dir, model, config)


def check_fits(run: Run, db: Database) -> None:
    """Refuse data the run's model cannot read (another sensor layout): one line naming both."""
    trained = run.config.get("data", {}).get("sensor_layout")
    layout = db.meta.get("sensor_layout")
    if trained and layout and trained != layout:
        raise InputError(
            f"{db.source}: recorded with {db.layout.describe()}; run {run.path} was trained on "
            f"{_describe(trained)}"
        )
    if db.sensors.shape[1] != run.model.config.n_sensors:
        raise InputError(
            f"{db.source}: {db.sensors.shape[1]} sensors, the model reads {run.model.config.n_sensors}"
        )


def _describe(layout: dict) -> str:
    """A run's recorded ``sensor_layout`` as ``SensorLayout.describe`` puts it."""
    try:
        return SensorLayout(tuple(layout["angles"]), float(layout["max_range"])).describe()
    except (KeyError, TypeError, ValueError):
        return str(layout)


def encode(
    run: Run | str | Path, db: Database | str | Path, split: str = "test", steps: int | None = None
) -> np.ndarray:
    """z_s (n, 10) of a trained model over one split, or its first ``steps`` (recurrent: state
    carried from its start). ``run`` and ``db`` may be loaded already or given by path."""
    if not isinstance(run, Run):
        run = load_run(run)
    db = as_database(db)
    check_fits(run, db)
    s, m = split_tensors(db, split)
    s, m = s[:steps], m[:steps]
    if len(s) == 0:
        raise InputError(f"{db.source}: the {split} split is empty")
    _, z = run_model(run.model, s, m)
    return z.numpy()


def evaluate_run(
    run: Run | str | Path,
    dbs: Sequence[Database | str | Path] | Database | str | Path,
    split: str = "test",
) -> dict:
    """Errors of one run on each database's split, with the baselines: the JSON of `evaluate`.
    ``run`` and the databases may be loaded already or given by path; one database or several."""
    if not isinstance(run, Run):
        run = load_run(run)
    if isinstance(dbs, (Database, str, Path)):
        dbs = [dbs]
    errors, base = {}, {}
    for db in map(as_database, dbs):
        check_fits(run, db)
        s, m = split_tensors(db, split)
        if len(s) < 2:
            raise InputError(f"{db.source}: the {split} split has fewer than 2 steps")
        name = db.meta["world"]["name"]
        if name in errors:
            raise InputError(
                f"{db.source}: a second test database of world {name!r}; give one per world"
            )
        errors[name] = model_error(run.model, s, m)
        base[name] = baselines(db, split)
    return {
        "model": run.kind,
        "run": str(run.path),
        "trained_on": run.trained_on,
        "seed": run.config.get("train", {}).get("seed"),
        "errors": errors,
        "baselines": base,
    }
