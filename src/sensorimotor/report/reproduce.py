"""``sensorimotor reproduce``: the whole paper, and the full 3 x 3 table, from one command.

Stages, each cached under ``OUT`` by a hash of what it depends on (a rerun does only what is
missing; a killed run resumes, losing nothing finished):

    data      OUT/data/{world}.npz                     one database per world
    train     OUT/runs/{world}__{model}__s{seed}/      every model on every world (--worlds), K seeds
    evaluate  OUT/eval/{run}.json                      each run on the three test splits
    analyze   OUT/analysis/{run}/, OUT/analysis/raw__{world}/, OUT/transfer/{run}__to__{world}/
    NAME      OUT/NAME/                                each experiment past the paper
                                                       (--experiment NAME: experiments.py)
    report    OUT/report.md, OUT/report.html           Table I, figures, the paper's claims
"""

from __future__ import annotations

import json
import shutil
import sys
import time
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass, field
from pathlib import Path

from sensorimotor.errors import InputError
from sensorimotor.files import file_hash, write_json_atomic
from sensorimotor.learn.models import MODEL_KINDS
from sensorimotor.learn.runs import count
from sensorimotor.report.backend import GPU_SHARE, job_runner
from sensorimotor.report.cache import read_key, stage_key
from sensorimotor.report.workers import Job, hardware, report
from sensorimotor.version import __version__

WORLDS = ("square", "rooms1", "rooms2")
TRANSFER_FROM = ("square", "rooms1")  # paper Figs. 8-9: Rec-SM clusters carried to other worlds


@dataclass(frozen=True)
class Scale:
    """How big a reproduction is."""

    name: str
    steps: int
    """Rows of each world's database (the paper: 1,000,000)."""
    seeds: int
    """Default number of seeds per model and world."""
    max_epochs: dict[str, int | None] = field(default_factory=dict)
    """Cap on epochs per model kind (missing or None: early stopping alone)."""
    patience: int = 10
    """Early-stopping patience in epochs (the paper: 10 epochs of 800,000 steps)."""
    caveat: str = ""
    """What the report of this scale can and cannot say, at its top."""


SCALES = {
    "smoke": Scale(
        "smoke",
        20_000,
        1,
        {k: 2 for k in MODEL_KINDS},
        caveat="A smoke test of the pipeline: every model is trained for 2 epochs on 20,000 "
        "steps, so its numbers and verdicts say nothing about the paper. `--scale paper` runs "
        "the paper's protocol.",
    ),
    # 5 times smaller epochs: a 5 times longer patience sees as many samples as the paper's 10
    "quick": Scale(
        "quick",
        200_000,
        1,
        {"s": 10, "sm": 10, "rec-s": 30, "rec-sm": 80},
        50,
        caveat="A quick run: 200,000-step databases, capped epochs and one seed, so its numbers "
        "are indicative only and its verdicts carry no spread over seeds. `--scale paper` runs "
        "the paper's protocol.",
    ),
    "paper": Scale("paper", 1_000_000, 5, {}),
}


def _write_json(path: Path, obj) -> None:
    write_json_atomic(path, obj)


# --- jobs (top-level functions: they run in worker processes) --------------------------------


def _data_job(world: str, steps: int, seed: int, path: str, key: str) -> str:
    from sensorimotor.sim.database import generate, save_database
    from sensorimotor.sim.world import load_world

    save_database(generate(load_world(world), steps, seed), path)
    _write_json(Path(path).with_suffix(".json"), {"key": key})
    return path


def _data_key(world: str, sc: Scale) -> str:
    """The cache key of a world's database: what ``generate`` makes it from."""
    return stage_key({"world": world, "steps": sc.steps, "seed": 0, "version": __version__})


def run_matches(run: Path, data_sha: str, config: dict) -> bool:
    """Whether a run folder was made from this data, this training configuration and the
    model sizes ``models.py`` gives now."""
    from sensorimotor.learn.models import ModelConfig
    from sensorimotor.learn.runs import TrainConfig

    try:
        made = json.loads((run / "config.json").read_text())
    except (OSError, ValueError):
        return False
    train = TrainConfig(**config)
    want = {k: v for k, v in asdict(train).items() if k != "device"}
    return (
        made.get("data", {}).get("sha256") == data_sha
        and made.get("train") == want
        and made.get("model") == ModelConfig(kind=train.model).to_dict()
    )


# Core-seconds one seed took in its stack in the paper grid on a 2-core CPU (docs/results.md):
# the order in which training jobs start (longest first).
SEED_COST = {"rec-sm": 230, "rec-s": 77, "sm": 44, "s": 20}


def _stack_name(model: str, runs: list[tuple[str, int]]) -> str:
    """A stacked job's name: ``square+rooms1__sm__s0,1`` where every world has those seeds."""
    seeds: dict[str, list[str]] = {}
    for world, seed in runs:
        seeds.setdefault(world, []).append(str(seed))
    if len({tuple(s) for s in seeds.values()}) == 1:
        return f"{'+'.join(seeds)}__{model}__s{','.join(next(iter(seeds.values())))}"
    return "+".join(f"{world}__{model}__s{','.join(s)}" for world, s in seeds.items())


def _train_config(sc: Scale, model: str, device: str, seed: int | None = None) -> dict:
    """The training configuration of one run (of a stack's runs without ``seed``)."""
    config = {
        "model": model,
        "device": device,
        "max_epochs": sc.max_epochs.get(model),
        "patience": sc.patience,
    }
    return config if seed is None else {**config, "seed": seed}


def _train_job(runs: list[tuple[str, int, str, str]], config: dict) -> dict:
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
    """``_train_job``'s training, its databases known to load."""
    from sensorimotor.learn.runs import TrainConfig
    from sensorimotor.learn.train import train_runs

    for _, seed, run_dir, data_sha in runs:
        run = Path(run_dir)
        if run.exists() and not run_matches(run, data_sha, {**config, "seed": seed}):
            shutil.rmtree(run)
    names = [Path(run_dir).name for _, _, run_dir, _ in runs]

    def on_epoch(i, r, stopper) -> None:
        report(
            names[i],
            f"epoch {r.epoch:3d} val {r.val_error:.5f} (best {stopper.lowest:.5f}) "
            f"{r.samples_per_s / 1e3:.0f} k samples/s"
            + (f" per seed, {len(runs)} stacked" if len(runs) > 1 else ""),
        )

    results = train_runs(
        [data for data, _, _, _ in runs],
        [(seed, run_dir) for _, seed, run_dir, _ in runs],
        TrainConfig(**config, seed=0),
        resume=True,
        on_epoch=on_epoch,
    )
    for name, result in zip(names, results, strict=True):
        report(
            name,
            f"done: {result.ending}, best val {result.best_val_error:.5f}",
        )
    return {name: r.best_val_error for name, r in zip(names, results, strict=True)}


def _eval_job(run_dir: str, data: list[str], out: str, key: str) -> dict:
    from sensorimotor.learn.evaluate import evaluate_run, load_run
    from sensorimotor.sim.database import load_database

    res = evaluate_run(load_run(run_dir), [load_database(p) for p in data])
    _write_json(Path(out), {"key": key, "result": res})
    return res


def _analysis_job(run: str, data: str, out: str, fit_data: str | None, key: str) -> dict:
    from sensorimotor.analysis import analyze_files

    res = analyze_files(run, data, out, fit_data=fit_data)
    _write_json(Path(out) / "stage.json", {"key": key})
    return res.metrics


# --- the pipeline ------------------------------------------------------------------------------


@dataclass
class Reproduction:
    """Where a reproduction lives and what it has found so far."""

    out: Path
    scale: Scale
    seeds: int
    device: str
    workers: int
    worlds: tuple[str, ...] = WORLDS  # trained on (and analysed in); tested on all of WORLDS
    timings: dict[str, dict] = field(default_factory=dict)
    data: dict[str, Path] = field(default_factory=dict)
    runs: list[tuple[str, str, int]] = field(default_factory=list)  # (world, model, seed)
    table: dict = field(default_factory=dict)
    analyses: dict[str, dict] = field(default_factory=dict)
    transfers: dict[str, dict] = field(default_factory=dict)
    experiments: tuple[str, ...] = ()  # past the paper, run after its stages
    found: dict[str, dict] = field(default_factory=dict)  # each experiment's numbers

    def run_name(self, world: str, model: str, seed: int) -> str:
        from sensorimotor.learn.runs import run_name

        return run_name(world, model, seed)

    def run_dir(self, world: str, model: str, seed: int) -> Path:
        return self.out / "runs" / self.run_name(world, model, seed)


@contextmanager
def _stage(rep: Reproduction, name: str, log: Callable[[str], None]):
    """Time one stage into ``rep.timings``."""
    log(f"[bold]stage {name}[/bold]")
    t0 = time.perf_counter()
    yield
    rep.timings[name] = {**rep.timings.get(name, {}), "seconds": time.perf_counter() - t0}


def _raise_failures(failures, log) -> None:
    if not failures:
        return
    for f in failures[1:]:
        log(f"[red]failed: {f.name}: {f.error}")
    first = failures[0]
    more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
    if isinstance(first.error, InputError):
        msg = str(first.error)  # a stack's error may name its run already
        msg = msg if msg.startswith(f"{first.name}") else f"{first.name}: {msg}"
        raise InputError(f"run {msg}{more}")
    raise RuntimeError(f"run {first.name} failed{more}") from first.error


def check_worlds(worlds: Sequence[str] | None) -> tuple[str, ...]:
    """The trained worlds, in the paper's order: any of ``WORLDS``, at least one."""
    if worlds is None:
        return WORLDS
    unknown = [w for w in worlds if w not in WORLDS]
    if unknown or not worlds:
        raise InputError(
            f"--worlds: use any of {', '.join(WORLDS)} (comma-separated), got {','.join(worlds)!r}"
        )
    return tuple(w for w in WORLDS if w in worlds)


def _eval_path(rep: Reproduction, name: str) -> Path:
    return rep.out / "eval" / f"{name}.json"


def _eval_job_of(rep: Reproduction, world: str, model: str, seed: int, data_hash) -> Job | None:
    """The job that evaluates one trained run on every world, or None if its result is kept."""
    run = rep.run_dir(world, model, seed)
    path = _eval_path(rep, run.name)
    key = stage_key({"model": file_hash(run / "model.pt"), "data": data_hash})
    if read_key(path) == key:
        return None
    data_list = [str(rep.data[w]) for w in WORLDS]
    return Job(run.name, _eval_job, (str(run), data_list, str(path), key))


Target = tuple[str, str, str, str | None, str]  # name, run ("raw" or folder), data, fit, out


def _raw_targets(rep: Reproduction, world: str) -> list[Target]:
    """The analysis of ``world``'s raw readings (the baseline representation)."""
    dest = rep.out / "analysis" / f"raw__{world}"
    return [(f"raw__{world}", "raw", str(rep.data[world]), None, str(dest))]


def _analysis_targets(rep: Reproduction, world: str, model: str, seed: int) -> list[Target]:
    """The analyses of one run: of its own world, and for Rec-SM seed 0 trained on a
    ``TRANSFER_FROM`` world, the transfer to each other world."""
    run = rep.run_dir(world, model, seed)
    own = (run.name, str(run), str(rep.data[world]), None, str(rep.out / "analysis" / run.name))
    targets = [own]
    if model == "rec-sm" and seed == 0 and world in TRANSFER_FROM:
        for target in WORLDS:
            if target != world:
                name = f"{run.name}__to__{target}"
                dest = str(rep.out / "transfer" / name)
                targets.append((name, str(run), str(rep.data[target]), str(rep.data[world]), dest))
    return targets


def _analysis_job_of(target: Target, path_hash: dict[str, str]) -> Job | None:
    """The job of one analysis, or None if its result is kept. ``path_hash``: each database's
    hash by its path, computed once (a database is tens of MB to read again)."""
    from sensorimotor.analysis import METRICS_VERSION

    name, run, data, fit, dest = target
    model_hash = "raw" if run == "raw" else file_hash(Path(run) / "model.pt")
    key = stage_key(
        {
            "model": model_hash,
            "data": path_hash[data],
            "fit": None if fit is None else path_hash[fit],
            "version": __version__,
            "metrics": METRICS_VERSION,
        }
    )
    metrics_path = Path(dest) / "metrics.json"
    if metrics_path.exists() and read_key(Path(dest) / "stage.json") == key:
        return None
    return Job(name, _analysis_job, (run, data, dest, fit, key))


def _count(rep: Reproduction, stage: str, run: int, kept: int, overlapped: dict) -> None:
    """A stage's job counts: ``kept`` found done, of which ``overlapped[stage]`` were done
    during training (the rest by an earlier invocation)."""
    during = overlapped[stage]
    rep.timings[stage] = {"jobs": run, "cached": kept - during, "during_training": during}


def _training_jobs(rep: Reproduction, data_hash: dict[str, str]):
    """The jobs that train what is not kept: (jobs, each job's runs by name, trainings).

    One job is one ``train.train_runs`` call: on the stacked engine, every seed of S (or SM)
    of all worlds at once, and every seed of Rec-S (or Rec-SM) of one world (a recurrent
    stack shares its batches); otherwise one job a run."""
    from sensorimotor.learn.train import trains_stacked

    groups: dict[tuple, list] = {}  # the runs of one job: (world, model, seed, entry)
    for world in rep.worlds:
        for model in MODEL_KINDS:
            for seed in range(rep.seeds):
                rep.runs.append((world, model, seed))
                run = rep.run_dir(world, model, seed)
                done = (run / "result.json").exists()
                config = _train_config(rep.scale, model, rep.device, seed)
                if done and run_matches(run, data_hash[world], config):
                    continue
                if not trains_stacked(model, rep.device):
                    key = (model, world, seed)
                elif model.startswith("rec"):
                    key = (model, world)
                else:
                    key = (model,)
                entry = (str(rep.data[world]), seed, str(run), data_hash[world])
                groups.setdefault(key, []).append((world, model, seed, entry))
    jobs, trains = [], {}
    for (model, *_), runs in groups.items():
        name = _stack_name(model, [(world, seed) for world, _, seed, _ in runs])
        config = _train_config(rep.scale, model, rep.device)
        jobs.append(Job(name, _train_job, ([entry for *_, entry in runs], config)))
        trains[name] = [(world, model, seed) for world, model, seed, _ in runs]
    return jobs, trains, sum(len(runs) for runs in groups.values())


def reproduce(
    out: str | Path,
    scale: str = "quick",
    seeds: int | None = None,
    device: str = "cpu",
    workers: int | None = 1,
    log: Callable[[str], None] = print,
    argv: list[str] | None = None,
    worlds: Sequence[str] | None = None,
    backend: str = "local",
    address: str | None = None,
    experiments: Sequence[str] | None = None,
) -> Reproduction:
    """Run (or resume) every stage; returns what was found. See the module docstring.

    ``worlds``: the worlds models are trained and analysed in, any of ``WORLDS`` (default
    all); every trained model is still tested on all three, as the paper's Table I.
    ``backend``: "local" (worker processes) or "ray" (Ray tasks on the cluster at ``address``,
    or on one started here); the same jobs, the same seeds, the same results. ``workers``:
    jobs at a time (None: every core here, or every CPU of the Ray cluster).
    ``experiments``: the experiments past the paper to run after its stages (names of
    ``experiments.EXPERIMENTS``; None: ``experiments.DEFAULT``)."""
    from sensorimotor.learn.train import resolve_device
    from sensorimotor.report.experiments import check_experiments

    chosen = check_experiments(experiments)
    gpus = GPU_SHARE if backend == "ray" and resolve_device(device) == "cuda" else 0.0
    with job_runner(backend, address, workers, gpus) as (runner, workers):
        return _reproduce(out, scale, seeds, device, workers, log, argv, worlds, runner, chosen)


def _reproduce(
    out, scale, seeds, device, workers, log, argv, worlds, run_jobs, experiments=()
) -> Reproduction:
    """``reproduce`` with its jobs run by ``run_jobs`` (``workers.run_jobs``'s signature)."""
    if scale not in SCALES:
        raise InputError(f"unknown scale {scale!r}: use one of {', '.join(SCALES)}")
    sc = SCALES[scale]
    seeds = sc.seeds if seeds is None else seeds
    if seeds < 1:
        raise InputError(f"--seeds must be at least 1, got {seeds}")
    trained = check_worlds(worlds)
    from sensorimotor.learn.train import resolve_device

    device = resolve_device(device)  # before any folder is made
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, not an output folder")
    try:
        for sub in ("data", "runs", "eval", "analysis", "transfer", "figures"):
            (out / sub).mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{out}: cannot create the output folder ({err.strerror})") from None
    rep = Reproduction(out, sc, seeds, device, workers, trained, experiments=tuple(experiments))
    t_start = time.perf_counter()

    def progress(name: str, message: str) -> None:
        log(f"  {name}: {message}")

    # data ---------------------------------------------------------------------------------
    with _stage(rep, "data", log):
        jobs = []
        for world in WORLDS:
            path = out / "data" / f"{world}.npz"
            key = _data_key(world, sc)
            rep.data[world] = path
            if path.exists() and read_key(path.with_suffix(".json")) == key:
                continue
            jobs.append(Job(f"data {world}", _data_job, (world, sc.steps, 0, str(path), key)))
        rep.timings["data"] = {"jobs": len(jobs), "cached": len(WORLDS) - len(jobs)}
        _, failures = run_jobs(jobs, workers, progress)
        _raise_failures(failures, log)
    data_hash = {w: file_hash(p) for w, p in rep.data.items()}
    path_hash = {str(rep.data[w]): h for w, h in data_hash.items()}

    # train --------------------------------------------------------------------------------
    with _stage(rep, "train", log):
        from sensorimotor.learn.fast.stacked_engine import computes_models_py
        from sensorimotor.learn.train import trains_stacked

        jobs, trains, n_train = _training_jobs(rep, data_hash)
        # longest first, so that the workers finish closer together
        jobs.sort(key=lambda job: -sum(SEED_COST[model] for _, model, _ in trains[job.name]))
        n_jobs = len(jobs)
        rep.timings["train"] = {"jobs": n_train, "cached": len(rep.runs) - n_train}
        stacked = ""
        if len(jobs) < n_train:  # some job trains a stack; asked only then (it loads numba)
            stacked = (
                " (seeds stacked)"
                if trains_stacked("rec-sm", device)
                else " (S and SM seeds stacked)"
            )
        log(
            f"  {count(n_train, 'training')} to run in {count(len(jobs), 'job')}{stacked}"
            + f", {len(rep.runs) - n_train} cached, {count(workers, 'worker')}"
        )
        to_train = {model for runs in trains.values() for _, model, _ in runs}
        for model in MODEL_KINDS:
            if model in to_train and not computes_models_py(model):
                log(
                    f"  [yellow]models.py's {model} is not what the stacked passes compute: it trains "
                    "with autograd (slower)"
                )
        overlapped = {"evaluate": 0, "analyze": 0}

        def then(name: str, _result) -> list[Job]:
            """Evaluate and analyse each run a training job finished, while others train."""
            more = []
            for world, model, seed in trains.pop(name, []):  # [] for a follow-up job
                more.append(_eval_job_of(rep, world, model, seed, data_hash))
                targets = _analysis_targets(rep, world, model, seed)
                more += [_analysis_job_of(tg, path_hash) for tg in targets]
            more = [job for job in more if job is not None]
            overlapped["evaluate"] += sum(job.fn is _eval_job for job in more)
            overlapped["analyze"] += sum(job.fn is _analysis_job for job in more)
            return more

        raw = [_analysis_job_of(tg, path_hash) for w in rep.worlds for tg in _raw_targets(rep, w)]
        jobs += [job for job in raw if job is not None]  # cheap: they fill the end
        overlapped["analyze"] += len(jobs) - n_jobs
        _, failures = run_jobs(jobs, workers, progress, then=then)
        _raise_failures(failures, log)

    # evaluate -----------------------------------------------------------------------------
    with _stage(rep, "evaluate", log):
        jobs, results = [], {}
        for world, model, seed in rep.runs:
            name = rep.run_name(world, model, seed)
            job = _eval_job_of(rep, world, model, seed, data_hash)
            if job is None:
                results[name] = json.loads(_eval_path(rep, name).read_text())["result"]
            else:
                jobs.append(job)
        _count(rep, "evaluate", len(jobs), len(rep.runs) - len(jobs), overlapped)
        new, failures = run_jobs(jobs, workers, progress)
        _raise_failures(failures, log)
        results.update(new)
        from sensorimotor.analysis.tables import table_from_results
        from sensorimotor.learn.evaluate import baselines
        from sensorimotor.sim.database import load_database

        base = {w: baselines(load_database(rep.data[w])) for w in WORLDS}
        ordered = [results[rep.run_name(*r)] for r in rep.runs]
        rep.table = table_from_results(ordered, base, list(WORLDS))
        _write_json(out / "table1.json", rep.table)

    # analyze ------------------------------------------------------------------------------
    with _stage(rep, "analyze", log):
        targets = [tg for world in rep.worlds for tg in _raw_targets(rep, world)]
        targets += [tg for run in rep.runs for tg in _analysis_targets(rep, *run)]
        jobs = [_analysis_job_of(tg, path_hash) for tg in targets]
        jobs = [job for job in jobs if job is not None]
        _count(rep, "analyze", len(jobs), len(targets) - len(jobs), overlapped)
        _, failures = run_jobs(jobs, workers, progress)
        _raise_failures(failures, log)
        for name, _run, _data, fit, dest in targets:
            metrics = json.loads((Path(dest) / "metrics.json").read_text())
            (rep.transfers if fit else rep.analyses)[name] = metrics

    # experiments past the paper ---------------------------------------------------------
    from sensorimotor.report import experiments as ex

    for name in rep.experiments:
        with _stage(rep, name, log):
            ctx = ex.Context(rep, name, run_jobs, workers, progress, log)
            rep.found[name] = ex.run_experiment(ctx)

    # report -------------------------------------------------------------------------------
    with _stage(rep, "report", log):
        from sensorimotor.report.document import write_report

        rep.timings["total"] = {"seconds": time.perf_counter() - t_start}
        extra = ex.sections(rep, rep.found)
        write_report(rep, argv if argv is not None else sys.argv, hardware(), extra)
    rep.timings["total"] = {"seconds": time.perf_counter() - t_start}
    _write_json(out / "timings.json", rep.timings)
    return rep
