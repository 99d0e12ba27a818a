"""Table I: test errors of several runs gathered by training world, model and test world."""

from __future__ import annotations

from sensorimotor.errors import InputError
from sensorimotor.learn.evaluate import Run, baselines, evaluate_run
from sensorimotor.learn.models import KINDS, REC_S, REC_SM, SM, S
from sensorimotor.learn.runs import setting_changes
from sensorimotor.sim.database import Database
from sensorimotor.stats import mean_sd

# The paper's Table I: models trained on Square, tested on each world (sum over sensors).
PAPER_TABLE_I = {
    S: {"square": 0.03735, "rooms1": 0.04299, "rooms2": 0.07290},
    SM: {"square": 0.005576, "rooms1": 0.01453, "rooms2": 0.02572},
    REC_S: {"square": 0.03587, "rooms1": 0.04068, "rooms2": 0.06971},
    REC_SM: {"square": 0.002404, "rooms1": 0.01054, "rooms2": 0.01809},
}


def fmt_cell(cell: dict | None, digits: int = 5) -> str:
    """A Table I cell: the mean, with the sample sd when there are several seeds."""
    if cell is None:
        return ""
    if cell["n"] > 1:
        return f"{cell['mean']:.{digits}f} ± {cell['sd']:.{digits}f}"
    return f"{cell['mean']:.{digits}f}"


def paper_ordering_holds(cells: dict[str, float]) -> bool | None:
    """The paper's claim in one column: Rec-SM < SM < both Rec-S and S (None if a cell is missing)."""
    if any(k not in cells for k in (S, SM, REC_S, REC_SM)):
        return None
    return cells[REC_SM] < cells[SM] < min(cells[REC_S], cells[S])


# settings that do not make another experiment: the seed makes a row's spread, the others
# change the speed only
NOT_AN_EXPERIMENT = ("seed", "device", "threads")


def _experiment(run: Run) -> dict:
    """A run's data (its hash), model and training settings but those in
    ``NOT_AN_EXPERIMENT``: the seeds of one row of Table I must agree on them."""
    train = run.config.get("train", {})
    return {
        "data sha256": run.config.get("data", {}).get("sha256"),
        **run.config.get("model", {}),
        **{k: v for k, v in train.items() if k not in NOT_AN_EXPERIMENT},
    }


def build_table(runs: list[Run], dbs: list[Database], split: str = "test") -> dict:
    """Evaluate every run on every database: JSON-ready tables, one per training world.
    InputError if two runs are one seed of one model and world (a seed counted twice), or
    seeds of one row were trained with other settings (two experiments in one mean)."""
    seen: dict[tuple, Run] = {}
    row_of: dict[tuple, Run] = {}  # (world, model) -> its first run
    for run in runs:
        key = (run.trained_on, run.kind, run.config.get("train", {}).get("seed"))
        if key in seen:
            raise InputError(
                f"{run.path}: the same world, model and seed as {seen[key].path} (a seed "
                "counted twice would shrink the spread)"
            )
        seen[key] = run
        first = row_of.setdefault(key[:2], run)
        changed = setting_changes(_experiment(first), _experiment(run))
        if changed:
            raise InputError(
                f"{run.path}: trained with other settings than {first.path} ({changed}); one "
                "row's mean and sd are over seeds of one experiment"
            )
    per_run = [evaluate_run(run, dbs, split) for run in runs]
    base = {db.meta["world"]["name"]: baselines(db, split) for db in dbs}
    return table_from_results(per_run, base, [db.meta["world"]["name"] for db in dbs])


def table_from_results(per_run: list[dict], base: dict, worlds: list[str]) -> dict:
    """Gather ``evaluate_run`` results into Table I: one table per training world, one row per
    model, one cell per test world with mean and sample sd over seeds."""
    tables: dict[str, list[dict]] = {}
    ordering: dict[str, dict[str, bool | None]] = {}
    for trained_on in dict.fromkeys(r["trained_on"] for r in per_run):
        rows = []
        for kind in KINDS:
            mine = [r for r in per_run if r["trained_on"] == trained_on and r["model"] == kind]
            if not mine:
                continue
            cells = {}
            for w in worlds:
                values = [r["errors"][w] for r in mine]
                mean, sd = mean_sd(values)
                cells[w] = {
                    "mean": mean,
                    "sd": sd,
                    "n": len(values),
                    "values": values,
                    "seeds": [r["seed"] for r in mine],
                }
            rows.append({"model": kind, "name": KINDS[kind].label, "cells": cells})
        tables[trained_on] = rows
        ordering[trained_on] = {
            w: paper_ordering_holds({row["model"]: row["cells"][w]["mean"] for row in rows})
            for w in worlds
        }
    return {
        "worlds": worlds,
        "tables": tables,
        "baselines": base,
        "paper_ordering_holds": ordering,
        "paper": PAPER_TABLE_I,
        "runs": per_run,
    }
