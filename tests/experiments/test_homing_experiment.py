"""``reproduce --experiment homing``: Rec-SMA trained through the memory experiment's door, the
homing grid on the reproduction's runs (tiny: one seed, one short rollout), cached, its section;
its verdicts on hand-made scores that make them hold and fail."""

from __future__ import annotations

import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest

pytest.importorskip("stable_baselines3")

from sensorimotor import experiments as ex
from sensorimotor.errors import InputError
from sensorimotor.experiments import homing
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.learn.models import REC_SM, REC_SMA
from sensorimotor.report.blocks import to_markdown
from sensorimotor.rl.results import summary
from sensorimotor.stats import BEFORE

SHIPPED = Path(__file__).parents[2] / "docs" / "results" / "runs"


def _rep(tmp_path, data: dict, worlds=("rooms1",)):
    return SimpleNamespace(
        out=tmp_path, worlds=worlds, seeds=1, device="cpu", data=data,
        run_dir=lambda world, model, seed: tmp_path / "runs" / f"{world}__{model}__s{seed}",
        scale=SimpleNamespace(name="smoke", steps=20_000, epochs=lambda kind: 1, patience=1),
    )  # fmt: skip


def test_homing_trains_rec_sma_once_runs_the_grid_and_keeps_it(rooms1_db_path, tmp_path,
                                                                monkeypatch, one_thread):  # fmt: skip
    monkeypatch.setitem(homing.PLANS, "smoke", homing.Plan(128, 128, 2, {"n_steps": 16, "batch_size": 32, "n_epochs": 1}))
    shutil.copytree(SHIPPED / f"rooms1__{REC_SM}__s0", tmp_path / "runs" / f"rooms1__{REC_SM}__s0")
    rep = _rep(tmp_path, {"rooms1": rooms1_db_path})
    seen: list[str] = []

    def counting(jobs, workers, progress):
        seen.extend(job.name for job in jobs)
        return run_jobs(jobs, workers, progress)

    ctx = ex.Context(rep, "homing", counting, 1, lambda *_: None, lambda _: None)
    found = ex.run_experiment(ctx)
    assert seen[0] == f"train {REC_SMA} rooms1__{REC_SMA}__s0"  # in the reproduction's runs
    assert (tmp_path / "runs" / f"rooms1__{REC_SMA}__s0" / "model.pt").is_file()
    assert sorted(seen[1:]) == sorted(f"{f}__s0" for f in homing.FEATURES)
    assert list(found["worlds"]) == ["rooms1"]  # Rooms2 is not among the reproduction's worlds
    got = found["worlds"]["rooms1"]
    assert set(got["rl"]["results"]) == set(homing.FEATURES)
    assert got["rl"]["world"] == "rooms1"
    assert [v["holds"] for v in got["verdicts"]] == [None, None, None]  # one seed: not judged
    seen.clear()
    assert ex.run_experiment(ctx) == found
    assert seen == []  # nothing trained twice
    md = to_markdown(ex.sections(rep, {"homing": found}), tmp_path)
    assert "## Does an agent need a memory to come back?" in md
    assert "| pose+raw (ceiling) |" in md
    assert "| pose (localised, no memory) |" in md
    assert "(strongest baseline)" in md
    assert "### homing in rooms1" in md
    guess = got["rl"]["no_memory"]  # rl.json's: the task's own memoryless baseline
    assert guess["resets"] == 1_000
    assert f"| {guess['what']}, 1,000 resets | {guess['success']:.2f} |" in md
    assert f"]({got['folder']}/rl.png)" in md


def test_homing_runs_in_the_worlds_with_rooms_and_is_refused_in_one_line_without(tmp_path):
    with pytest.raises(InputError, match="needs the encoders trained on rooms1 or rooms2"):
        homing.check(_rep(tmp_path, {}, worlds=("square",)))
    assert homing.worlds(_rep(tmp_path, {}, worlds=("rooms2", "square", "rooms1"))) == ["rooms1", "rooms2"]


def _rl(scores: dict[str, list[float]]) -> dict:
    return {
        "seeds": len(scores["raw"]), "eval_episodes": 50,
        "results": {f: {"success_stochastic": summary(v)} for f, v in scores.items()},
    }  # fmt: skip


def test_the_verdicts_read_the_issues_thresholds():
    good = {"pose+raw": [0.9, 0.85, 0.95], "raw": [0.3, 0.35, 0.2], REC_SMA: [0.85, 0.8, 0.9]}
    got = homing.verdicts(_rl(good))
    assert [v.holds for v in got] == [True, True, True]
    assert all(v.provenance == BEFORE for v in got)
    bad = {"pose+raw": [0.9, 0.95, 1.0], "raw": [0.5, 0.45, 0.4], REC_SMA: [0.8, 0.75, 0.8]}
    got = homing.verdicts(_rl(bad))
    assert [v.holds for v in got] == [False, False, False]
    assert [v.numbers.rpartition("; ")[2] for v in got] == [  # means 0.783, gap +0.167, 0.45
        "missed by 0.02", "missed by 0.07", "missed by 0.05"]  # fmt: skip
