"""``sensorimotor reproduce``: the whole paper, and the full 3 x 3 table, from one command.

The front door of the house: the paper's stages (``pipeline.paper``: data, train, evaluate,
analyse), then the experiments past the paper that were asked for (``experiments``: each in
``OUT/NAME/``), then the report (``report``: ``OUT/report.md``, ``OUT/report.html``), every job
on the chosen backend (``jobs``). Every stage is cached under ``OUT``: a rerun does only what
is missing, and a killed run resumes, losing nothing finished.
"""

from __future__ import annotations

import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

from sensorimotor import experiments as ex
from sensorimotor.errors import InputError
from sensorimotor.files import write_json_atomic
from sensorimotor.jobs.backend import GPU_SHARE, job_runner
from sensorimotor.jobs.workers import hardware
from sensorimotor.pipeline.paper import SCALES, Reproduction, check_worlds, run_paper, stage

FOLDERS = ("data", "runs", "eval", "analysis", "transfer", "figures")


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
    rep = _plan(out, scale, seeds, device, worlds, experiments)
    gpus = GPU_SHARE if backend == "ray" and rep.device == "cuda" else 0.0
    with job_runner(backend, address, workers, gpus) as (runner, workers):
        rep.workers = workers
        return _reproduce(rep, log, argv, runner)


def _plan(out, scale, seeds, device, worlds, experiments) -> Reproduction:
    """The reproduction asked for, every option and each experiment's preconditions
    (``experiments.check``) checked before a job runs or a folder is made: InputError, one
    line. Its ``workers`` is set by the runner."""
    from sensorimotor.learn.train import resolve_device

    chosen = ex.check_experiments(experiments)
    if scale not in SCALES:
        raise InputError(f"unknown scale {scale!r}: use one of {', '.join(SCALES)}")
    sc = SCALES[scale]
    seeds = sc.seeds if seeds is None else seeds
    if seeds < 1:
        raise InputError(f"--seeds must be at least 1, got {seeds}")
    trained = check_worlds(worlds)
    device = resolve_device(device)
    out = Path(out)
    if out.exists() and not out.is_dir():
        raise InputError(f"{out}: is a file, not an output folder")
    rep = Reproduction(out, sc, seeds, device, 0, trained, experiments=chosen)
    ex.check(rep)
    return rep


def _reproduce(rep: Reproduction, log, argv, run_jobs) -> Reproduction:
    """``reproduce`` of the planned ``rep`` with its jobs run by ``run_jobs``
    (``jobs.workers.run_jobs``'s signature)."""
    from sensorimotor.report.document import write_report

    out, workers = rep.out, rep.workers
    try:
        for sub in FOLDERS:
            (out / sub).mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(f"{out}: cannot create the output folder ({err.strerror})") from None
    t_start = time.perf_counter()

    def progress(name: str, message: str) -> None:
        log(f"  {name}: {message}")

    run_paper(rep, run_jobs, log)
    for name in rep.experiments:
        with stage(rep, name, log):
            ctx = ex.Context(rep, name, run_jobs, workers, progress, log)
            rep.found[name] = ex.run_experiment(ctx)
    with stage(rep, "report", log):
        rep.timings["total"] = {"seconds": time.perf_counter() - t_start}
        extra = ex.sections(rep, rep.found)
        write_report(rep, argv if argv is not None else sys.argv, hardware(), extra)
    rep.timings["total"] = {"seconds": time.perf_counter() - t_start}
    write_json_atomic(out / "timings.json", rep.timings)
    return rep
