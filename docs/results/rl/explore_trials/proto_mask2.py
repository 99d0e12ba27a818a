"""Prototype: pose + the visited mask (the task's state) for explore; PPO settings as proto_ppo."""

import os

import numpy as np
from gymnasium import spaces

import sensorimotor.rl.features as F
import sensorimotor.rl.vec_env as V

orig_one = V.TaskVecEnv._reset_one


def reset_one(self, i, seed=None):
    if not hasattr(self, "last_visited"):
        self.last_visited = np.zeros_like(self.visited)
    self.last_visited[i] = self.visited[i]
    return orig_one(self, i, seed)


V.TaskVecEnv._reset_one = reset_one

orig_init, orig_reset, orig_step = (
    F.FeatureVecEnv.__init__,
    F.FeatureVecEnv.reset,
    F.FeatureVecEnv.step_wait,
)


def on(self):
    return self.features in os.environ.get("MASKED", "pose").split(",")


def init(self, venv, features, encoder=None):
    orig_init(self, venv, features, encoder)
    if on(self):
        n = self.observation_space.shape[0] + 100
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(n,), dtype=np.float32)


def mask(v):
    return v.reshape(len(v), -1).astype(np.float32)


def reset(self):
    o = orig_reset(self)
    return np.concatenate([o, mask(self.venv.visited)], 1) if on(self) else o


def step_wait(self):
    obs, r, d, infos = orig_step(self)
    if not on(self):
        return obs, r, d, infos
    for i in np.flatnonzero(d):
        infos[i]["terminal_observation"] = np.concatenate(
            [infos[i]["terminal_observation"], mask(self.venv.last_visited[i : i + 1])[0]]
        )
    return np.concatenate([obs, mask(self.venv.visited)], 1), r, d, infos


F.FeatureVecEnv.__init__, F.FeatureVecEnv.reset, F.FeatureVecEnv.step_wait = init, reset, step_wait

import proto_ppo  # noqa: E402, F401  (PPO settings from the environment, then the command line)
