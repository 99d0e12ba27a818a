"""The front door: a model kind registered in one place is trained, tabulated, analysed and
reported by ``reproduce`` with nothing else edited; an experiment whose preconditions fail
stops it in one line before any stage."""

from __future__ import annotations

import json

import pytest

from conftest import assert_one_line_error, run_cli
from sensorimotor.errors import InputError
from sensorimotor.learn import models
from sensorimotor.reproduce import reproduce


@pytest.mark.slow  # the whole pipeline at the smoke scale, in this process
def test_a_kind_registered_in_one_place_goes_through_the_whole_pipeline(tmp_path, monkeypatch):
    toy = models.Kind("toy", "Toy-encoder", "Toy", recurrent=False, motors=True, cost=1.0)
    monkeypatch.setitem(models.KINDS, toy.name, toy)  # the one place
    out = tmp_path / "out"
    reproduce(out, scale="smoke", worlds=["square"], workers=1, log=lambda line: None)

    assert (out / "runs" / "square__toy__s0" / "model.pt").is_file()  # trained
    table = json.loads((out / "table1.json").read_text())
    rows = {row["model"]: row for row in table["tables"]["square"]}
    assert list(rows) == models.paper_kinds()  # tabulated, in the registry's order
    assert rows["toy"]["name"] == "Toy-encoder"
    assert all(cell["n"] == 1 for cell in rows["toy"]["cells"].values())
    metrics = json.loads((out / "analysis" / "square__toy__s0" / "metrics.json").read_text())
    assert len(metrics["analysis"]["clusters"]) == 20  # analysed: the paper's 20 clusters
    report = (out / "report.md").read_text()
    assert "Toy-encoder" in report  # reported


def test_a_taken_name_cannot_be_registered_twice():
    with pytest.raises(ValueError, match="already taken"):
        models.register(models.Kind("sm", "x", "x", False, True))
    with pytest.raises(ValueError, match="already taken"):
        models.register(models.Kind("raw", "x", "x", False, False))


def test_an_experiment_missing_its_world_fails_in_one_line_before_any_stage(tmp_path):
    out = tmp_path / "out"
    args = ["reproduce", "--scale", "smoke", "--worlds", "rooms1", "--experiment", "real"]
    proc = run_cli(*args, "--out", out)
    assert_one_line_error(proc, "experiment real", "add square to --worlds")
    assert "stage" not in proc.stdout + proc.stderr  # no stage started
    assert not out.exists()  # nothing generated, trained or written
    with pytest.raises(InputError, match=r"experiment walls: .* add square to --worlds"):
        reproduce(out, scale="smoke", worlds=["rooms2"], experiments=["walls", "real"])
    assert not out.exists()
