"""``reproduce --experiment behaviour``: the smooth behaviour's Square trained, tested and
analysed beside the reproduction's own Square runs, the scaling experiment's verdicts, a section."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

from sensorimotor.errors import InputError
from sensorimotor.experiments import behaviour as bh
from sensorimotor.experiments import scaling as sc
from sensorimotor.learn.models import paper_kinds
from sensorimotor.pipeline.paper import SCALES
from sensorimotor.reproduce import reproduce
from sensorimotor.sim.database import load_database
from sensorimotor.stats import BEFORE


def _condition(cond, errors: dict, corner: dict, nothing: float, behind: dict) -> dict:
    """A condition's numbers (``scaling.condition_numbers``) from hand-made ones."""
    evals = [{"model": k, "errors": {"square": v}} for k, v in errors.items()]
    numbers = {
        k: {
            "corner_f1": [corner[k]],
            "corner_auc": [None],
            "nothing_clusters": [nothing if k == "rec-sm" else 1.0],
            "behind_r2": [behind.get(k, 0.0)],
        }
        for k in ("raw", *paper_kinds())
    }
    base = [{"copy_last": 0.07, "mean": 0.3}]
    return sc.condition_numbers(cond, evals, ["square"], [], base, numbers)


def test_the_section_says_where_the_verdicts_differ_and_what_the_scale_cannot_say(tmp_path):
    errors = {"s": 0.04, "sm": 0.006, "rec-s": 0.035, "rec-sm": 0.002}
    corner = {"raw": 0.3, "s": 0.3, "sm": 0.41, "rec-s": 0.3, "rec-sm": 0.5}
    paper = _condition(bh.PAPER, errors, corner, 3.0, {"s": 0.1, "rec-sm": 0.3})
    smooth = _condition(bh.SMOOTH, {**errors, "sm": 0.05}, corner, 3.0, {"s": 0.1, "rec-sm": 0.3})
    assert [v["holds"] for v in paper["verdicts"]] == [True, True, True]
    assert [v["holds"] for v in smooth["verdicts"]] == [False, True, True]
    moves = {"paper": {"reflex_share": 0.01, "turn_lag1_autocorrelation": 0.0, "turn_sd": 0.3,
                       "speed_mean": 0.5, "speed_min": 0.0, "speed_max": 1.0}}  # fmt: skip
    moves["smooth"] = {**moves["paper"], "turn_lag1_autocorrelation": None}
    found = {
        "size": {"steps": 3_000, "seeds": 1, "patience": 1, "max_epochs": {}},
        "motion": moves,
        "conditions": {"paper": paper, "smooth": smooth},
    }
    rep = SimpleNamespace(out=tmp_path, scale=SCALES["quick"])
    text = [str(b.content) for b in bh.section(rep, found)]
    assert any("differ between the behaviours for: ordering (holds under the paper's, fails "
               "under the smooth one)" in t for t in text)  # fmt: skip
    assert any("At `--scale quick` the corner cluster is not expected" in t for t in text)
    assert any("n/a" in t for t in text)  # a missing motion number
    same = bh.section(
        SimpleNamespace(out=tmp_path, scale=SCALES["paper"]),
        {**found, "conditions": {"paper": paper, "smooth": paper}},
    )
    last = str(same[-1].content)
    assert last == "Every finding has the same verdict under both behaviours."


def test_the_experiment_needs_square(tmp_path):
    with pytest.raises(InputError, match=r"experiment behaviour: .* add square to --worlds"):
        reproduce(tmp_path / "out", scale="smoke", worlds=["rooms1"], experiments=["behaviour"])
    assert not (tmp_path / "out").exists()


@pytest.mark.slow  # the paper's stages on Square and eight trainings at the smoke scale
def test_the_experiment_runs_beside_the_reproduction_and_keeps_its_work(tmp_path):
    out = tmp_path / "out"
    rep = reproduce(out, scale="smoke", worlds=["square"], experiments=["behaviour"], log=str)
    found = rep.found["behaviour"]
    json.dumps(found, allow_nan=False)  # strict JSON
    assert json.loads((out / "behaviour" / "behaviour.json").read_text()) == found
    assert found["size"]["max_epochs"]["rec-sm"] == 2  # the smoke scale's cap
    conds = found["conditions"]
    assert list(conds) == ["paper", "smooth"]
    paper_sm = rep.table["tables"]["square"][1]["cells"]["square"]["mean"]
    assert conds["paper"]["errors"]["sm"]["mean"] == paper_sm  # the reproduction's own run
    for c in conds.values():
        assert [v["claim"] for v in c["verdicts"]] == ["ordering", "corner cluster", "memory"]
        assert {v["provenance"] for v in c["verdicts"]} == {BEFORE}
        assert all("experiments/behaviour.py" in v["where"] for v in c["verdicts"])
    assert found["motion"]["smooth"]["turn_lag1_autocorrelation"] > 0.7
    assert abs(found["motion"]["paper"]["turn_lag1_autocorrelation"]) < 0.1
    assert load_database(out / "behaviour" / "data" / "smooth.npz").behaviour == "smooth"
    assert (out / "behaviour" / "trajectories.png").stat().st_size > 10_000
    md = (out / "report.md").read_text()
    assert "## A second behaviour: the paper's findings under a smooth random motion" in md
    assert "(behaviour/trajectories.png)" in md
    again = reproduce(out, scale="smoke", worlds=["square"], experiments=["behaviour"], log=str)
    assert again.found["behaviour"]["jobs"] == {"data": 0, "train": 0, "evaluate": 0, "analyze": 0}
