"""The scaling experiment: one condition's stages on tiny databases (and nothing trained again
on a second run), the plans' merged database, and the verdicts on hand-made numbers."""

from __future__ import annotations

import json
import shutil
from types import SimpleNamespace

import numpy as np
import pytest

from sensorimotor import experiments as ex
from sensorimotor.experiments import scaling as sc
from sensorimotor.experiments.scaling_report import section, verdicts
from sensorimotor.files import file_hash
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.stats import BEFORE


def _ctx(out):
    (out / "scaling").mkdir(parents=True, exist_ok=True)
    return ex.Context(SimpleNamespace(out=out), "scaling", run_jobs, 1, lambda *_: None, print)


def test_one_condition_runs_its_stages_and_a_second_run_trains_nothing(tmp_path):
    ctx = _ctx(tmp_path)
    size = sc.Size(3_000, 1, {k: 1 for k in ("s", "sm", "rec-s", "rec-sm")}, 1)
    cond = sc.Condition("tiny", "3 rays", rays=3)
    first = sc.run_conditions(ctx, size, [cond])
    assert first["jobs"] == {"data": 1, "train": 4, "evaluate": 4, "analyze": 5}
    c = first["conditions"]["tiny"]
    assert load_database(tmp_path / "scaling" / "data" / "tiny.npz").sensors.shape[1] == 3
    assert set(c["errors"]) == {"s", "sm", "rec-s", "rec-sm"}
    assert all(e["n"] == 1 and e["mean"] > 0 for e in c["errors"].values())
    assert [v["claim"] for v in c["verdicts"]] == ["ordering", "corner cluster", "memory"]
    assert {v["provenance"] for v in c["verdicts"]} == {BEFORE}
    json.dumps(first, allow_nan=False)  # strict JSON
    # the corner probe beside the cluster F1, in every representation, fitted on the train split
    assert all("corner_auc" in c["claims"][k] for k in ("raw", "s", "sm", "rec-s", "rec-sm"))
    metrics = json.loads(
        (tmp_path / "scaling" / "analysis" / "raw__tiny__on__tiny" / "metrics.json").read_text()
    )
    assert metrics["analysis"]["events"]["corner"]["probe_fit"] == "train split"
    assert c["claims"]["raw"]["corner_auc"] == metrics["analysis"]["events"]["corner"]["probe_auc"]
    again = sc.run_conditions(ctx, size, [cond])
    assert again["jobs"] == {"data": 0, "train": 0, "evaluate": 0, "analyze": 0}
    assert again["conditions"] == first["conditions"]
    # other training settings would retrain (the runs' inputs changed)
    plans, data_jobs, merges = sc._data_stage(ctx, size, [cond])
    hashes = {p: file_hash(p) for p in (plans[0].train_data,)}
    assert not data_jobs + merges
    assert len(sc._train_jobs(ctx, sc.Size(3_000, 1, {}, 1), plans, "cpu", hashes)) == 4
    assert not sc._train_jobs(ctx, size, plans, "cpu", hashes)
    text = [
        b.content
        for b in section(
            SimpleNamespace(out=tmp_path),
            {**first, "size": {"steps": 3_000, "seeds": 1, "patience": 1, "max_epochs": {}}},
        )
    ]
    assert "tiny: 3 rays" in text
    assert any("Thresholds set before the data: analysis/claims.py" in str(t) for t in text)


def test_merged_plans_have_each_split_the_union_of_the_plans(tmp_path):
    parts = []
    for k in range(2):
        world = sc.plan_world(k, f"p{k}")
        parts.append(save_database(generate(world, 100, k), tmp_path / f"p{k}.npz"))
    merged = load_database(sc.merge_plans([str(p) for p in parts], tmp_path / "m.npz", "m"))
    dbs = [load_database(p) for p in parts]
    assert len(merged) == 200
    assert not merged.has_walls
    for split in ("train", "val", "test"):
        want = np.concatenate([db.take(split).sensors for db in dbs])
        np.testing.assert_array_equal(merged.take(split).sensors, want)
    assert "p0, p1" in merged.meta["source"]


def test_the_plans_data_stage_is_kept_when_the_output_folder_moves(tmp_path):
    cond = sc.Condition("pl", "two plans", plans=1)
    size = sc.Size(1_000, 1)
    ctx = _ctx(tmp_path / "a")
    plans, jobs, merges = sc._data_stage(ctx, size, [cond])
    assert [len(jobs), len(merges)] == [2, 1]
    run_jobs(jobs + merges, 1)
    assert len(load_database(plans[0].train_data)) == 100
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    _, jobs, merges = sc._data_stage(_ctx(tmp_path / "b"), size, [cond])
    assert not jobs + merges


def _claims(corner: dict, nothing: float, behind: dict) -> dict:
    return {
        k: {
            "corner_f1": corner[k],
            "nothing_clusters": nothing if k == "rec-sm" else 1.0,
            "behind_r2": behind.get(k, 0.0),
        }
        for k in ("raw", "s", "sm", "rec-s", "rec-sm")
    }


def test_verdicts_hold_fail_and_say_na_by_their_thresholds():
    errors = {"s": 0.04, "sm": 0.006, "rec-s": 0.035, "rec-sm": 0.002}
    corner = {"raw": 0.3, "s": 0.3, "sm": 0.41, "rec-s": 0.3, "rec-sm": 0.5}
    good = verdicts(errors, _claims(corner, 3.0, {"s": 0.1, "rec-sm": 0.21}))
    assert [v.holds for v in good] == [True, True, True]
    # SM not below Rec-S; SM's corner F1 only 0.09 above; Rec-SM's R² only 0.09 above S's
    bad = verdicts(
        {**errors, "sm": 0.036},
        _claims({**corner, "sm": 0.39}, 3.0, {"s": 0.1, "rec-sm": 0.19}),
    )
    assert [v.holds for v in bad] == [False, False, False]
    one_cluster = verdicts(errors, _claims(corner, 1.0, {"s": 0.1, "rec-sm": 0.5}))
    assert one_cluster[2].holds is False
    missing = verdicts({**errors, "s": float("nan")}, _claims({**corner, "raw": None}, 3.0, {}))
    assert [v.holds for v in missing[:2]] == [None, None]
    assert [v.word("holds", "fails") for v in (good[0], bad[0], missing[0])] == [
        "holds",
        "fails",
        "n/a",
    ]


@pytest.mark.parametrize("name", ["scaling"])
def test_scaling_is_registered_but_not_run_by_default(name):
    assert ex.EXPERIMENTS[name].module == "sensorimotor.experiments.scaling"
    assert name not in ex.DEFAULT
    assert ex.module(name).run is sc.run
    assert ex.module(name).section is section
