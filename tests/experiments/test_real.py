"""``reproduce --experiment real``: the shipped real recording through Square-trained encoders,
and a campus world trained on like the paper's worlds (here a small grid in the campus's place,
a few thousand steps), each stage cached, a section with its tables and figures."""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest

import sensorimotor
from sensorimotor import experiments as ex
from sensorimotor.analysis.probes import BURN_IN
from sensorimotor.errors import InputError
from sensorimotor.experiments import real
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.learn.kinds import KINDS
from sensorimotor.learn.models import paper_kinds
from sensorimotor.report.document import to_markdown
from sensorimotor.sim.mrpt import gridmap_bytes

PAPER = paper_kinds()


def _context(tmp_path, square: dict, seen: list, worlds=("square",)):
    rep = SimpleNamespace(
        out=tmp_path,
        worlds=worlds,
        device="cpu",
        run_dir=lambda world, model, seed: square[model],
        scale=SimpleNamespace(name="smoke", steps=20_000, epochs=lambda kind: 1, patience=1),
    )

    def runner(jobs, workers, progress):
        seen.extend(job.name for job in jobs)
        return run_jobs(jobs, workers, progress)

    return ex.Context(rep, "real", runner, 1, None, print)


def test_the_real_experiment_runs_the_log_and_a_campus_and_keeps_its_results(
    square_db_path, tmp_path, monkeypatch
):
    free = np.full((44, 64), 0.5)  # a 30 x 20 m yard of 0.5 m cells, a building in it
    free[2:42, 2:62] = 0.99
    free[15:25, 20:30] = 0.01
    grid = tmp_path / "yard.gridmap"
    grid.write_bytes(gridmap_bytes(free, 0.5))
    monkeypatch.setattr(real, "GRIDMAP", grid)
    monkeypatch.setattr(real, "CAMPUS_STEPS", {**real.CAMPUS_STEPS, "smoke": 3000})
    square = {k: tmp_path / "runs" / f"square__{k}__s0" for k in PAPER}
    for kind, run in square.items():
        sensorimotor.train(square_db_path, run, sensorimotor.TrainConfig(model=kind, max_epochs=1))
    seen: list[str] = []
    found = ex.run_experiment(_context(tmp_path, square, seen))
    json.dumps(found, allow_nan=False)  # strict JSON
    assert json.loads((tmp_path / "real" / "real.json").read_text()) == found
    assert len(seen) == 2 + 1 + len(PAPER) + 1 + len(PAPER) + len(PAPER) + 1 + len(PAPER)

    rec = found["real"]
    assert (rec["rows"], rec["test_rows"], rec["scans"]) == (224, 23, 225)
    assert rec["baselines"]["mean"] == pytest.approx(0.2175, abs=1e-4)  # as in docs/results/real
    assert rec["baselines"]["copy_last"] == pytest.approx(0.0993, abs=1e-4)
    assert set(rec["models"]) == set(PAPER)
    assert all(math.isfinite(m["error"]) for m in rec["models"].values())
    assert rec["analysis_raw"]["steps"] == 23
    assert rec["analysis_raw"]["walls_known"] is False

    camp = found["campus"]
    assert (camp["world"], camp["steps"], camp["test_rows"]) == ("yard", 3000, 300)
    assert camp["size"] == [31.0, 21.0]  # the yard and one cell around
    # the building's four sides, the yard's and two steps at each of its corners: the yard is
    # opened to the clearance (2 m, 4 cells), which rounds its corners off
    assert (camp["walls"], camp["clearance"]) == (24, 2.0)
    assert camp["trapped_from"] is None  # the agent roams the yard to the end
    for m in camp["models"].values():
        assert math.isfinite(m["error"])
        assert math.isfinite(m["on_real"])
        assert m["epochs"] == 1
    assert camp["baselines"]["copy_last"] < camp["baselines"]["mean"]
    assert set(camp["analysis"]) == {"raw", *PAPER}
    assert not any(a["walls_known"] for a in camp["analysis"].values())
    for name, a in camp["analysis"].items():  # a memory's first steps, from zero, left out
        recurrent = name != "raw" and KINDS[name].recurrent
        assert a["steps"] == 300 - (BURN_IN if recurrent else 0)

    again: list[str] = []
    assert ex.run_experiment(_context(tmp_path, square, again)) == found
    assert again == []  # kept: nothing imported, trained, tested or analysed twice

    rep = SimpleNamespace(out=tmp_path)
    md = to_markdown(ex.sections(rep, {"real": found}), tmp_path)
    assert "## Real data" in md
    assert "**23 rows**" in md
    assert "opened to a clearance of 2 m" in md
    assert "trapped" not in md
    assert "none beats copying the last reading" in md  # 1-epoch models do not
    assert "none of the campus-trained models beats copying" in md
    for kind in PAPER:
        assert f"| {kind} |" in md
    for png in ("real_path.png", "campus_trajectory.png"):
        assert f"(real/{png})" in md
        assert (tmp_path / "real" / png).stat().st_size > 10_000


def test_the_real_experiment_needs_square(tmp_path):
    ctx = _context(tmp_path, {}, [], worlds=("rooms1",))
    with pytest.raises(InputError, match="add square to --worlds"):
        real.run(ctx)
    with pytest.raises(InputError, match="add square to --worlds"):  # before any stage
        ex.check(SimpleNamespace(experiments=("real",), worlds=("rooms1",)))
    ex.check(SimpleNamespace(experiments=("real",), worlds=("square", "rooms1")))
