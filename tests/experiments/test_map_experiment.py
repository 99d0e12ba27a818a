"""The map experiment of reproduce: one map per representation and seed, cached by its inputs,
aggregated over seeds with paired verdicts, and a report section read from its numbers."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import pytest

from sensorimotor import experiments as ex
from sensorimotor.analysis.map import hmm
from sensorimotor.errors import InputError
from sensorimotor.experiments import map as map_stage
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.train import train
from sensorimotor.report.blocks import to_markdown
from sensorimotor.sim.database import generate, save_database
from sensorimotor.sim.world import load_world
from sensorimotor.stats import BEFORE, CHOSEN


def test_the_verdict_needs_the_margin_and_two_standard_errors():
    verdict = map_stage.verdict
    # one seed: the margin alone
    assert verdict([1.0], [0.9], 0.05).holds is True
    assert verdict([1.0], [0.97], 0.05).holds is False
    # a large mean difference that is noisy over seeds does not hold
    noisy = verdict([1.0, 0.0, 1.0], [0.2, 0.6, 0.2], 0.05)
    assert noisy.numbers["mean"] == pytest.approx(1 / 3)
    assert noisy.numbers["se"] > noisy.numbers["mean"] / 2
    assert noisy.holds is False
    steady = verdict([0.5, 0.52, 0.49], [0.4, 0.41, 0.4], 0.05)
    assert steady.holds is True
    assert steady.numbers["sd"] == pytest.approx(0.01, abs=1e-9)  # differences 0.1, 0.11, 0.09
    assert verdict([0.5, None], [0.4, 0.4], 0.05).holds is None
    # success rates of 100 pairs: one seed is judged on its binomial error (about 0.067 here)
    rates = verdict([0.45], [0.33], 0.05, trials=[100])
    assert rates.numbers["se"] == pytest.approx((0.45 * 0.55 / 100 + 0.33 * 0.67 / 100) ** 0.5)
    assert rates.holds is False
    assert "binomial" in rates.test
    assert verdict([0.6], [0.33], 0.05, trials=[100]).holds is True
    assert verdict([0.45] * 25, [0.33] * 25, 0.05, trials=[100] * 25).holds is True


def test_a_verdict_records_its_margin_set_before_the_data_as_strict_json():
    v = map_stage.verdict([1.0], [0.9], 0.05, claim="the map predicts").to_dict()
    json.dumps(v, allow_nan=False)
    assert v["claim"] == "the map predicts"
    assert v["threshold"] == "mean paired difference above 0.05"
    want = {"mean": pytest.approx(0.1), "sd": 0.0, "se": None, "n": 1, "margin": 0.05,
            "t_interval": None}  # one seed: no interval
    assert v["numbers"] == want
    assert v["provenance"] == BEFORE
    assert "MARGINS" in v["where"]


def test_aggregate_pairs_seeds_and_orders_representations():
    def fake(markov, the_map):
        return {"bits_per_step": {"markov": markov, "map": the_map}, "states": {"active": 7}}

    per_map = [
        ("w", "rec-sm", 1, fake(1.0, 0.8)),
        ("w", "raw", 0, fake(1.2, 1.19)),
        ("w", "rec-sm", 0, fake(1.1, 0.9)),
    ]
    found = map_stage.aggregate(per_map)["w"]
    assert list(found) == ["raw", "rec-sm"]
    rec = found["rec-sm"]
    assert rec["seeds"] == [0, 1]
    assert rec["metrics"]["bits.map"]["values"] == [0.9, 0.8]
    assert rec["metrics"]["bits.map"]["mean"] == pytest.approx(0.85)
    assert rec["metrics"]["room.map"]["mean"] is None  # absent from map.json: n/a
    assert rec["claims"]["predicts"]["numbers"]["mean"] == pytest.approx(0.2)
    assert rec["claims"]["predicts"]["holds"] is True  # differences 0.2, 0.2: sd 0
    assert found["raw"]["claims"]["predicts"]["holds"] is False  # one seed, under the margin
    assert rec["claims"]["localises"]["holds"] is None
    assert rec["claims"]["predicts"]["provenance"] == BEFORE
    assert rec["claims"]["localises"]["provenance"] == CHOSEN  # its split, chosen on test first
    assert "validation" in rec["claims"]["localises"]["where"]


def test_aggregate_gives_the_maps_share_of_its_ceilings():
    def fake(broom, ceiling, plan, plan_ceiling):
        return {
            "localisation": {"balanced_room_accuracy": {"map": broom}},
            "planning": {"success": {"map": plan}},
            "ceiling": {
                "localisation": {"balanced_room_accuracy": ceiling},
                "planning": {"success": plan_ceiling},
            },
        }

    per_map = [("w", "raw", 0, fake(0.4, 0.8, 0.3, 0.6)), ("w", "raw", 1, fake(0.45, 0.9, 0.2, 0))]
    metrics = map_stage.aggregate(per_map)["w"]["raw"]["metrics"]
    assert metrics["broom.of_ceiling"]["values"] == [0.5, 0.5]
    assert metrics["plan.of_ceiling"]["values"] == [0.5, None]  # a ceiling of 0: no share
    assert metrics["plan.of_ceiling"]["mean"] is None


@pytest.fixture(scope="module")
def tiny_rep(tmp_path_factory):
    """A reproduction of one trained world: a 6,000-step Rooms1 database and one S run
    trained for one epoch on it."""
    root = tmp_path_factory.mktemp("rep")
    data = root / "data" / "rooms1.npz"
    data.parent.mkdir()
    save_database(generate(load_world("rooms1"), 6_000, seed=2), data)
    run = root / "runs" / "rooms1__s__s0"
    train(data, run, TrainConfig(model="s", seed=0, max_epochs=1, threads=1))
    return SimpleNamespace(
        out=root,
        scale=SimpleNamespace(name="tiny"),
        seeds=1,
        worlds=("rooms1",),
        data={"rooms1": data},
        runs=[("rooms1", "s", 0)],
        run_dir=lambda w, m, s: root / "runs" / f"{w}__{m}__s{s}",
    )


def test_run_maps_raw_and_each_run_caches_them_and_the_section_reads_them(
    tiny_rep, monkeypatch, one_thread
):
    monkeypatch.setattr(map_stage, "PAIRS", {"tiny": 2})
    monkeypatch.setattr(hmm, "HMM_ITERS", 2)  # the plain HMM's EM: tested in test_map_ceilings
    fitted: list[str] = []

    def counting(jobs, workers, progress):
        fitted.extend(job.name for job in jobs)
        return run_jobs(jobs, workers, progress)

    ctx = ex.Context(tiny_rep, "map", counting, 1, lambda *_: None, lambda _: None)
    found = ex.run_experiment(ctx)
    assert sorted(fitted) == ["map raw__rooms1__s0", "map rooms1__s__s0"]
    saved = json.loads((tiny_rep.out / "map" / "map.json").read_text())
    assert saved == found
    one = json.loads((tiny_rep.out / "map" / "rooms1__s__s0" / "map.json").read_text())
    models = found["worlds"]["rooms1"]
    assert list(models) == ["raw", "s"]
    assert models["s"]["metrics"]["bits.map"]["values"] == [one["bits_per_step"]["map"]]
    one_seed = models["s"]["metrics"]["bits.map"]
    assert (one_seed["sd"], one_seed["n"]) == (0.0, 1)  # one seed: sd 0 and n = 1 beside it
    assert models["s"]["metrics"]["plan.map"]["mean"] in (0.0, 0.5, 1.0)  # 2 pairs
    assert found["jobs"] == {"fitted": 2, "cached": 0}

    # a second run fits nothing
    fitted.clear()
    again = ex.run_experiment(ctx)
    assert fitted == []
    assert again["worlds"] == found["worlds"]
    assert again["jobs"] == {"fitted": 0, "cached": 2}

    blocks = ex.sections(tiny_rep, {"map": found})
    md = to_markdown(blocks, Path(tiny_rep.out))
    assert "The map on rooms1" in md
    assert "| bits/step: map |" in md
    assert "the map localises the room better than its cells" in md
    assert "map/rooms1__s__s0/place_fields.png" in md  # the trained run's figure, not raw's
    assert "n=1" in md
    assert "| bits/step: map | " in md
    assert "| balanced: MCL ceiling |" in md
    assert "| planning success: map, of the ceiling |" in md
    assert "| bits/step: GRU on (cell, action) |" in md
    assert "chosen on these data" in md  # each claim says where its settings come from
    assert " ± " not in md.split("### The map on rooms1")[1]  # one seed: no spread shown

    # a cached map.json cut short: one line naming it, not a traceback
    cut = tiny_rep.out / "map" / "rooms1__s__s0" / "map.json"
    cut.write_text(cut.read_text()[:100])
    with pytest.raises(InputError, match=r"rooms1__s__s0/map\.json: not a readable map"):
        ex.run_experiment(ctx)
