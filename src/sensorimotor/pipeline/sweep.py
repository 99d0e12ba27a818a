"""``sensorimotor sweep``: a search over training settings, each trial an ordinary run folder.

A sweep file (TOML) names the database, the settings held fixed and those searched::

    data = "square.npz"      # the database trained on (a path relative to this file)
    search = "grid"          # grid: every combination; random: `trials` draws from `seed`
    trials = 8               # random search only
    seed = 0                 # random search only: seeds the draws

    [train]                  # TrainConfig settings of every trial (the paper's by default)
    model = "rec-sm"
    max_epochs = 20

    [space]                  # the searched settings: a list of values each
    lr = [1e-4, 3e-4, 1e-3, 3e-3]
    batch_size = [32, 64]
    # random search also draws from ranges: {log_uniform = [1e-4, 1e-2]}, {uniform = [0.9,
    # 0.99]}, {int_uniform = [10, 40]}; a list is drawn from uniformly

    [asha]                   # --backend ray: early termination on the validation error
    grace_period = 1         # epochs every trial trains before it can be stopped
    reduction_factor = 2     # each rung keeps 1 / reduction_factor of the trials

Searchable: ``data`` (the training world, and with it the sensor layout), the training
settings ``model seed lr batch_size horizon patience min_ratio max_epochs`` and the model's
sizes ``z_sensors z_motors rec_hidden lstm_size lstm_layers predictor_hidden``. Trials are drawn
here, from the file alone, so that both backends run the same trials: ``OUT/runs/trial_NNN``
trained by ``learn.train.train``. ``--backend local`` runs them through the local workers, each
to its end; ``--backend ray`` through Ray Tune, whose ASHA scheduler stops the trials whose
best validation error so far lies in the worse part of their rung. A killed sweep resumes
(``--resume``): locally each unfinished run folder goes on from its checkpoint; on Ray,
``Tuner.restore`` restarts the unfinished trials, which go on from their run folders.
``OUT/sweep.csv`` and ``OUT/sweep.md`` hold the results, ``OUT/sweep.png`` the validation error
against each searched setting, and the best trial is printed as the ``train`` command that
trains it again.
"""

from __future__ import annotations

import itertools
import json
import math
import os
import sys
import tomllib
from collections.abc import Callable
from contextlib import redirect_stdout
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.files import (
    MAX_TEXT_BYTES,
    check_input,
    check_nesting,
    read_json,
    write_text_atomic,
)
from sensorimotor.jobs.workers import Job, JobFailure, default_workers, raise_first, send_progress
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.runs import SIZES, model_config

SEARCHES = ("grid", "random")
SEARCHABLE = ("data", "model", "seed", "lr", "batch_size", "horizon", "patience", "min_ratio")
SEARCHABLE += ("max_epochs", *SIZES)
FIXED = tuple(f.name for f in fields(TrainConfig) if f.name not in ("device", "threads"))
FIXED += SIZES
RANGES = ("log_uniform", "uniform", "int_uniform")
ASHA = {"grace_period": 1, "reduction_factor": 2}
NO_SIGINT_HANDLER = "TUNE_DISABLE_SIGINT_HANDLER"
MAX_TRIALS = 1_000  # trials of a sweep (each a training: hours each at the paper's size)
MAX_T = 100  # ASHA's horizon in epochs when the sweep sets no max_epochs


@dataclass(frozen=True)
class Trial:
    """One point of the search: its name (its run folder's), the searched values, and what
    it trains: a database and a whole training configuration."""

    name: str
    values: dict
    data: str
    config: dict
    sizes: dict  # the model's sizes that are not the paper's


@dataclass(frozen=True)
class Sweep:
    """A sweep file, read and checked, with its trials drawn."""

    path: Path
    search: str
    space: dict
    trials: tuple[Trial, ...]
    asha: dict

    def record(self) -> dict:
        """What ``OUT/sweep.json`` holds: enough to tell a resumed sweep from another one."""
        return {
            "search": self.search,
            "space": self.space,
            "asha": self.asha,
            "trials": [asdict(t) for t in self.trials],
        }


def _table(raw: dict, key: str, path: Path) -> dict:
    value = raw.get(key, {})
    if not isinstance(value, dict):
        raise InputError(f"{path}: [{key}] must be a table, got {value!r}")
    return value


def read_sweep(path: str | Path) -> Sweep:
    """Read a sweep file; InputError naming the file and the setting on any problem."""
    path = check_input(path, "sweep file", MAX_TEXT_BYTES)
    try:
        raw = tomllib.loads(path.read_text())
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read the sweep file ({err})") from None
    except tomllib.TOMLDecodeError as err:
        raise InputError(f"{path}: not valid TOML ({err})") from None
    except RecursionError:
        raise InputError(f"{path}: nested too deeply to be a sweep file") from None
    check_nesting(raw, str(path))
    known = {"data", "search", "trials", "seed", "train", "space", "asha"}
    unknown = sorted(set(raw) - known)
    if unknown:
        raise InputError(f"{path}: unknown key {unknown[0]!r}: use {', '.join(sorted(known))}")
    search = raw.get("search", "grid")
    if search not in SEARCHES:
        raise InputError(f"{path}: search must be grid or random, got {search!r}")
    train, space = _table(raw, "train", path), _table(raw, "space", path)
    asha = {**ASHA, **_table(raw, "asha", path)}
    for key in train:
        if key not in FIXED:
            raise InputError(f"{path}: [train] {key!r} is not a setting: use {', '.join(FIXED)}")
    for key, value in asha.items():
        least = 1 if key == "grace_period" else 2
        if key not in ASHA:
            raise InputError(f"{path}: [asha] {key!r}: use grace_period or reduction_factor")
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise InputError(f"{path}: [asha] {key} must be an integer >= {least}, got {value!r}")
    if not space:
        raise InputError(f"{path}: [space] is empty: give the settings to search, e.g. lr = [...]")
    for key, values in space.items():
        _check_values(path, search, key, values, train)
    if "data" not in raw and "data" not in space:
        raise InputError(f'{path}: no data: give data = "DATABASE.npz" or search [space] data')
    fixed_data = raw.get("data")
    if fixed_data is not None and (not isinstance(fixed_data, str) or "data" in space):
        raise InputError(f"{path}: data must be one path (search several in [space])")
    if search == "grid":
        extra = sorted({"trials", "seed"} & set(raw))
        if extra:
            raise InputError(f'{path}: {extra[0]} is for search = "random"')
        count = math.prod(len(v) for v in space.values())  # before the grid is built
        if count > MAX_TRIALS:
            raise InputError(
                f"{path}: the grid holds {count:,} trials, more than {MAX_TRIALS:,}: search "
                'fewer values, or draw trials with search = "random"'
            )
        points = [
            dict(zip(space, combo, strict=True)) for combo in itertools.product(*space.values())
        ]
    else:
        points = _draw(path, raw, space)
    trials = []
    for i, values in enumerate(points):
        name = f"trial_{i:03d}"
        data = values.get("data", fixed_data)
        data = str((path.parent / data).resolve())
        settings = {**train, **{k: v for k, v in values.items() if k != "data"}}
        sizes = {k: settings.pop(k) for k in SIZES if k in settings}
        try:
            config = TrainConfig.of(**{"model": TrainConfig.model, **settings})
            model_config(config.model, sizes)
        except (InputError, TypeError) as err:
            raise InputError(f"{path}: {name} ({_show(values)}): {err}") from None
        config_dict = {k: v for k, v in asdict(config).items() if k not in ("device", "threads")}
        trials.append(Trial(name, values, data, config_dict, sizes))
    return Sweep(path, search, space, tuple(trials), asha)


def _check_values(path: Path, search: str, key: str, values, train: dict) -> None:
    if key not in SEARCHABLE:
        raise InputError(f"{path}: [space] {key!r} cannot be searched: use {', '.join(SEARCHABLE)}")
    if key in train:
        raise InputError(f"{path}: {key} is both fixed in [train] and searched in [space]")
    if isinstance(values, list):
        if not values:
            raise InputError(f"{path}: [space] {key} has no values")
        if len({json.dumps(v) for v in values}) < len(values):
            raise InputError(f"{path}: [space] {key} gives a value twice")
        if key == "data" and not all(isinstance(v, str) for v in values):
            raise InputError(f"{path}: [space] data must be a list of paths")
        return
    ok = (
        search == "random"
        and isinstance(values, dict)
        and len(values) == 1
        and next(iter(values)) in RANGES
    )
    bounds = next(iter(values.values())) if ok else None
    if not ok:
        kinds = (
            "a list" if search == "grid" else f"a list or one of {{{', '.join(RANGES)} = [a, b]}}"
        )
        raise InputError(f"{path}: [space] {key} must be {kinds}, got {values!r}")
    kind = next(iter(values))
    numbers = isinstance(bounds, list) and len(bounds) == 2
    numbers = numbers and all(
        isinstance(b, int | float) and not isinstance(b, bool) for b in bounds
    )
    if not numbers or not math.isfinite(bounds[0]) or not math.isfinite(bounds[1]):
        raise InputError(f"{path}: [space] {key}: {kind} needs [low, high], got {bounds!r}")
    if not bounds[0] < bounds[1] or (kind == "log_uniform" and bounds[0] <= 0):
        raise InputError(
            f"{path}: [space] {key}: {kind} needs 0 < low < high, got {bounds!r}"
            if kind == "log_uniform"
            else f"{path}: [space] {key}: {kind} needs low < high, got {bounds!r}"
        )


def _draw(path: Path, raw: dict, space: dict) -> list[dict]:
    """The random search's trials: ``trials`` draws, each setting in the order of the file."""
    n, seed = raw.get("trials"), raw.get("seed", 0)
    for key, value, least in (("trials", n, 1), ("seed", seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise InputError(f"{path}: {key} must be an integer >= {least}, got {value!r}")
    if n > MAX_TRIALS:
        raise InputError(f"{path}: trials must be at most {MAX_TRIALS:,}, got {n:,}")
    rng = np.random.default_rng(seed)
    points = []
    for _ in range(n):
        values = {}
        for key, spec in space.items():
            if isinstance(spec, list):
                values[key] = spec[int(rng.integers(len(spec)))]
                continue
            ((kind, (low, high)),) = spec.items()
            if kind == "int_uniform":
                values[key] = int(rng.integers(int(low), int(high) + 1))
            elif kind == "uniform":
                values[key] = float(f"{rng.uniform(low, high):.4g}")
            else:
                values[key] = float(f"{math.exp(rng.uniform(math.log(low), math.log(high))):.4g}")
        points.append(values)
    return points


def _show(values: dict) -> str:
    return ", ".join(f"{k}={v}" for k, v in values.items())


# --- running ----------------------------------------------------------------------------------


def _trial_job(name: str, data: str, run_dir: str, config: dict, sizes: dict) -> float:
    """One trial in a local worker: train (or go on training) its run folder; its best
    validation error."""
    from sensorimotor.learn.train import train

    def on_epoch(r, stopper) -> None:
        send_progress(name, f"epoch {r.epoch:3d} val {r.val_error:.5f} (best {stopper.lowest:.5f})")

    resume = (Path(run_dir) / "config.json").exists()
    train_config = TrainConfig(**config)
    model = model_config(train_config.model, sizes) if sizes else None
    result = train(data, run_dir, train_config, resume, on_epoch, model)
    send_progress(name, f"done: {result.ending}, best val {result.best_val_error:.5f}")
    return result.best_val_error


def _tune_trial(config: dict) -> None:
    """One trial in a Ray Tune actor: the same training, each epoch's best validation error
    so far told to Tune (its ASHA scheduler may end the trial there)."""
    from ray import tune

    from sensorimotor.learn.train import train

    trial = config["trial"]
    reported = []

    def on_epoch(r, stopper) -> None:
        reported.append(r.epoch)
        tune.report({"val_error": stopper.lowest, "epoch": r.epoch + 1})

    resume = (Path(trial["run_dir"]) / "config.json").exists()
    config = TrainConfig(**trial["config"])
    model = model_config(config.model, trial["sizes"]) if trial["sizes"] else None
    result = train(trial["data"], trial["run_dir"], config, resume, on_epoch, model)
    if not reported:  # its epochs were all trained before a kill: Tune still needs its metric
        tune.report({"val_error": result.best_val_error, "epoch": result.epochs})


def _check_data(sweep: Sweep) -> None:
    """Every database loads and is big enough for each trial, before any trial starts."""
    from sensorimotor.learn.train import check_trainable
    from sensorimotor.sim.database import load_database

    dbs = {}
    for trial in sweep.trials:
        if trial.data not in dbs:
            dbs[trial.data] = load_database(trial.data)
        check_trainable(dbs[trial.data], TrainConfig(**trial.config))


def _open(sweep: Sweep, out: Path, resume: bool) -> None:
    """Create ``out`` with its ``sweep.json``, or (with ``resume``) check it holds this sweep."""
    record = out / "sweep.json"
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, not a sweep folder")
    if record.exists() and not resume:
        raise InputError(f"{out}: already holds a sweep; pass --resume to go on with it")
    if record.exists():
        old = read_json(record, "sweep record")
        if old != json.loads(json.dumps(sweep.record())):
            raise InputError(
                f"{out}: --resume with another sweep than {sweep.path} (its trials differ)"
            )
        return
    try:
        (out / "runs").mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{out}: cannot create the sweep folder ({err.strerror})") from None
    write_text_atomic(record, json.dumps(sweep.record(), indent=2) + "\n")


@dataclass(frozen=True)
class SweepResult:
    """A sweep's outcome: one row per trial (best first), the best trial's ``train`` command,
    the files written, and the trials that failed (named with their errors)."""

    out: Path
    rows: list[dict]
    best_command: str | None
    files: list[Path]
    failures: list[JobFailure]


def run_sweep(
    spec: str | Path,
    out: str | Path,
    backend: str = "local",
    address: str | None = None,
    workers: int | None = None,
    resume: bool = False,
    log: Callable[[str], None] = print,
) -> SweepResult:
    """Run (or with ``resume`` go on with) the sweep of file ``spec`` into folder ``out``."""
    from sensorimotor.jobs.backend import check_backend

    check_backend(backend, address, workers)
    if backend == "ray":
        from sensorimotor.jobs.ray_backend import import_ray

        import_ray()  # a missing extra: said before anything is written
    sweep, out = read_sweep(spec), Path(out)
    _check_data(sweep)
    _open(sweep, out, resume)
    searched = ", ".join(sweep.space)
    log(f"sweep of {len(sweep.trials)} trials ({sweep.search} over {searched}) -> {out}")
    if backend == "local":
        failures = _run_local(sweep, out, default_workers() if workers is None else workers, log)
    else:
        failures = _run_ray(sweep, out, address, workers, resume, log)
    result = write_results(sweep, out, backend, failures)
    raise_first(failures)
    return result


def _run_local(sweep: Sweep, out: Path, workers: int, log) -> list[JobFailure]:
    from sensorimotor.jobs.workers import run_jobs

    jobs = []
    for t in sweep.trials:
        run_dir = out / "runs" / t.name
        if not (run_dir / "result.json").exists():
            jobs.append(Job(t.name, _trial_job, (t.name, t.data, str(run_dir), t.config, t.sizes)))
    log(f"  {len(jobs)} to train, {len(sweep.trials) - len(jobs)} done, {workers} workers")
    _, failures = run_jobs(jobs, workers, lambda name, msg: log(f"  {name}: {msg}"))
    return failures


def _run_ray(sweep: Sweep, out: Path, address, workers, resume: bool, log) -> list[JobFailure]:
    from sensorimotor.jobs.ray_backend import ray_session

    _LOG[0] = log
    with ray_session(address, workers) as cpus:
        from ray import tune
        from ray.tune.schedulers import ASHAScheduler

        experiment = (out / "tune").resolve()
        trainable = tune.with_resources(_tune_trial, {"cpu": 1})
        if resume and tune.Tuner.can_restore(str(experiment)):
            log("  restoring the Ray Tune experiment: unfinished trials go on from their runs")
            tuner = tune.Tuner.restore(str(experiment), trainable, resume_errored=True)
        else:
            max_epochs = {t.config["max_epochs"] for t in sweep.trials}
            # past the last epoch: a trial's own cap ends it (writing result.json), not ASHA's
            max_t = max(m or MAX_T for m in max_epochs) + 1
            scheduler = ASHAScheduler(time_attr="epoch", max_t=max_t, **sweep.asha)
            trials = [
                {
                    "name": t.name,
                    "data": t.data,
                    "run_dir": str((out / "runs" / t.name).resolve()),
                    "config": t.config,
                    "sizes": t.sizes,
                }
                for t in sweep.trials
            ]
            tuner = tune.Tuner(
                trainable,
                param_space={"trial": tune.grid_search(trials)},
                tune_config=tune.TuneConfig(
                    metric="val_error",
                    mode="min",
                    scheduler=scheduler,
                    max_concurrent_trials=cpus if workers is None else workers,
                    trial_name_creator=_trial_name,
                    trial_dirname_creator=_trial_name,
                    reuse_actors=True,  # a trial's process serves the next: no new imports
                ),
                run_config=tune.RunConfig(
                    name=experiment.name,
                    storage_path=str(experiment.parent),
                    verbose=0,
                    callbacks=[_progress_callback()],
                ),
            )
        # Ctrl-C as everywhere else: KeyboardInterrupt, this run's trials ended with the Ray
        # session (Tune's own handler would return as if done); Tune saves its state as it goes
        quiet = os.environ.get(NO_SIGINT_HANDLER)
        os.environ[NO_SIGINT_HANDLER] = "1"
        try:
            with redirect_stdout(sys.stderr):  # Tune's own lines: stdout is for the command
                grid = tuner.fit()
        finally:
            if quiet is None:
                os.environ.pop(NO_SIGINT_HANDLER)
            else:
                os.environ[NO_SIGINT_HANDLER] = quiet
    if grid.num_terminated + grid.num_errors < len(grid):  # stopped by a signal (SIGUSR1)
        raise KeyboardInterrupt  # as locally: no results until the sweep is done (--resume)
    failures = []
    for result in grid:
        if result.error is not None:
            name = result.config["trial"]["name"]
            failures.append(JobFailure(name, getattr(result.error, "cause", None) or result.error))
    return failures


_LOG: list[Callable[[str], None]] = [print]  # where the running sweep's Tune lines go


def _emit(line: str) -> None:
    """A line of the Tune callback to the running sweep's log (the callback is pickled with
    the experiment, so it holds no log of its own)."""
    _LOG[0](line)


def _trial_name(trial) -> str:
    return trial.config["trial"]["name"]


def _progress_callback():
    """A Tune callback that prints each trial's epochs as the local workers' lines are."""
    from ray.tune import Callback

    class Progress(Callback):
        def on_trial_result(self, iteration, trials, trial, result, **info) -> None:
            name = _trial_name(trial)
            _emit(f"  {name}: epoch {result['epoch'] - 1:3d} best val {result['val_error']:.5f}")

        def on_trial_complete(self, iteration, trials, trial, **info) -> None:
            _emit(f"  {_trial_name(trial)}: done")

    return Progress()


def write_results(sweep: Sweep, out: Path, backend: str, failures: list[JobFailure]) -> SweepResult:
    """``sweep.csv`` (trial order), ``sweep.md`` (best first, with the best ``train`` command)
    and ``sweep.png`` (validation error against each searched setting), from the run folders."""
    from sensorimotor.pipeline import sweep_results as sr

    failed = {f.name for f in failures}
    # a trial without result.json and without failure was ended by ASHA (or by a kill)
    ended = "ASHA" if backend == "ray" else "unfinished"
    rows = []
    for t in sweep.trials:
        row = sr.trial_row(t.name, t.values, out / "runs" / t.name, ended, t.name in failed)
        if row["stopped"] == ended and row["epochs"] == t.config["max_epochs"]:
            row["stopped"] = "max epochs"  # ended by ASHA, or a kill, after its last epoch
        rows.append(row)
    keys = list(sweep.space)
    ranked = sorted(
        (r for r in rows if r["best_val_error"] is not None), key=lambda r: r["best_val_error"]
    )
    best = None
    if ranked:
        trial = next(t for t in sweep.trials if t.name == ranked[0]["trial"])
        best = sr.command_line(trial.data, trial.config, trial.sizes)
    files = [
        write_text_atomic(out / "sweep.csv", sr.results_csv(rows, keys)),
        write_text_atomic(
            out / "sweep.md",
            sr.results_markdown(
                sweep.path,
                sweep.search,
                ranked + [r for r in rows if r not in ranked],
                keys,
                best,
                backend,
            ),
        ),
    ]
    files += sr.save_sweep_figure(rows, sweep.space, out / "sweep.png")
    return SweepResult(out, ranked, best, files, failures)
