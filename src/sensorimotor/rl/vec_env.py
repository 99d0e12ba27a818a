"""N task environments stepped together: one simulator call and array arithmetic per step.

``TaskVecEnv`` is a stable-baselines3 ``VecEnv`` over N ``LaserTaskEnv`` (``envs.tasks``) that
gives, step for step, what ``make_vec_env`` gives over ``gym.make`` of the same task (a
``DummyVecEnv`` of ``Monitor(TimeLimit(...))``; ``tests/rl/test_vec_env.py`` checks it bit for
bit): the same observations, rewards, ends, ``is_success``, ``terminal_observation`` and
``TimeLimit.truncated``, and the same starts, each environment drawing from its own
``np_random`` seeded ``seed + i``. What differs is the cost: ``DummyVecEnv`` calls each
environment's ``step`` in turn through four wrappers, three ray casts and Python arithmetic
each; here the motion, the collision check and the readings of all N robots are one call of
the simulation core (``sim.core.move_many``, the same ray caster and motion as
``LaserWorldEnv.step``) and the task's rewards one call of ``envs.tasks.task_step``, the
scoring ``LaserTaskEnv.step`` runs with N = 1, which reads the task's ``Task`` object
(``envs.tasks.TASKS``): any registered task runs here as it runs there. Environments whose
episode ended are reset one by one by their own ``LaserTaskEnv.reset`` (its start rules).

``info`` holds what the learning loop reads: ``pose``, ``readings``, ``collision``,
``is_success``, ``coverage``, and at an episode's end ``episode`` (Monitor's return and
length, for the logs), ``terminal_observation`` and ``TimeLimit.truncated``. Noise is not
supported (the tasks run noiseless).
"""

from __future__ import annotations

import time

import numpy as np
from stable_baselines3.common.vec_env import VecEnv

from sensorimotor.envs.laser_world import MAX_STEP, MAX_TURN, WALL_MARGIN
from sensorimotor.envs.tasks import GRID, LaserTaskEnv, Task, measure, task_step
from sensorimotor.sim import core as sim
from sensorimotor.sim.world import World


class TaskVecEnv(VecEnv):
    """``n`` environments of ``task`` (a name in ``envs.tasks.TASKS`` or a ``Task``) in
    ``world``, truncated after ``budget`` steps (default: the task's, ``Task.budget``); module
    doc."""

    def __init__(self, task: str | Task, world: str | World, n: int, budget: int | None = None):
        self.envs = [LaserTaskEnv(task, world) for _ in range(n)]
        first = self.envs[0]
        super().__init__(n, first.observation_space, first.action_space)
        self.task, self.world = first.task, first.world  # the Task object
        self.budget = self.task.budget if budget is None else int(budget)
        self.render_mode = None
        self.poses = np.zeros((n, 3))  # (N, 3) x, y, heading
        self.start_room = np.full(n, -1)  # (N,) index in world.rooms where the episode started
        self.visited = np.zeros((n, GRID, GRID), dtype=bool)  # cells entered this episode
        self.done = np.zeros(n, dtype=bool)  # the task is done so far
        self.steps = np.zeros(n, dtype=int)  # steps into the episode
        self.returns = np.zeros(n)  # the episode's return so far (Monitor's)
        self.readings = np.zeros((n, len(first.angles)))  # (N, R) noiseless, float64
        self.actions = np.zeros((n, 2))
        self._seeds: list[int | None] = [None] * n
        self._start = time.perf_counter()

    # --- the batch's state <-> one environment ----------------------------------------------
    def _reset_one(self, i: int, seed: int | None = None) -> tuple[np.ndarray, dict]:
        observation, info = self.envs[i].reset(seed=seed)
        env = self.envs[i]
        self.poses[i] = env.pose
        self.readings[i] = info["readings"]
        self.start_room[i] = env.start_room
        self.visited[i] = env.visited
        self.done[i] = False
        self.steps[i] = 0
        self.returns[i] = 0.0
        info = self._info(i, False)
        if env.excursion is not None:  # the task drove the robot before the agent's first step
            info["excursion"] = env.excursion
        return observation, info

    def _info(self, i: int, collision: bool) -> dict:
        return {
            "pose": self.poses[i].copy(),
            "readings": self.readings[i].copy(),
            "collision": bool(collision),
            "is_success": bool(self.done[i]),
            "coverage": float(self.visited[i].mean()),
        }

    # --- VecEnv ---------------------------------------------------------------------------
    def reset(self) -> np.ndarray:
        obs = np.zeros((self.num_envs, *self.observation_space.shape), dtype=np.float32)
        self.reset_infos = [{} for _ in range(self.num_envs)]
        for i in range(self.num_envs):
            obs[i], self.reset_infos[i] = self._reset_one(i, self._seeds[i])
        self._seeds = [None] * self.num_envs  # as DummyVecEnv: a seed is used once
        return obs

    def seed(self, seed: int | None = None) -> list[int | None]:
        self._seeds = [None if seed is None else seed + i for i in range(self.num_envs)]
        return self._seeds

    def step_async(self, actions: np.ndarray) -> None:
        self.actions = np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 2)

    def step_wait(self):
        if not np.isfinite(self.actions).all():
            raise ValueError(f"actions must be finite numbers in [-1, 1], got {self.actions!r}")
        a = np.clip(self.actions, -1.0, 1.0)  # (N, 2)
        d = (a[:, 0] + 1.0) / 2.0 * MAX_STEP  # (N,) units
        r = a[:, 1] * MAX_TURN  # (N,) rad
        env = self.envs[0]
        before = measure(env, self.poses)  # the task's quantity before the move, if any
        hit = np.zeros(self.num_envs, dtype=np.bool_)
        sim.move_many(
            env.segments, self.poses, d, r, env.ahead_range, WALL_MARGIN, env.angles,
            env.max_range, self.readings, hit,
        )  # fmt: skip
        rewards, terminated, self.done = task_step(
            env, self.poses, before, self.start_room, self.visited
        )  # the tasks' scoring, on every environment at once
        obs = np.clip(self.readings, 0.0, env.max_range).astype(np.float32)  # (N, R)
        self.steps += 1
        self.returns += rewards
        truncated = (self.steps >= self.budget) & ~terminated
        dones = terminated | truncated
        infos = [self._info(i, hit[i]) for i in range(self.num_envs)]
        for i in np.flatnonzero(dones):
            infos[i]["episode"] = {
                "r": float(self.returns[i]),
                "l": int(self.steps[i]),
                "t": round(time.perf_counter() - self._start, 6),
            }
            infos[i]["TimeLimit.truncated"] = bool(truncated[i])
            infos[i]["terminal_observation"] = obs[i].copy()
            obs[i], self.reset_infos[i] = self._reset_one(i)
        return obs, rewards.astype(np.float32), dones, infos

    # --- the rest of VecEnv's interface ------------------------------------------------------
    def close(self) -> None:
        for env in self.envs:
            env.close()

    def get_attr(self, attr_name: str, indices=None) -> list:
        return [getattr(self.envs[i], attr_name) for i in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value, indices=None) -> None:
        for i in self._get_indices(indices):
            setattr(self.envs[i], attr_name, value)

    def env_method(self, method_name: str, *args, indices=None, **kwargs) -> list:
        return [
            getattr(self.envs[i], method_name)(*args, **kwargs) for i in self._get_indices(indices)
        ]

    def env_is_wrapped(self, wrapper_class, indices=None) -> list[bool]:
        return [False for _ in self._get_indices(indices)]

    def get_images(self) -> list:
        return [None for _ in range(self.num_envs)]
