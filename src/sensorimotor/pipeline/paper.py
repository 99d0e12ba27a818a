"""The paper's stages, from databases to analyses, cached under ``OUT``:

    data      OUT/data/{world}.npz                     one database per world
    train     OUT/runs/{world}__{model}__s{seed}/      every model kind on every world, K seeds
    evaluate  OUT/eval/{run}.json                      each run on the three test splits
    analyze   OUT/analysis/{run}/, OUT/analysis/raw__{world}/, OUT/transfer/{run}__to__{world}/

Each output is kept beside a hash of what it depends on (a rerun does only what is missing; a
killed run resumes, losing nothing finished). ``run_paper`` runs them on a job runner and fills
a ``Reproduction``; ``sensorimotor.reproduce`` adds the experiments and the report.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from sensorimotor.errors import InputError
from sensorimotor.files import file_hash, read_json, write_json_atomic
from sensorimotor.jobs.cache import read_key, stage_key
from sensorimotor.jobs.workers import Job, raise_first
from sensorimotor.learn.models import KINDS, REC_SM, paper_kinds
from sensorimotor.learn.runs import count, run_name
from sensorimotor.pipeline.stages import (
    analysis_job,
    data_job,
    data_key,
    eval_job,
    run_matches,
    stack_name,
    train_config,
    train_job,
)
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
    """Cap on epochs per model kind (missing: ``epoch_cap``; None: early stopping alone)."""
    patience: int = 10
    """Early-stopping patience in epochs (the paper: 10 epochs of 800,000 steps)."""
    caveat: str = ""
    """What the report of this scale can and cannot say, at its top."""
    epoch_cap: int | None = None
    """Cap on epochs of a kind missing from ``max_epochs``."""
    beyond: tuple[str, ...] = ()
    """The paper's claims (the start of their wording) this scale is too small to support,
    measured: where one is not supported, the report says it needs ``--scale paper``."""

    def epochs(self, model: str) -> int | None:
        """The epoch cap of ``model`` at this scale (None: early stopping alone)."""
        return self.max_epochs.get(model, self.epoch_cap)


SCALES = {
    "smoke": Scale(
        "smoke",
        20_000,
        1,
        epoch_cap=2,
        caveat="A smoke test of the pipeline: every model is trained for 2 epochs on 20,000 "
        "steps, so its numbers and verdicts say nothing about the paper. `--scale paper` runs "
        "the paper's protocol.",
    ),
    # 5 times smaller epochs: a 5 times longer patience sees as many samples as the paper's 10
    "quick": Scale(
        "quick",
        200_000,
        1,
        {k: kind.quick_epochs for k, kind in KINDS.items()},
        50,
        caveat="A quick run: 200,000-step databases, capped epochs and one seed, so its numbers "
        "are indicative only and its verdicts carry no spread over seeds. `--scale paper` runs "
        "the paper's protocol.",
        # measured (docs/DESIGN.md, "The quick scale"): Rec-SM's corner F1 stays at the raw
        # readings' (0.16 at 80 epochs, 0.18 at 160), so no corner cluster grows and the
        # transfer claims are not judged; the wall-end cluster needs Rooms1's wall ends seen
        # often enough
        beyond=(
            "Motors grow a corner cluster",
            "No corner cluster without motors",
            "A wall-end cluster grows",
            "Transfer:",
        ),
    ),
    "paper": Scale("paper", 1_000_000, 5, {}),
}


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
        return run_name(world, model, seed)

    def run_dir(self, world: str, model: str, seed: int) -> Path:
        return self.out / "runs" / self.run_name(world, model, seed)


PAPER_STAGES = ("data", "train", "evaluate", "analyze")


def stages_of(rep: Reproduction) -> tuple[str, ...]:
    """Every stage ``reproduce`` runs, in order: the paper's, the experiments, the report."""
    return (*PAPER_STAGES, *rep.experiments, "report")


@contextmanager
def stage(rep: Reproduction, name: str, log: Callable[[str], None]):
    """Time one stage into ``rep.timings``; its line says which of all the stages it is."""
    names = stages_of(rep)
    where = f" ({names.index(name) + 1} of {len(names)})" if name in names else ""
    log(f"[bold]stage {name}{where}[/bold]")
    t0 = time.perf_counter()
    yield
    rep.timings[name] = {**rep.timings.get(name, {}), "seconds": time.perf_counter() - t0}


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
    return Job(run.name, eval_job, (str(run), data_list, str(path), key))


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
    if model == REC_SM and seed == 0 and world in TRANSFER_FROM:
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
    return Job(name, analysis_job, (run, data, dest, fit, key))


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
        for model in paper_kinds():
            for seed in range(rep.seeds):
                rep.runs.append((world, model, seed))
                run = rep.run_dir(world, model, seed)
                done = (run / "result.json").exists()
                config = _train_config(rep.scale, model, rep.device, seed)
                if done and run_matches(run, data_hash[world], config):
                    continue
                if not trains_stacked(model, rep.device):
                    key = (model, world, seed)
                elif KINDS[model].recurrent:
                    key = (model, world)
                else:
                    key = (model,)
                entry = (str(rep.data[world]), seed, str(run), data_hash[world])
                groups.setdefault(key, []).append((world, model, seed, entry))
    jobs, trains = [], {}
    for (model, *_), runs in groups.items():
        name = stack_name(model, [(world, seed) for world, _, seed, _ in runs])
        config = _train_config(rep.scale, model, rep.device)
        jobs.append(Job(name, train_job, ([entry for *_, entry in runs], config)))
        trains[name] = [(world, model, seed) for world, model, seed, _ in runs]
    return jobs, trains, sum(len(runs) for runs in groups.values())


def _train_config(sc: Scale, model: str, device: str, seed: int | None = None) -> dict:
    """The training configuration of one run at scale ``sc`` (of a stack's, without ``seed``)."""
    return train_config(model, device, sc.epochs(model), sc.patience, seed)


class _Tally:
    """Counts a stage's finished jobs into the log: "done 3 of 12: square__sm__s0"; ``total``
    grows when a finished job queues others."""

    def __init__(self, log: Callable[[str], None], total: int) -> None:
        self.log, self.total, self.done = log, total, 0

    def __call__(self, name: str, _result) -> None:
        self.done += 1
        self.log(f"  done {self.done} of {self.total}: {name}")


def run_paper(rep: Reproduction, run_jobs: Callable, log: Callable[[str], None]) -> None:
    """Run (or resume) the paper's stages into ``rep.out``; what they find goes into ``rep``.
    ``run_jobs``: ``jobs.workers.run_jobs``'s signature, on the chosen backend."""
    out, sc, device, workers = rep.out, rep.scale, rep.device, rep.workers

    def progress(name: str, message: str) -> None:
        log(f"  {name}: {message}")

    # data ---------------------------------------------------------------------------------
    with stage(rep, "data", log):
        jobs = []
        for world in WORLDS:
            path = out / "data" / f"{world}.npz"
            key = data_key(world, sc.steps)
            rep.data[world] = path
            if path.exists() and read_key(path.with_suffix(".json")) == key:
                continue
            jobs.append(Job(f"data {world}", data_job, (world, sc.steps, 0, str(path), key)))
        rep.timings["data"] = {"jobs": len(jobs), "cached": len(WORLDS) - len(jobs)}
        _, failures = run_jobs(jobs, workers, progress, _Tally(log, len(jobs)))
        raise_first(failures, "run ", log)
    data_hash = {w: file_hash(p) for w, p in rep.data.items()}
    path_hash = {str(rep.data[w]): h for w, h in data_hash.items()}

    # train --------------------------------------------------------------------------------
    with stage(rep, "train", log):
        from sensorimotor.learn.engine import computes_models_py
        from sensorimotor.learn.train import trains_stacked

        jobs, trains, n_train = _training_jobs(rep, data_hash)
        # longest first, so that the workers finish closer together
        jobs.sort(key=lambda job: -sum(KINDS[model].cost for _, model, _ in trains[job.name]))
        n_jobs = len(jobs)
        rep.timings["train"] = {"jobs": n_train, "cached": len(rep.runs) - n_train}
        stacked = ""
        if len(jobs) < n_train:  # some job trains a stack; asked only then (it loads numba)
            stacked = (
                " (seeds stacked)"
                if trains_stacked(REC_SM, device)
                else " (S and SM seeds stacked)"
            )
        log(
            f"  {count(n_train, 'training')} to run in {count(len(jobs), 'job')}{stacked}"
            + f", {len(rep.runs) - n_train} cached, {count(workers, 'worker')}"
        )
        to_train = {model for runs in trains.values() for _, model, _ in runs}
        for model in KINDS:
            if model in to_train and not computes_models_py(model):
                log(
                    f"  [yellow]models.py's {model} is not what the stacked passes compute: it trains "
                    "with autograd (slower)"
                )
        overlapped = {"evaluate": 0, "analyze": 0}
        tally = _Tally(log, 0)

        def then(name: str, _result) -> list[Job]:
            """Evaluate and analyse each run a training job finished, while others train."""
            more = []
            for world, model, seed in trains.pop(name, []):  # [] for a follow-up job
                more.append(_eval_job_of(rep, world, model, seed, data_hash))
                targets = _analysis_targets(rep, world, model, seed)
                more += [_analysis_job_of(tg, path_hash) for tg in targets]
            more = [job for job in more if job is not None]
            overlapped["evaluate"] += sum(job.fn is eval_job for job in more)
            overlapped["analyze"] += sum(job.fn is analysis_job for job in more)
            tally.total += len(more)
            return more

        raw = [_analysis_job_of(tg, path_hash) for w in rep.worlds for tg in _raw_targets(rep, w)]
        jobs += [job for job in raw if job is not None]  # cheap: they fill the end
        overlapped["analyze"] += len(jobs) - n_jobs
        tally.total = len(jobs)
        _, failures = run_jobs(jobs, workers, progress, tally, then=then)
        raise_first(failures, "run ", log)

    # evaluate -----------------------------------------------------------------------------
    with stage(rep, "evaluate", log):
        jobs, results = [], {}
        for world, model, seed in rep.runs:
            name = rep.run_name(world, model, seed)
            job = _eval_job_of(rep, world, model, seed, data_hash)
            if job is None:
                results[name] = read_json(_eval_path(rep, name), "evaluation")["result"]
            else:
                jobs.append(job)
        _count(rep, "evaluate", len(jobs), len(rep.runs) - len(jobs), overlapped)
        new, failures = run_jobs(jobs, workers, progress, _Tally(log, len(jobs)))
        raise_first(failures, "run ", log)
        results.update(new)
        from sensorimotor.analysis.tables import table_from_results
        from sensorimotor.learn.evaluate import baselines
        from sensorimotor.sim.database import load_database

        base = {w: baselines(load_database(rep.data[w])) for w in WORLDS}
        ordered = [results[rep.run_name(*r)] for r in rep.runs]
        rep.table = table_from_results(ordered, base, list(WORLDS))
        write_json_atomic(out / "table1.json", rep.table)

    # analyze ------------------------------------------------------------------------------
    with stage(rep, "analyze", log):
        targets = [tg for world in rep.worlds for tg in _raw_targets(rep, world)]
        targets += [tg for run in rep.runs for tg in _analysis_targets(rep, *run)]
        jobs = [_analysis_job_of(tg, path_hash) for tg in targets]
        jobs = [job for job in jobs if job is not None]
        _count(rep, "analyze", len(jobs), len(targets) - len(jobs), overlapped)
        _, failures = run_jobs(jobs, workers, progress, _Tally(log, len(jobs)))
        raise_first(failures, "run ", log)
        for name, _run, _data, fit, dest in targets:
            metrics = read_json(Path(dest) / "metrics.json", "analysis metrics")
            (rep.transfers if fit else rep.analyses)[name] = metrics
