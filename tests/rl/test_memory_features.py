"""A task's excursion passes through the features: a recurrent encoder remembers it, Rec-SMA
reads the commands executed (the excursion's and the agent's), the oracle pose+raw knows
where the episode started; a tiny homing grid runs end to end."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

pytest.importorskip("stable_baselines3")

from sensorimotor.envs.laser_world import MAX_STEP, MAX_TURN
from sensorimotor.learn.models import build_model
from sensorimotor.rl.features import FeatureVecEnv, _frozen, load_encoder
from sensorimotor.rl.runner import RLConfig, run_grid
from sensorimotor.rl.vec_env import TaskVecEnv
from sensorimotor.sim.database import scale_motors, scale_sensors

RUNS = Path(__file__).parents[2] / "docs" / "results" / "runs"


def homing(n: int = 2, seed: int = 4) -> TaskVecEnv:
    venv = TaskVecEnv("homing", "rooms1", n)
    venv.seed(seed)
    return venv


def z_last(encoder, readings, motors=None) -> np.ndarray:
    """z_s of the last step of one sequence, run from a zero state (learn.models)."""
    x = torch.from_numpy(scale_sensors(np.asarray(readings, dtype=np.float32)))[None]
    m = None if motors is None else torch.from_numpy(scale_motors(np.asarray(motors)))[None]
    with torch.no_grad():
        return encoder.encode(x, None, m)[0][0, -1].numpy()


def test_a_recurrent_encoder_reads_the_excursion_before_the_first_observation():
    encoder, _ = load_encoder("rec-sm", RUNS, "rooms1", 0)
    venv = FeatureVecEnv(homing(), "rec-sm", encoder)
    obs = venv.reset()
    for i, info in enumerate(venv.venv.reset_infos):
        seq = [*info["excursion"]["readings"], info["readings"]]
        np.testing.assert_allclose(obs[i], z_last(encoder, seq), atol=1e-5)
        assert not np.allclose(obs[i], z_last(encoder, [info["readings"]]), atol=1e-3)


def command(a: np.ndarray) -> np.ndarray:
    return np.array([(a[0] + 1) / 2 * MAX_STEP, a[1] * MAX_TURN])


def test_rec_sma_reads_the_commands_of_the_excursion_and_of_the_agent():
    encoder = _frozen(build_model("rec-sma", seed=0))  # no shipped run: untrained weights
    venv = FeatureVecEnv(homing(n=2), "rec-sma", encoder)
    obs = venv.reset()
    infos = venv.venv.reset_infos
    readings = [[*info["excursion"]["readings"], info["readings"]] for info in infos]
    motors = [list(info["excursion"]["motors"]) for info in infos]
    for i in range(2):  # the last motor slot is not read at the last step: any value
        np.testing.assert_allclose(obs[i], z_last(encoder, readings[i], [*motors[i], [0, 0]]),
                                   atol=1e-5)  # fmt: skip
    rng = np.random.default_rng(0)
    for _ in range(3):
        a = rng.uniform(-1, 1, (2, 2)).astype(np.float32)
        obs, _, dones, step_infos = venv.step(a)
        assert not dones.any()
        for i in range(2):
            readings[i].append(step_infos[i]["readings"])
            motors[i].append(command(a[i].astype(np.float64)))
            ref = z_last(encoder, readings[i], [*motors[i], [0, 0]])
            np.testing.assert_allclose(obs[i], ref, atol=1e-5)
    # the commands matter: the same readings with other commands give other features
    other = z_last(encoder, readings[0], [*np.zeros((len(motors[0]), 2)), [0, 0]])
    assert not np.allclose(obs[0], other, atol=1e-4)


def test_the_oracle_pose_raw_knows_where_the_episode_started():
    venv = FeatureVecEnv(homing(), "pose+raw")
    obs = venv.reset()
    for i, info in enumerate(venv.venv.reset_infos):
        x0, y0 = info["excursion"]["poses"][0][:2]
        np.testing.assert_allclose(obs[i, 9:], [x0 / 25 - 1, y0 / 25 - 1], rtol=1e-6)
        np.testing.assert_allclose(obs[i, 4:9], info["readings"] / 10, rtol=1e-6)


def test_a_tiny_homing_grid_runs_with_the_oracle_and_gives_the_same_bytes(tmp_path):
    ppo = {"n_steps": 32, "batch_size": 64, "n_epochs": 1, "learning_rate": 3e-4,
           "gamma": 0.99, "gae_lambda": 0.95, "ent_coef": 0.0}  # fmt: skip
    config = RLConfig(task="homing", features=("raw", "pose+raw"), seeds=1, steps=64,
                      eval_every=64, eval_episodes=2, n_envs=2, stats_steps=64,
                      transfer=("rooms2",), ppo=ppo)  # fmt: skip
    rl = run_grid(config, tmp_path / "a")
    assert len(rl["results"]["pose+raw"]["spread"]["sd"]) == 11
    assert set(rl["results"]["raw"]["transfer"]) == {"rooms2"}
    run_grid(config, tmp_path / "b")
    assert (tmp_path / "a" / "rl.json").read_bytes() == (tmp_path / "b" / "rl.json").read_bytes()
