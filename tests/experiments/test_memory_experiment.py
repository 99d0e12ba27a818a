"""``reproduce --experiment memory``: Rec-SMA and its ablations trained, every representation
probed on a fresh database, the verdicts against thresholds set before, a section; all cached."""

from __future__ import annotations

import json
from types import SimpleNamespace

import pytest

import sensorimotor
from sensorimotor import experiments as ex
from sensorimotor.errors import InputError
from sensorimotor.experiments import memory
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.learn.models import REC_SM, paper_kinds
from sensorimotor.report.document import to_markdown


def _context(tmp_path, data: dict, runs: dict, seen: list, worlds=("rooms1",)):
    rep = SimpleNamespace(
        out=tmp_path,
        worlds=worlds,
        seeds=1,
        device="cpu",
        data=data,
        run_dir=lambda world, model, seed: tmp_path / "runs" / f"{world}__{model}__s{seed}",
        scale=SimpleNamespace(name="smoke", steps=20_000, epochs=lambda kind: 1, patience=1),
    )

    def runner(jobs, workers, progress):
        seen.extend(job.name for job in jobs)
        return run_jobs(jobs, workers, progress)

    return ex.Context(rep, "memory", runner, 1, None, print)


@pytest.mark.slow  # five trainings and twenty-two probes on 20,000-step databases
def test_the_memory_experiment_trains_the_variants_probes_everything_and_keeps_it(
    rooms1_db_path, tmp_path, monkeypatch
):
    monkeypatch.setattr(memory, "OBSERVER_FIT", 3000)  # the filter's cost, kept small
    for name in memory.SHOWN_OBSERVERS:
        monkeypatch.setitem(memory.OBSERVERS, name, (memory.OBSERVERS[name][0], 4000))
    runs = {k: tmp_path / "runs" / f"rooms1__{k}__s0" for k in paper_kinds()}
    for kind, run in runs.items():
        sensorimotor.train(rooms1_db_path, run, sensorimotor.TrainConfig(model=kind, max_epochs=1))
    seen: list[str] = []
    found = ex.run_experiment(_context(tmp_path, {"rooms1": rooms1_db_path}, runs, seen))
    json.dumps(found, allow_nan=False)  # strict JSON
    assert json.loads((tmp_path / "memory" / "memory.json").read_text()) == found
    n_variants = len(memory.VARIANTS)
    assert sum(name.startswith("train") for name in seen) == n_variants
    shown = 2 + len(memory.SHOWN_OBSERVERS) + len(paper_kinds()) + n_variants
    assert sum(name.startswith("probe") for name in seen) == shown
    rows = found["rows"]["rooms1"]
    assert list(rows) == [
        "pose", *memory.SHOWN_OBSERVERS, "raw", *paper_kinds(), *(v.name for v in memory.VARIANTS)
    ]  # fmt: skip
    assert rows["pose"]["r2_x"]["mean"] > 0.99  # the ceiling holds the position exactly
    assert rows["pose"]["room"]["mean"] > rows["raw"]["room"]["mean"]
    assert rows["observer"]["room"]["mean"] > rows["raw"]["room"]["mean"]  # a memory's ceiling
    assert rows["raw"]["error"]["mean"] is None
    assert rows[REC_SM]["error"]["n"] == 1
    assert all(len(curve) == 32 for curve in found["curves"].values())
    claims = {v["claim"]: v for v in found["verdicts"]}
    assert len(claims) == 3  # room and position in rooms1, the ablation
    assert all(v["provenance"] == "set before the data" for v in claims.values())
    assert (tmp_path / "memory" / "memory.png").stat().st_size > 10_000

    again: list[str] = []
    assert ex.run_experiment(_context(tmp_path, {"rooms1": rooms1_db_path}, runs, again)) == found
    assert again == []  # nothing trained or probed twice

    md = to_markdown(ex.sections(SimpleNamespace(out=tmp_path), {"memory": found}), tmp_path)
    assert "## A memory that reads the motor commands" in md
    assert "true pose (ceiling)" in md
    assert "ideal observer (ceiling for a memory)" in md
    assert "(strongest baseline)" in md
    assert "(memory/memory.png)" in md


def test_the_memory_experiment_needs_a_world_with_rooms(tmp_path):
    ctx = _context(tmp_path, {}, {}, [], worlds=("square",))
    with pytest.raises(InputError, match="needs rooms1 or rooms2"):
        memory.run(ctx)


def test_the_ideal_observer_goes_through_the_same_probes(rooms1_db_path, tmp_path, monkeypatch):
    monkeypatch.setattr(memory, "OBSERVER_FIT", 3000)  # the filter's cost, kept small
    monkeypatch.setitem(memory.OBSERVERS, "observer", (True, 4000))  # 16,000 is the default
    out = tmp_path / "observer.json"
    probes = memory.probe_job("observer", str(rooms1_db_path), str(out), "k")["probes"]
    assert json.loads(out.read_text(), parse_constant=float)["result"]["probes"] == probes
    assert probes["fit_steps"] == 3000 - probes["burn_in"]
    # it finds the place from the stream alone, where the raw readings stay near chance (1/3)
    assert probes["room"]["balanced_accuracy"] > 0.5
    assert probes["position"]["median_error"] < 5.0, probes


def test_the_observer_without_commands_refuses_another_behaviour(tmp_path):
    from sensorimotor.sim.database import generate, save_database
    from sensorimotor.sim.world import load_world

    path = tmp_path / "smooth.npz"
    save_database(generate(load_world("rooms1"), 3000, seed=0, behaviour="smooth"), path)
    with pytest.raises(ValueError, match=r"smooth\.npz: the observer without commands"):
        memory.probe_job("observer-blind", str(path), str(tmp_path / "o.json"), "k")
    assert not (tmp_path / "o.json").exists()
