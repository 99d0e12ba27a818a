"""``reproduce --experiment gridmap``: the map in its own regime, on fresh test databases, its
goals as verdicts over seeds."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from sensorimotor import experiments as ex
from sensorimotor.analysis.map import hmm
from sensorimotor.analysis.map.planning import EXPLORE
from sensorimotor.errors import InputError
from sensorimotor.experiments import gridmap
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.report.document import to_markdown
from sensorimotor.sim.database import load_database
from sensorimotor.stats import BEFORE, t_interval


def fake_map(room: float, ari: float, plan: float, top: float) -> dict:
    """The numbers of a map.json that the experiment reads."""
    return {
        "localisation": {
            "balanced_room_accuracy": {"map": room, "cells": 0.5},
            "position_error": {"map": 1.0},
        },
        "baselines": {
            "localisation": {"history_readout": 0.7},
            "bits_per_step": {"markov3": 0.8, "rnn": 0.7},
        },
        "ceiling": {"localisation": {"balanced_room_accuracy": 1.0}, "planning": {"success": top}},
        "rooms": {"adjusted_rand": ari, "adjusted_rand_cells": 0.1, "communities": {"map": 4}},
        "planning": {"success": {"map": plan, "random": 0.1}},
        "bits_per_step": {"map": 0.1},
    }


def test_the_goals_are_verdicts_on_the_mean_and_planning_is_capped_by_the_ceiling():
    maps = [("rooms2", k, fake_map(0.9, a, p, 0.9)) for k, a, p in
            ((0, 0.4, 0.70), (1, 0.5, 0.75), (2, 0.7, 0.80))]  # fmt: skip
    res = gridmap.aggregate(maps)["rooms2"]
    assert res["seeds"] == [0, 1, 2]
    ari = res["rows"]["adjusted Rand of the communities: map"]
    assert ari["mean"] == pytest.approx(1.6 / 3)
    assert ari["t_interval"] == pytest.approx(list(t_interval([0.4, 0.5, 0.7])))
    goals = res["goals"]
    assert goals["room"]["holds"] is True
    assert goals["adjusted_rand"]["holds"] is True  # 0.533 >= 0.5, though its interval is wide
    plan = goals["planning"]
    assert plan["numbers"]["goal"] == pytest.approx(0.72)  # 0.8 x 0.9 < 0.80
    assert plan["holds"] is True  # 0.75
    assert {v["provenance"] for v in goals.values()} == {BEFORE}
    low = gridmap.aggregate([("rooms1", 0, fake_map(0.7, 0.2, 0.5, 1.0))])["rooms1"]
    assert low["goals"]["planning"]["numbers"]["goal"] == 0.80
    assert [v["holds"] for v in low["goals"].values()] == [False, False, False]
    assert low["rows"]["planning success: map"]["t_interval"] is None  # one seed: no interval


def test_seeds_of_the_training_and_the_fresh_databases_never_meet_validations():
    train = [gridmap.train_seed(k) for k in range(10)]
    fresh = [gridmap.fresh_seed(k) for k in range(10)]
    assert len(set(train + fresh)) == 20
    assert 1 not in train + fresh  # seed 1: the databases the resolution was chosen on


def test_a_reproduction_without_rooms_is_refused():
    with pytest.raises(InputError, match="rooms1 or rooms2"):
        gridmap.check(SimpleNamespace(worlds=("square",)))
    gridmap.check(SimpleNamespace(worlds=("square", "rooms2")))


def test_run_maps_on_fresh_databases_caches_and_the_section_reads_it(
    tmp_path, monkeypatch, one_thread
):
    monkeypatch.setitem(gridmap.SIZES, "smoke", gridmap.Size(3_000, 5, {"rooms1": 2}, 1))
    monkeypatch.setattr(hmm, "HMM_ITERS", 2)  # the plain HMM's EM: tested in test_map_ceilings
    rep = SimpleNamespace(out=tmp_path, scale=SimpleNamespace(name="smoke"), seeds=1,
                          worlds=("rooms1", "square"))  # fmt: skip
    ran: list[str] = []

    def counting(jobs, workers, progress):
        ran.extend(job.name for job in jobs)
        return run_jobs(jobs, workers, progress)

    ctx = ex.Context(rep, "gridmap", counting, 1, lambda *_: None, lambda _: None)
    found = ex.run_experiment(ctx)
    assert ran == ["data rooms1_grid_s0", "data rooms1_grid_s2", "gridmap rooms1__s0"]
    one = json.loads((tmp_path / "gridmap" / "rooms1__s0" / "map.json").read_text())
    fresh = load_database(one["test_data"])
    assert (fresh.meta["seed"], fresh.behaviour, len(fresh.layout.angles)) == (2, "grid", 16)
    assert load_database(one["data"]).meta["seed"] == 0
    assert one["steps"]["test"] == len(fresh.take("test"))
    assert one["settings"]["start"] == "fine"
    assert one["settings"]["pseudocount"] == gridmap.PSEUDOCOUNT
    assert one["planning"]["explore"] == EXPLORE > 0  # a lattice behaviour's planner explores
    rows = found["worlds"]["rooms1"]["rows"]
    assert rows["planning success: map"]["values"] == [one["planning"]["success"]["map"]]
    assert list(found["worlds"]) == ["rooms1"]  # Square has no rooms to score

    ran.clear()
    again = ex.run_experiment(ctx)
    assert ran == []
    assert again["worlds"] == found["worlds"]
    assert again["jobs"] == {"fitted": 0, "cached": 1}

    md = to_markdown(ex.sections(rep, {"gridmap": found}), Path(tmp_path))
    assert "The map in its own regime" in md
    assert "| it plans to the goal |" in md
    assert "set before the data" in md
    assert "gridmap/rooms1__s0/map_graph.png" in md
