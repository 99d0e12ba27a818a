"""The batched task environments give, bit for bit, what stable-baselines3's ``DummyVecEnv``
over ``gym.make`` of the same task gives: observations, rewards, ends, successes, the
terminal observation and truncation flag, the next episode's start."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv

from sensorimotor.envs import TASKS
from sensorimotor.envs.tasks import Task, register, unregister
from sensorimotor.rl.vec_env import TaskVecEnv


@pytest.mark.parametrize(
    ("task", "world", "budget", "steps"),
    [
        ("corner", "rooms1", 60, 1500),
        ("doorway", "rooms1", 40, 300),
        ("explore", "rooms2", 25, 100),
        ("homing", "rooms1", 30, 200),
    ],
)
def test_batched_environments_step_as_the_plain_ones(task, world, budget, steps):
    n = 6
    plain = DummyVecEnv(
        [lambda: Monitor(gym.make(TASKS[task].env_id, world=world, max_episode_steps=budget))] * n
    )
    batched = TaskVecEnv(task, world, n, budget)
    plain.seed(3)
    batched.seed(3)
    np.testing.assert_array_equal(plain.reset(), batched.reset())
    actions = np.random.default_rng(0).uniform(-1.2, 1.2, (steps, n, 2)).astype(np.float32)
    ends = successes = 0
    for a in actions:  # outside the box too: clipped alike
        o1, r1, d1, i1 = plain.step(a)
        o2, r2, d2, i2 = batched.step(a)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        for k, (x, y) in enumerate(zip(i1, i2, strict=True)):
            np.testing.assert_array_equal(x["pose"], y["pose"])
            assert (x["is_success"], x["coverage"]) == (y["is_success"], y["coverage"])
            if d1[k]:
                np.testing.assert_array_equal(x["terminal_observation"], y["terminal_observation"])
                assert x["TimeLimit.truncated"] == y["TimeLimit.truncated"]
                assert x["episode"]["l"] == y["episode"]["l"]
                np.testing.assert_array_equal(
                    plain.reset_infos[k]["pose"], batched.reset_infos[k]["pose"]
                )
                if task == "homing":  # the next episode's excursion, bit for bit
                    for part in ("readings", "motors", "poses"):
                        np.testing.assert_array_equal(
                            plain.reset_infos[k]["excursion"][part],
                            batched.reset_infos[k]["excursion"][part],
                        )
                ends += 1
                successes += x["is_success"]
    assert ends > n  # every environment ended an episode and went on
    if task not in ("explore", "homing"):  # no 40 % coverage in 25 steps; rarely home in 30
        assert successes > 0  # episodes ended by the task, not only by the budget


# --- a task registered in one place runs in both paths -------------------------------------
def _step_cost(env, episodes) -> np.ndarray:
    return np.full(len(episodes.poses), -0.01)


def _facing_east(env, episodes) -> np.ndarray:
    return np.abs(episodes.poses[:, 2]) < 0.3


def _not_facing_east(env) -> bool:
    return abs(env.pose[2]) >= 0.3


@pytest.fixture
def toy_task():
    """Turn to face east (heading within 0.3 rad of 0): -0.01 a step, +1 on success."""
    task = register(Task("east", 20, _step_cost, _facing_east, good_start=_not_facing_east))
    yield task
    unregister(task.name)
    assert "east" not in TASKS


def test_a_registered_task_runs_in_the_plain_and_the_batched_environment(toy_task):
    env = gym.make(toy_task.env_id, world="square")
    assert env.spec.max_episode_steps == 20
    rng = np.random.default_rng(0)
    _, info = env.reset(seed=0)
    assert abs(info["pose"][2]) >= 0.3  # its start rule
    rewards, done = [], False
    while not done:
        _, reward, terminated, truncated, info = env.step(rng.uniform(-1, 1, 2))
        rewards.append(reward)
        done = terminated or truncated
    assert terminated  # faced east before the budget
    assert info["is_success"]
    assert rewards == [-0.01] * (len(rewards) - 1) + [-0.01 + 1.0]

    n = 4
    plain = DummyVecEnv([lambda: Monitor(gym.make(toy_task.env_id, world="square"))] * n)
    batched = TaskVecEnv("east", "square", n)
    assert batched.budget == 20
    plain.seed(5)
    batched.seed(5)
    np.testing.assert_array_equal(plain.reset(), batched.reset())
    successes = 0
    for a in rng.uniform(-1, 1, (100, n, 2)).astype(np.float32):
        o1, r1, d1, i1 = plain.step(a)
        o2, r2, d2, i2 = batched.step(a)
        np.testing.assert_array_equal(o1, o2)
        np.testing.assert_array_equal(r1, r2)
        np.testing.assert_array_equal(d1, d2)
        assert [x["is_success"] for x in i1] == [y["is_success"] for y in i2]
        successes += sum(x["is_success"] for x in i1)
    assert successes > 0
