"""``reproduce --experiment rl``: the grid on a reproduction's Rooms1 encoders (tiny: one task,
two feature sets, one seed, one 512-step rollout), cached so that a rerun trains no agent; its
report section; its verdicts on hand-made scores that make them hold and fail."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest

pytest.importorskip("stable_baselines3")

from sensorimotor import experiments as ex
from sensorimotor.errors import InputError
from sensorimotor.experiments import rl as rl_stage
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.report.blocks import to_markdown
from sensorimotor.rl.results import summary, verdicts
from sensorimotor.rl.runner import RLConfig
from sensorimotor.stats import BEFORE, CHOSEN

RUNS = Path(__file__).parents[2] / "docs" / "results" / "runs"  # the shipped Rooms1 encoders


def fake_rep(out: Path, worlds=("rooms1",), seeds: int = 1) -> SimpleNamespace:
    return SimpleNamespace(
        out=out, worlds=worlds, seeds=seeds, scale=SimpleNamespace(name="smoke"),
        run_dir=lambda world, model, seed: RUNS / f"{world}__{model}__s{seed}",
    )  # fmt: skip


@pytest.fixture
def tiny(monkeypatch):
    monkeypatch.setattr(rl_stage, "tasks", lambda: ("corner",))
    monkeypatch.setattr(rl_stage, "features", lambda: ("raw", "sm"))
    plan = rl_stage.Plan(512, 512, 2, {"n_steps": 64, "batch_size": 64, "n_epochs": 1})
    monkeypatch.setitem(rl_stage.PLANS, "smoke", plan)


def test_the_grid_runs_as_jobs_is_cached_and_its_section_reads_it(tmp_path, tiny, one_thread):
    trained: list[str] = []

    def counting(jobs, workers, progress):
        trained.extend(job.name for job in jobs)
        return run_jobs(jobs, workers, progress)

    rep = fake_rep(tmp_path)
    ctx = ex.Context(rep, "rl", counting, 1, lambda *_: None, lambda _: None)
    found = ex.run_experiment(ctx)
    assert sorted(trained) == ["raw__s0", "sm__s0"]
    corner = found["tasks"]["corner"]
    assert corner["rl"]["transfer"] == ["square", "rooms2"]
    assert set(corner["rl"]["results"]) == {"raw", "sm"}
    assert found["headline"] == "success_stochastic"
    assert (tmp_path / corner["folder"] / "rl.png").is_file()

    trained.clear()
    assert ex.run_experiment(ctx) == found  # the same numbers, and no agent trained again
    assert trained == []

    markdown = to_markdown(ex.sections(rep, {"rl": found}), tmp_path)
    assert "| sm |" in markdown
    assert f"]({corner['folder']}/rl.png)" in markdown
    assert "1 seed(s): no verdict" in markdown
    assert "(mean, IQM; one seed: no interval)" in markdown
    assert " (one seed) |" in markdown  # a mean without an interval


def test_a_task_that_the_common_budget_teaches_nothing_gets_its_own(monkeypatch):
    """quick: explore trains 500,000 steps, the other tasks 40,000; the section says so."""
    rep = fake_rep(Path("/nowhere"))
    rep.scale = SimpleNamespace(name="quick")
    configs = rl_stage.configs(rep)
    assert {t: (c.steps, c.eval_every) for t, c in configs.items()} == {
        "corner": (40_000, 20_000),
        "doorway": (40_000, 20_000),
        "explore": (500_000, 125_000),
    }
    steps = {"corner": 40_000, "doorway": 40_000, "explore": 500_000}
    assert rl_stage._steps(steps) == "40,000 steps each (explore: 500,000)"
    assert rl_stage._steps({"corner": 512}) == "512 steps each"


def test_doorway_is_not_sent_to_a_world_without_two_rooms(tiny, monkeypatch):
    monkeypatch.setattr(rl_stage, "tasks", lambda: ("doorway",))
    (config,) = rl_stage.configs(fake_rep(Path("/nowhere"))).values()
    assert config.transfer == ("rooms2",)


def test_the_grid_reads_its_tasks_features_and_encoders_from_the_registries(monkeypatch):
    from sensorimotor.learn.models import KINDS, Kind

    assert rl_stage.tasks() == ("corner", "doorway", "explore")
    assert rl_stage.features() == ("pose", "raw", "s", "sm", "rec-s", "rec-sm", "random")
    assert rl_stage.encoders() == ("s", "sm", "rec-s", "rec-sm")
    monkeypatch.setitem(KINDS, "toy", Kind("toy", "Toy-encoder", "Toy", False, True))
    assert rl_stage.encoders()[-1] == "toy"
    assert "toy" in rl_stage.features()


def test_a_reproduction_without_rooms1_or_a_run_is_refused_in_one_line(tmp_path):
    with pytest.raises(InputError, match="add rooms1 to --worlds"):
        rl_stage.configs(fake_rep(tmp_path, worlds=("square",)))
    rep = fake_rep(tmp_path)
    rep.run_dir = lambda world, model, seed: tmp_path / f"{world}__{model}__s{seed}"
    with pytest.raises(InputError, match="no s run on rooms1"):
        rl_stage.configs(rep)


def hand_made(scores: dict[str, list[float]]) -> dict:
    results = {
        f: {"success_stochastic": summary(v), "success": summary(v)} for f, v in scores.items()
    }
    return {
        "seeds": len(next(iter(scores.values()))),
        "verdicts": {s: verdicts(results, s) for s in ("success_stochastic", "success")},
    }


def test_the_verdicts_hold_and_fail_by_their_thresholds():
    # 3 seeds: Student-t intervals (t = 4.30), wider than the bootstrap of 3 values
    good = {"pose": [0.8, 0.9, 0.7], "random": [0.1, 0.0, 0.1], "raw": [0.2, 0.3, 0.1],
            "sm": [0.5, 0.6, 0.4], "rec-sm": [0.5, 0.6, 0.45]}  # fmt: skip
    lines = rl_stage.verdict_lines(hand_made(good))
    assert [held for _, held in lines] == [True, True, True]
    assert "Student-t below 10 seeds" in lines[1][0]
    assert "bootstrap" in lines[1][0]  # the bootstrap interval beside the Student-t one
    assert all(f"Provenance: {BEFORE}" in text for text, _ in lines)
    explore = hand_made(good)
    explore["verdicts"] = {
        s: verdicts({f: {s: summary(v)} for f, v in good.items()}, s, "explore", RLConfig().ppo)
        for s in ("success_stochastic", "success")
    }
    assert all(f"Provenance: {CHOSEN}" in t for t, _ in rl_stage.verdict_lines(explore))
    bad = {**good, "random": [0.3, 0.35, 0.4], "sm": [0.2, 0.2, 0.2]}  # sm - raw: 0, -0.1, +0.1
    lines = rl_stage.verdict_lines(hand_made(bad))
    assert [held for _, held in lines] == [True, False, False]
    assert "NOT supported" in lines[1][0]
    blind = {**bad, "random": [0.8, 0.9, 0.6]}  # the oracle does not beat random: no verdicts
    lines = rl_stage.verdict_lines(hand_made(blind))
    assert [held for _, held in lines] == [False, None]
    assert "does NOT hold" in lines[0][0]
    assert "no verdict" in lines[1][0]
    two = {f: v[:2] for f, v in good.items()}  # 2 seeds: not judged
    assert [held for _, held in rl_stage.verdict_lines(hand_made(two))] == [None, None]
