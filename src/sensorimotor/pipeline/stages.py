"""The paper's stages as jobs: top-level functions with picklable arguments, run in worker
processes or Ray tasks (``jobs``), shared by ``reproduce`` (``paper``) and the experiments that
train and test models of their own (``experiments.scaling``). Each writes its output whole,
beside the cache key it was made with."""

from __future__ import annotations

import shutil
from dataclasses import asdict
from pathlib import Path

from sensorimotor.errors import InputError
from sensorimotor.files import read_json_if_any, write_json_atomic
from sensorimotor.jobs.cache import stage_key
from sensorimotor.jobs.workers import send_progress
from sensorimotor.version import __version__


def data_job(world: str, steps: int, seed: int, path: str, key: str) -> str:
    from sensorimotor.sim.database import generate, save_database
    from sensorimotor.sim.world import load_world

    save_database(generate(load_world(world), steps, seed), path)
    write_json_atomic(Path(path).with_suffix(".json"), {"key": key})
    return path


def data_key(world: str, steps: int) -> str:
    """The cache key of a world's database: what ``generate`` makes it from."""
    return stage_key({"world": world, "steps": steps, "seed": 0, "version": __version__})


def configs(config: dict):
    """A job's training ``config`` (``train_config``) as (TrainConfig, ModelConfig): its
    ``sizes`` are the model's, the rest the training's, over the kind's defaults."""
    from sensorimotor.learn.config import TrainConfig
    from sensorimotor.learn.models import ModelConfig

    settings = {k: v for k, v in config.items() if k != "sizes"}
    train = TrainConfig.of(**settings)
    return train, ModelConfig(kind=train.model, **config.get("sizes", {}))


def run_matches(run: Path, data_sha: str, config: dict) -> bool:
    """Whether a run folder was made from this data, this training configuration and the
    model sizes ``models.py`` gives now (a setting it does not record ran at its default)."""
    from sensorimotor.learn.runs import setting_defaults

    made = read_json_if_any(run / "config.json", "run config")
    if made is None:
        return False
    train, model = configs(config)
    want = {k: v for k, v in asdict(train).items() if k != "device"}
    kind = train.model
    made_model = {**setting_defaults("model", kind), **made.get("model", {})}
    return (
        made.get("data", {}).get("sha256") == data_sha
        and {**setting_defaults("train", kind), **made.get("train", {})} == want
        and {**made_model, "n_sensors": model.n_sensors} == model.to_dict()
    )


def stack_name(model: str, runs: list[tuple[str, int]]) -> str:
    """A stacked job's name: ``square+rooms1__sm__s0,1`` where every world has those seeds."""
    seeds: dict[str, list[str]] = {}
    for world, seed in runs:
        seeds.setdefault(world, []).append(str(seed))
    if len({tuple(s) for s in seeds.values()}) == 1:
        return f"{'+'.join(seeds)}__{model}__s{','.join(next(iter(seeds.values())))}"
    return "+".join(f"{world}__{model}__s{','.join(s)}" for world, s in seeds.items())


def train_config(
    model: str,
    device: str,
    max_epochs: int | None,
    patience: int,
    seed: int | None = None,
    sizes: dict | None = None,
    **settings,
) -> dict:
    """The training configuration of one run (of a stack's runs without ``seed``): ``sizes``
    and ``settings`` change the model's and the training's (an ablation)."""
    config = {"model": model, "device": device, "max_epochs": max_epochs, "patience": patience}
    config |= settings | ({"sizes": sizes} if sizes else {})
    return config if seed is None else {**config, "seed": seed}


def train_job(runs: list[tuple[str, int, str, str]], config: dict) -> dict:
    """Runs of one model in one process, in one ``train.train_runs`` call (stacked where the
    model and device allow); each run ``(data, seed, run folder, data hash)``, feed-forward
    ones from several worlds at once.
    The runs of a database that fails to load are left out, the others train, then the job
    fails naming the first run left out and its file."""
    from sensorimotor.sim.database import load_database

    bad: dict[str, InputError] = {}
    for data in dict.fromkeys(data for data, _, _, _ in runs):
        try:
            load_database(data)  # bad data fails here, before a stale run folder is cleared
        except InputError as err:
            bad[data] = err
    left_out = [(data, Path(run_dir).name) for data, _, run_dir, _ in runs if data in bad]
    runs = [run for run in runs if run[0] not in bad]
    results = _train_stack(runs, config) if runs else {}
    if left_out:
        data, name = left_out[0]
        more = f" (and {len(left_out) - 1} more runs)" if len(left_out) > 1 else ""
        raise InputError(f"{name}{more}: {bad[data]}")
    return results


def _train_stack(runs: list[tuple[str, int, str, str]], config: dict) -> dict:
    """``train_job``'s training, its databases known to load: a run folder made from other
    inputs is cleared first."""
    for _, seed, run_dir, data_sha in runs:
        run = Path(run_dir)
        if run.exists() and not run_matches(run, data_sha, {**config, "seed": seed}):
            shutil.rmtree(run)
    return train_and_tell(
        [data for data, _, _, _ in runs], [(seed, run_dir) for _, seed, run_dir, _ in runs], config
    )


def train_and_tell(data: str | list[str], runs: list[tuple[int, str]], config: dict) -> dict:
    """``train.train_runs`` of ``runs`` (seed, run folder) on ``data`` (one database, or one
    per run), resumed where a folder holds a checkpoint, each epoch sent as a progress line;
    the best validation error of each run by its folder's name."""
    from sensorimotor.learn.runs import epoch_label
    from sensorimotor.learn.train import train_runs

    names = [Path(run_dir).name for _, run_dir in runs]
    stacked = f" per seed, {len(runs)} stacked" if len(runs) > 1 else ""

    def on_epoch(i, r, stopper) -> None:
        send_progress(
            names[i],
            f"{epoch_label(r.epoch, config.get('max_epochs'))} val {r.val_error:.5f} "
            f"(best {stopper.lowest:.5f}) "
            f"{r.samples_per_s / 1e3:.0f} k samples/s{stacked}",
        )

    train, model = configs(config)
    results = train_runs(data, runs, train, resume=True, on_epoch=on_epoch, model=model)
    for name, result in zip(names, results, strict=True):
        send_progress(name, f"done: {result.ending}, best val {result.best_val_error:.5f}")
    return {name: r.best_val_error for name, r in zip(names, results, strict=True)}


def eval_job(run_dir: str, data: list[str], out: str, key: str) -> dict:
    """Test one run on each database of ``data``; its result, kept in ``out`` with ``key``."""
    from sensorimotor.learn.evaluate import evaluate_run

    res = evaluate_run(run_dir, data)
    write_json_atomic(Path(out), {"key": key, "result": res})
    return res


def analysis_job(
    run: str, data: str, out: str, fit_data: str | None, key: str, event_probes: bool = False
) -> dict:
    """Analyse ``run`` (a run folder or ``"raw"``) on ``data``'s test split into ``out`` (with
    clusters fitted on ``fit_data``'s, where given; with ``event_probes``, the event probes
    fitted on ``data``'s training split); its metrics."""
    from sensorimotor.analysis import analyze_files

    # the paper's analyses leave the place probes to --experiment memory (a minute of the quick run)
    res = analyze_files(run, data, out, fit_data=fit_data, probes=False, event_probes=event_probes)
    write_json_atomic(Path(out) / "stage.json", {"key": key})
    return res.metrics
