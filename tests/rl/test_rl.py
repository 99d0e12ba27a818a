"""Reinforcement learning on frozen encoders: the features the policy sees (shapes, the
recurrent state carried and reset with the episode), the evaluation's episode accounting, the
statistics against hand-computed values, a resumed grid giving the same bytes, one-line errors."""

from __future__ import annotations

import json
import shutil
from functools import partial
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
import torch

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.vec_env import DummyVecEnv

from conftest import assert_one_line_error
from sensorimotor.envs import TASKS
from sensorimotor.errors import InputError
from sensorimotor.learn.models import build_model
from sensorimotor.rl import RUNS_ENV, check_extra
from sensorimotor.rl.features import (
    FeatureVecEnv,
    _frozen,
    feature_sets,
    load_encoder,
    needs_runs,
    parse_features,
)
from sensorimotor.rl.results import fmt_ci, summary, verdicts
from sensorimotor.rl.runner import EVAL_SEED, RLConfig, evaluate, run_grid
from sensorimotor.sim.database import scale_sensors
from sensorimotor.stats import BEFORE, CHOSEN, Verdict, bootstrap_interval, t_interval

RUNS = Path(__file__).parents[2] / "docs" / "results" / "runs"
UNTRAINED = ("pose", "raw", "random", "pose+raw")  # feature sets read from no run
TINY_PPO = {"n_steps": 32, "batch_size": 64, "n_epochs": 1, "learning_rate": 3e-4,
            "gamma": 0.99, "gae_lambda": 0.95, "ent_coef": 0.0}  # fmt: skip


def corner_envs(limits: list[int], world: str = "rooms1") -> DummyVecEnv:
    """Corner task environments truncated after ``limits[i]`` steps, seeded 0, 1, ..."""
    makers = [
        partial(gym.make, TASKS["corner"].env_id, world=world, max_episode_steps=n) for n in limits
    ]
    venv = DummyVecEnv(makers)
    venv.seed(0)
    return venv


@pytest.mark.parametrize("features", list(feature_sets()))
def test_each_feature_set_has_its_shape_for_every_environment(features):
    if (RUNS / f"rooms1__{features}__s0").is_dir() or features in UNTRAINED:
        encoder, run = load_encoder(features, RUNS, "rooms1", 0)
        assert (run is None) == (features in UNTRAINED)
    else:  # a kind without a shipped run (rec-sma): its untrained encoder
        encoder = _frozen(build_model(features, seed=0))
    venv = FeatureVecEnv(corner_envs([5, 5, 5]), features, encoder)
    size = {"pose": 4, "raw": 5, "pose+raw": 11}.get(features, 10)
    assert venv.observation_space.shape == (size,)
    obs = venv.reset()
    assert obs.shape == (3, size)
    assert obs.dtype == np.float32
    obs, *_ = venv.step(np.zeros((3, 2), dtype=np.float32))
    assert obs.shape == (3, size)
    assert np.isfinite(obs).all()
    if features == "pose":  # the oracle: scaled x, y and the heading's cosine and sine
        pose = venv.venv.buf_infos[0]["pose"]
        np.testing.assert_allclose(
            obs[0], [pose[0] / 25 - 1, pose[1] / 25 - 1, np.cos(pose[2]), np.sin(pose[2])],
            rtol=1e-6,
        )  # fmt: skip


def test_the_recurrent_state_is_carried_through_an_episode_and_reset_with_it():
    """Env 0 ends after 3 steps, env 1 runs on: the reference is the encoder run from a zero
    state over each episode's readings (learn.models, one sequence at a time)."""
    encoder, _ = load_encoder("rec-sm", RUNS, "rooms1", 0)
    venv = FeatureVecEnv(corner_envs([3, 100]), "rec-sm", encoder)
    venv.reset()
    readings = [[info["readings"]] for info in venv.venv.reset_infos]  # per env, its episode
    actions = np.array([[0.0, 0.3], [0.5, -0.2]], dtype=np.float32)
    for _ in range(3):
        obs, _, dones, infos = venv.step(actions)
        for i in range(2):
            readings[i].append(infos[i]["readings"])
    assert dones.tolist() == [True, False]

    def reference(seq) -> np.ndarray:
        x = torch.from_numpy(scale_sensors(np.array(seq, dtype=np.float32)))[None]  # (1, T, 5)
        with torch.no_grad():
            return encoder.encode(x)[0][0, -1].numpy()  # z_s of the last step

    np.testing.assert_allclose(obs[1], reference(readings[1]), atol=1e-6)  # carried 4 steps
    np.testing.assert_allclose(infos[0]["terminal_observation"], reference(readings[0]), atol=1e-6)
    start = venv.venv.reset_infos[0]["readings"]
    np.testing.assert_allclose(obs[0], reference([start]), atol=1e-6)  # a new episode: zero state
    assert not np.allclose(obs[1], reference([readings[1][-1]]), atol=1e-3)  # memory matters


def test_evaluation_counts_each_episode_once_and_plays_the_same_starts():
    """Stub policy (full speed ahead) on 3 environments for 7 episodes of at most 4 steps: the
    same numbers as 7 episodes played one by one on environments seeded as the evaluation's."""

    class Ahead:
        def predict(self, obs, deterministic):
            assert deterministic
            return np.tile([1.0, 0.0], (len(obs), 1)).astype(np.float32), None

    venv = FeatureVecEnv(corner_envs([4, 4, 4]), "raw")
    got = evaluate(Ahead(), venv, 7)
    assert evaluate(Ahead(), venv, 7) == got
    successes, returns = [], []
    for i, episodes in enumerate([3, 2, 2]):  # 7 episodes shared among 3 environments
        env = gym.make(TASKS["corner"].env_id, world="rooms1", max_episode_steps=4)
        env.reset(seed=EVAL_SEED + i)
        for e in range(episodes):
            if e:
                env.reset()
            total, done = 0.0, False
            while not done:
                _, reward, terminated, truncated, info = env.step(np.array([1.0, 0.0]))
                total += reward
                done = terminated or truncated
            successes.append(float(info["is_success"]))
            returns.append(total)
    assert got["success"] == pytest.approx(np.mean(successes))
    assert got["return"] == pytest.approx(np.mean(returns))


def test_a_summary_has_student_t_intervals_below_ten_seeds_and_the_bootstrap_from_ten():
    s = summary([0.2, 0.4, 0.9])
    assert (s["ci_low"], s["ci_high"]) == t_interval([0.2, 0.4, 0.9])
    assert s["interval"] == "Student-t"
    assert s["ci_low"] <= s["mean"] <= s["ci_high"]
    assert s["per_seed"] == [0.2, 0.4, 0.9]
    # ten seeds: the bootstrap, its numbers those of the bootstrap before stats.interval
    ten = summary([0.1, 0.3, 0.2, 0.5, 0.4, 0.35, 0.6, 0.15, 0.25, 0.45])
    assert ten["interval"] == "bootstrap"
    assert (ten["ci_low"], ten["ci_high"]) == (0.24, 0.425)
    assert (ten["iqm"], ten["iqm_ci_low"], ten["iqm_ci_high"]) == (
        0.325,
        0.20833333333333334,
        0.44166666666666665,
    )
    # both intervals beside the one read: Student-t and the percentile bootstrap
    assert (s["t_ci_low"], s["t_ci_high"]) == t_interval([0.2, 0.4, 0.9])
    assert (s["bootstrap_ci_low"], s["bootstrap_ci_high"]) == bootstrap_interval([0.2, 0.4, 0.9])
    assert s["t_ci_low"] < s["bootstrap_ci_low"]  # three seeds: the bootstrap is narrower
    assert (ten["bootstrap_ci_low"], ten["t_ci_low"]) == (0.24, t_interval(ten["per_seed"])[0])
    text = fmt_ci(s)
    assert text == (
        f"0.50 [t {s['t_ci_low']:.2f}, {s['t_ci_high']:.2f}; "
        f"bootstrap {s['bootstrap_ci_low']:.2f}, {s['bootstrap_ci_high']:.2f}]"
    )
    one = summary([0.5])
    assert (one["ci_low"], one["ci_high"], one["interval"]) == (None, None, None)
    assert one["t_ci_low"] is one["bootstrap_ci_low"] is None
    assert one["iqm_ci_low"] == one["iqm_ci_high"] == 0.5
    with pytest.raises(ValueError, match="finite"):
        summary([0.1, float("nan")])


def test_the_verdict_needs_every_motor_feature_set_above_raw_by_its_interval():
    def scores(*v):
        return {"success": {"per_seed": list(v)}}

    results = {"raw": scores(0.1, 0.2, 0.3), "rec-sm": scores(0.5, 0.6, 0.7)}
    v = verdicts(results)
    assert v["motors_help"]["differences"]["rec-sm"]["mean"] == pytest.approx(0.4)
    assert v["motors_help"]["holds"] is True
    assert v["motors_help"]["provenance"] == BEFORE
    assert "Student-t" in v["motors_help"]["test"]
    json.dumps(v, allow_nan=False)
    assert v["pose_beats_random"]["holds"] is None  # not run
    results["sm"] = scores(0.3, 0.1, 0.2)  # as good as raw on average, not better
    assert verdicts(results)["motors_help"]["holds"] is False
    results |= {"pose": scores(0.9, 0.8, 1.0), "random": scores(0.0, 0.1, 0.0)}
    assert verdicts(results)["pose_beats_random"]["holds"] is True
    assert verdicts({"pose": scores(0.5)})["motors_help"]["holds"] is None
    two = {"pose": scores(0.9, 0.9), "random": scores(0.1, 0.1)}  # interval [0.8, 0.8]
    assert verdicts(two)["pose_beats_random"]["holds"] is None  # below MIN_SEEDS: not judged
    other = {f: {"success_stochastic": r["success"]} for f, r in results.items()}
    assert verdicts(other, "success_stochastic") == verdicts(results)  # the score is chosen


def test_explore_verdicts_are_chosen_on_these_data_while_the_chosen_bonus_is_used():
    def scores(*v):
        return {"success": {"per_seed": list(v)}}

    results = {"pose": scores(0.9, 0.8, 1.0), "random": scores(0.0, 0.1, 0.0),
               "raw": scores(0.1, 0.2, 0.3), "rec-sm": scores(0.5, 0.6, 0.7)}  # fmt: skip
    chosen = verdicts(results, "success", "explore", RLConfig().ppo)
    for v in chosen.values():
        assert v["provenance"] == CHOSEN
        assert "entropy bonus" in v["where"]
        assert Verdict.from_dict(v).provenance == CHOSEN
    assert chosen["pose_beats_random"]["holds"] is True  # the numbers are the same
    other_bonus = {**RLConfig().ppo, "ent_coef": 0.0}
    for task, ppo in (("corner", RLConfig().ppo), ("explore", other_bonus)):
        assert all(
            v["provenance"] == BEFORE for v in verdicts(results, "success", task, ppo).values()
        )


def tiny_config(**kw) -> RLConfig:
    base = {"task": "corner", "features": ("raw", "rec-s"), "seeds": 1, "steps": 128,
            "runs": str(RUNS), "eval_every": 64, "eval_episodes": 4, "n_envs": 2,
            "transfer": ("square",), "ppo": TINY_PPO, "stats_steps": 64}  # fmt: skip
    return RLConfig(**{**base, **kw})


def test_a_grid_resumed_after_a_lost_agent_gives_the_same_bytes(tmp_path):
    config = tiny_config()
    rl = run_grid(config, tmp_path)
    first = (tmp_path / "rl.json").read_bytes()
    r = rl["results"]["rec-s"]
    assert r["curve"]["steps"] == [0, 64, 128]
    assert set(r["transfer"]) == {"square"}
    assert r["encoder_runs"] == [str(RUNS / "rooms1__rec-s__s0")]
    assert 0.0 <= r["success"]["mean"] <= 1.0
    assert len(r["curve"]["success_stochastic"]["mean"]) == 3  # both policies, every evaluation
    assert set(rl["verdicts"]) == {"success", "success_stochastic"}
    assert (tmp_path / "rl.png").stat().st_size > 0
    assert (tmp_path / "raw__s0" / "policy.zip").is_file()
    spread = rl["results"]["raw"]["spread"]  # sd per dimension before standardisation
    assert len(spread["sd"]) == 5
    assert spread["steps"] == 64
    assert any(s > 0 for s in spread["sd"])  # (a ray may read the range all along)
    agent = json.loads((tmp_path / "raw__s0" / "result.json").read_text())
    assert agent["standardisation"]["sd"] == spread["sd_per_seed"][0]
    shutil.rmtree(tmp_path / "rec-s__s0")  # as if stopped while training it
    (tmp_path / "raw__s0" / "policy.zip").unlink()  # a finished agent is not trained again
    run_grid(config, tmp_path)
    assert (tmp_path / "rl.json").read_bytes() == first
    assert not (tmp_path / "raw__s0" / "policy.zip").exists()
    with pytest.raises(InputError, match="other settings"):
        run_grid(tiny_config(steps=192), tmp_path)
    agent["standardisation"]["sd"] = agent["standardisation"]["sd"][:2]  # hand-edited, ragged
    (tmp_path / "raw__s0" / "result.json").write_text(json.dumps(agent))
    with pytest.raises(InputError, match=r"raw__s0.*corrupt standardisation"):
        run_grid(config, tmp_path)


def test_inputs_are_checked_before_any_agent_trains(tmp_path):
    with pytest.raises(InputError, match="two named rooms"):
        run_grid(tiny_config(task="doorway", transfer=("square",)), tmp_path / "a")
    with pytest.raises(InputError, match="run folder not found"):
        run_grid(tiny_config(runs=str(tmp_path)), tmp_path / "b")
    other = tmp_path / "runs" / "rooms1__rec-s__s0"  # a run of another sensor layout
    shutil.copytree(RUNS / "rooms1__rec-s__s0", other)
    config = json.loads((other / "config.json").read_text())
    config["data"]["sensor_layout"]["angles"] = [-1.0, -0.5, 0.0, 0.5, 1.0]
    (other / "config.json").write_text(json.dumps(config))
    with pytest.raises(InputError, match="sensor layout"):
        run_grid(tiny_config(runs=str(tmp_path / "runs")), tmp_path / "c")
    assert not (tmp_path / "a").exists()
    assert not (tmp_path / "c" / "raw__s0").exists()
    with pytest.raises(InputError, match="unknown features nope"):
        parse_features("raw,nope")
    assert parse_features("raw, pose,raw") == ["raw", "pose"]


def test_a_registered_kind_is_a_feature_set_and_gets_a_colour(monkeypatch):
    from sensorimotor.learn.models import KINDS, Kind
    from sensorimotor.rl.plots import COLORS, colors

    monkeypatch.setitem(KINDS, "toy", Kind("toy", "Toy-encoder", "Toy", False, True))
    sets = feature_sets()
    kinds = ["s", "sm", "rec-s", "rec-sm", "rec-sma", "toy"]
    assert list(sets) == ["pose", "raw", *kinds, "random", "pose+raw"]
    assert (sets["toy"].kind, sets["toy"].trained, sets["toy"].size) == ("toy", True, None)
    assert (sets["pose"].size, sets["raw"].size, sets["random"].trained) == (4, 5, False)
    assert parse_features("toy,raw") == ["toy", "raw"]
    assert needs_runs(["pose", "toy", "random", "rec-s"]) == ["toy", "rec-s"]
    palette = colors(["pose", "toy", "other"])
    assert palette["pose"] == COLORS["pose"]
    assert len({palette["pose"], palette["toy"], palette["other"]}) == 3
    with pytest.raises(InputError, match="--runs"):
        load_encoder("toy", None, "rooms1", 0)


def test_trained_features_need_a_runs_folder_there_is_no_default(cli, tmp_path, monkeypatch):
    assert RLConfig().runs is None  # nothing points into the repository
    with pytest.raises(InputError, match=f"give --runs DIR .* or set {RUNS_ENV}"):
        run_grid(tiny_config(runs=None), tmp_path / "a")
    assert not (tmp_path / "a").exists()
    run_grid(tiny_config(runs=None, features=("raw",), steps=32, eval_every=32), tmp_path / "b")
    monkeypatch.delenv(RUNS_ENV, raising=False)
    proc = cli("rl", "corner", "--features", "raw,rec-sm", "--out", tmp_path / "c")
    assert_one_line_error(proc, "features rec-sm", "--runs", RUNS_ENV)
    monkeypatch.setenv(RUNS_ENV, str(tmp_path / "nowhere"))  # the variable stands for --runs
    proc = cli("rl", "corner", "--features", "rec-sm", "--out", tmp_path / "c")
    assert_one_line_error(proc, "nowhere")


def test_a_missing_extra_is_one_clear_line(monkeypatch):
    import importlib.util

    monkeypatch.setattr(importlib.util, "find_spec", lambda name: None)
    with pytest.raises(InputError, match=r"pip install 'sensorimotor\[rl\]'"):
        check_extra()


def test_the_command_line_refuses_bad_input_in_one_line(cli, tmp_path):
    proc = cli("rl", "doorway", "--world", "square", "--features", "raw", "--out", tmp_path)
    assert_one_line_error(proc, "two named rooms")
    proc = cli("rl", "corner", "--features", "pose,telepathy", "--out", tmp_path)
    assert_one_line_error(proc, "unknown features telepathy")


def test_agents_trained_as_jobs_of_worker_processes_are_those_trained_here(tmp_path, one_thread):
    """`rl --workers 2`: each agent a job of `report`'s worker processes (as `--backend ray`
    makes each a Ray task), the same rl.json to the byte as the agents trained in this process."""
    from sensorimotor.jobs.backend import job_runner, run_all

    config = tiny_config(features=("raw", "random"), transfer=())
    run_grid(config, tmp_path / "here")
    with job_runner("local", workers=2) as (run_jobs, n):
        jobs, lines = [], []

        def run_agents(todo):
            jobs.extend(name for name, _, _ in todo)
            return run_all(run_jobs, n, todo, lambda name, msg: lines.append((name, msg)))

        run_grid(config, tmp_path / "jobs", run_agents=run_agents)
    assert sorted(jobs) == ["random__s0", "raw__s0"]
    # each agent tells its parent how far it is, its last line always (a log sees it move)
    last = f"{config.steps:,} of {config.steps:,} steps"
    assert {("raw__s0", last), ("random__s0", last)} <= set(lines)
    assert (tmp_path / "jobs" / "rl.json").read_bytes() == (
        tmp_path / "here" / "rl.json"
    ).read_bytes()


def test_no_verdict_on_the_features_when_the_oracle_does_not_beat_random():
    from sensorimotor.rl.results import verdicts

    def scores(*values):
        return {"success": {"per_seed": list(values)}}

    results = {
        "pose": scores(0.10, 0.12, 0.11),  # the oracle learned nothing above random
        "random": scores(0.30, 0.31, 0.29),
        "raw": scores(0.10, 0.11, 0.12),
        "sm": scores(0.60, 0.62, 0.61),
        "rec-sm": scores(0.60, 0.63, 0.61),
    }
    v = verdicts(results)
    assert v["pose_beats_random"]["holds"] is False
    assert v["motors_help"]["holds"] is None
    assert "sanity check" in v["motors_help"]["numbers"]
    results["pose"] = scores(0.90, 0.92, 0.91)
    assert verdicts(results)["motors_help"]["holds"] is True


@pytest.mark.parametrize("seeds", [1, 3])
def test_the_figure_draws_whiskers_only_where_there_is_an_interval(seeds):
    from matplotlib.container import ErrorbarContainer

    from sensorimotor.rl.plots import rl_figure

    one = seeds == 1
    score = {"mean": 0.5, "ci_low": None if one else 0.4, "ci_high": None if one else 0.6}
    curve = {k: {kk: [v, v] for kk, v in score.items()} for k in ("success", "success_stochastic")}
    result = {"success": score, "success_stochastic": score, "curve": {"steps": [0, 10], **curve}}
    rl = {"task": "homing", "world": "rooms1", "seeds": seeds, "eval_episodes": 50,
          "transfer": [], "results": {"raw": result, "pose": result}}  # fmt: skip
    fig = rl_figure(rl)
    curves, *bars = fig.axes
    assert (f"{seeds} seed:" if one else f"{seeds} seeds:") in curves.get_title()
    for ax in bars:
        whiskers = [c for c in ax.containers if isinstance(c, ErrorbarContainer)]
        assert ("no interval" in ax.get_title()) == one
        assert len(whiskers) == (0 if one else 1)
