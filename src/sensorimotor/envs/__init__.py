"""Gymnasium environments; importing this module registers them.

>>> import gymnasium as gym
>>> import sensorimotor.envs
>>> env = gym.make("sensorimotor/LaserWorld-v0", world="rooms1")
>>> task = gym.make("sensorimotor/LaserCorner-v0", world="rooms1")  # also Doorway, Explore

``gym.make("sensorimotor.envs:sensorimotor/LaserWorld-v0")`` imports this module itself.
"""

from __future__ import annotations

import gymnasium as gym

from sensorimotor.envs.laser_world import LaserWorldEnv, paper_policy
from sensorimotor.envs.tasks import BUDGETS, TASKS, LaserTaskEnv

LASER_WORLD_ID = "sensorimotor/LaserWorld-v0"

if LASER_WORLD_ID not in gym.registry:  # importlib.reload must not re-register (a warning)
    gym.register(
        id=LASER_WORLD_ID,
        entry_point="sensorimotor.envs.laser_world:LaserWorldEnv",
        max_episode_steps=10_000,
    )

# the tasks: one id each, truncated after the task's step budget (see LaserTaskEnv)
TASK_IDS = {task: f"sensorimotor/Laser{task.capitalize()}-v0" for task in TASKS}
for _task, _id in TASK_IDS.items():
    if _id not in gym.registry:
        gym.register(
            id=_id,
            entry_point="sensorimotor.envs.tasks:LaserTaskEnv",
            max_episode_steps=BUDGETS[_task],
            kwargs={"task": _task},
        )

__all__ = ["LASER_WORLD_ID", "TASK_IDS", "LaserTaskEnv", "LaserWorldEnv", "paper_policy"]
