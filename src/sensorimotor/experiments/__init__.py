"""Experiments past the paper: optional stages of ``reproduce --experiment NAME[,NAME]``.

Each runs after the paper's stages and on their outputs (databases, runs, analyses), keeps its
files under ``OUT/NAME/`` cached by a hash of their inputs (a rerun redoes only what changed; a
killed run loses nothing finished), and adds its own section to the report. An experiment is a
module named in ``EXPERIMENTS`` with two functions, and a third if it needs one:

    run(ctx: Context) -> dict                  its jobs (through ctx.run_jobs); its numbers,
                                               strict JSON, which reproduce writes to
                                               OUT/NAME/NAME.json
    section(rep, found: dict) -> list[Block]   its report section, read from those numbers
    check(rep) -> None                         optional: an InputError (one line) when the
                                               reproduction cannot give it what it needs (a
                                               world not in --worlds, an extra not installed);
                                               reproduce calls it before the paper's stages,
                                               so a long run does not fail at its end

Its module must not import ``sensorimotor.reproduce`` (it is handed the ``pipeline.paper.Reproduction``):
imports point one way.
"""

from __future__ import annotations

import importlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import ModuleType

from sensorimotor.errors import InputError
from sensorimotor.files import write_json_atomic
from sensorimotor.jobs.workers import raise_first
from sensorimotor.pipeline.paper import Reproduction


@dataclass(frozen=True)
class Experiment:
    """One experiment past the paper: its name in ``--experiment``, the module that holds its
    ``run(ctx)`` and ``section(rep, found)``, and what it asks, in a line."""

    name: str
    module: str
    about: str

    def load(self) -> ModuleType:
        return importlib.import_module(self.module)


EXPERIMENTS: dict[str, Experiment] = {
    e.name: e
    for e in (
        Experiment("map", "sensorimotor.experiments.map", "a map learned from the cells"),
        Experiment(
            "gridmap",
            "sensorimotor.experiments.gridmap",
            "the map in its own regime: a lattice behaviour, rooms and plans on fresh databases",
        ),
        Experiment(
            "scaling", "sensorimotor.experiments.scaling", "more rays, noise, unseen floor plans"
        ),
        Experiment("rl", "sensorimotor.experiments.rl", "PPO agents on the Rooms1 encoders"),
        Experiment(
            "walls",
            "sensorimotor.experiments.walls",
            "Table I over wall layouts that fit the paper's sentences",
        ),
        Experiment(
            "real", "sensorimotor.experiments.real", "a real robot's laser log and a real campus"
        ),
        Experiment(
            "memory",
            "sensorimotor.experiments.memory",
            "a memory that reads the motor commands: does it know the room and the position?",
        ),
        Experiment(
            "homing",
            "sensorimotor.experiments.homing",
            "an agent that must come back to a room it cannot see: does a memory of the commands help?",
        ),
        Experiment(
            "behaviour",
            "sensorimotor.experiments.behaviour",
            "Table I's ordering, the corner cell and the memory under a smooth random motion",
        ),
    )
}
"""Every experiment by name, in the order they run."""
DEFAULT: tuple[str, ...] = ()
"""The experiments ``reproduce`` runs unless told otherwise (cheap enough for every run)."""


@dataclass(frozen=True)
class Context:
    """What an experiment's ``run`` is handed: the reproduction so far and how to run jobs."""

    rep: Reproduction  # out, scale, seeds, worlds, data, runs, analyses, ...
    name: str
    run_jobs: Callable  # workers.run_jobs's signature, on the reproduction's backend
    workers: int
    progress: Callable[[str, str], None]  # (job name, message)
    log: Callable[[str], None]

    def run(self, jobs: list) -> dict:
        """Run ``jobs`` on the reproduction's runner; their results by name. The first failure
        is raised, an InputError as its one line."""
        results, failures = self.run_jobs(jobs, self.workers, self.progress)
        raise_first(failures, f"{self.name}: ")
        return results

    @property
    def dir(self) -> Path:
        """``OUT/NAME/``: the experiment's own folder (made before ``run``)."""
        return Path(self.rep.out) / self.name


def check_experiments(names: Sequence[str] | None) -> tuple[str, ...]:
    """The experiments to run, in ``EXPERIMENTS``' order: ``DEFAULT`` for None, none for
    ``["none"]``; an unknown name is refused with the known ones."""
    if names is None:
        return DEFAULT
    names = [n for n in names if n]
    if names == ["none"]:
        return ()
    unknown = [n for n in names if n not in EXPERIMENTS]
    if unknown or not names:
        known = ", ".join([*EXPERIMENTS, "none"])
        raise InputError(
            f"--experiment: use any of {known} (comma-separated), got {','.join(names)!r}"
        )
    return tuple(n for n in EXPERIMENTS if n in names)


def module(name: str) -> ModuleType:
    return EXPERIMENTS[name].load()


def check(rep: Reproduction) -> None:
    """Each of ``rep.experiments``' preconditions, its module's ``check(rep)`` where it has
    one: called before any stage, so a missing world fails in one line at once."""
    for name in rep.experiments:
        precondition = getattr(module(name), "check", None)
        if precondition is not None:
            precondition(rep)


def run_experiment(ctx: Context) -> dict:
    """Run one experiment into ``OUT/NAME/``; its numbers, also written to ``NAME.json``."""
    try:
        ctx.dir.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise InputError(
            f"{ctx.dir}: cannot create the experiment's folder ({err.strerror})"
        ) from None
    found = module(ctx.name).run(ctx)
    write_json_atomic(ctx.dir / f"{ctx.name}.json", found)
    return found


def sections(rep, found: dict[str, dict]) -> list:
    """Every experiment's report section, in the order they ran."""
    return [
        block for name, numbers in found.items() for block in module(name).section(rep, numbers)
    ]
