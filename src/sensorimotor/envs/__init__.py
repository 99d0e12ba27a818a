"""Gymnasium environments; importing this module registers them.

>>> import gymnasium as gym
>>> import sensorimotor.envs
>>> env = gym.make("sensorimotor/LaserWorld-v0", world="rooms1")
>>> task = gym.make("sensorimotor/LaserCorner-v0", world="rooms1")  # also Doorway, Explore

Each task of ``tasks.TASKS`` has its id (``Task.env_id``), registered with it
(``tasks.register``).

``gym.make("sensorimotor.envs:sensorimotor/LaserWorld-v0")`` imports this module itself.
"""

from __future__ import annotations

import gymnasium as gym

from sensorimotor.envs.laser_world import LaserWorldEnv, paper_policy
from sensorimotor.envs.tasks import TASKS, LaserTaskEnv, Task, register

LASER_WORLD_ID = "sensorimotor/LaserWorld-v0"

if LASER_WORLD_ID not in gym.registry:  # importlib.reload must not re-register (a warning)
    gym.register(
        id=LASER_WORLD_ID,
        entry_point="sensorimotor.envs.laser_world:LaserWorldEnv",
        max_episode_steps=10_000,
    )

__all__ = [
    "LASER_WORLD_ID", "TASKS", "LaserTaskEnv", "LaserWorldEnv", "Task", "paper_policy", "register",
]  # fmt: skip
