"""Three navigation tasks for the laser robot, to ask whether a representation helps it act."""

from __future__ import annotations

from pathlib import Path
from typing import Any, ClassVar

import numpy as np
from gymnasium import spaces

from sensorimotor.envs.laser_world import MAX_STEP, MAX_TURN, LaserWorldEnv
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.events import corner_in_view, corner_points
from sensorimotor.sim.world import World, point_in_polygon

TASKS = ("corner", "doorway", "explore")
BUDGETS = {"corner": 200, "doorway": 300, "explore": 400}  # steps before truncation
CORNER_REACH = 2.0  # units; a corner counts as reached within this distance, in view
CORNER_PROGRESS = 0.05  # reward per unit of progress toward the nearest corner
GRID = 10  # explore: the world is cut into GRID x GRID cells
CELL_REWARD = 0.1  # explore: reward per newly visited cell
EXPLORE_SUCCESS = 0.4  # explore: success when at least this fraction of the cells is visited
MAX_START_DRAWS = 1000  # start poses drawn before giving up on a world where the task is done


class LaserTaskEnv(LaserWorldEnv):
    """
    ## Description

    The laser robot of ``LaserWorld-v0`` (same worlds, sensors, physics and collisions: this
    class only adds a task on top) given one of three tasks, to measure whether a learned
    representation helps an agent act (the paper's conclusion):

    - ``corner``: reach any corner where two walls meet (``sim.events.corner_points``): be
      within 2 units of it, facing it: ``sim.events.corner_in_view`` with a 2-unit range, so the
      corner lies in the sensor fan (+-0.6 rad), in plain sight, seen as a concave corner.
    - ``doorway``: start in one named room of the world (``World.rooms``) and reach any other.
      Needs a world that names at least two rooms (``rooms1``, ``rooms2`` do; ``square`` names
      one).
    - ``explore``: visit as many cells as possible of a 10 x 10 grid laid over the world.

    ## Action Space

    ``Box(-1, 1, (2,), float32)``, rescaled to the motor command ``(d, r)`` of ``LaserWorld-v0``:

    | Num | Action                         | -1 means                | +1 means               |
    |-----|--------------------------------|-------------------------|------------------------|
    | 0   | ``d = (a0 + 1) / 2``           | no translation          | 1 unit forward         |
    | 1   | ``r = 1.1 pi a1``              | turn 1.1 pi clockwise   | turn 1.1 pi ccw        |

    Actions outside the box are clipped to it. Whatever the action, the robot never crosses a
    wall nor leaves the world (the translation stops 1e-6 short of the wall ahead, as in
    ``LaserWorld-v0``; ``info["collision"]`` says so).

    ## Observation Space

    The 5 laser readings, ``float32`` in ``[0, 10]``, as in ``LaserWorld-v0``. ``info["pose"]``
    holds the true pose ``(x, y, heading)``: the oracle features of ``sensorimotor.rl``.

    ## Rewards

    - ``corner``: ``+1`` on reaching a corner, plus ``0.05`` per unit of progress toward the
      nearest corner (``0.05 (dist_before - dist_after)``, negative when moving away).
    - ``doorway``: ``+1`` on entering another room, 0 otherwise.
    - ``explore``: ``+0.1`` for each grid cell entered for the first time (the start cell counts
      as visited).

    ## Starting State

    A pose drawn as in ``LaserWorld-v0`` (``sim.sample_start``); ``corner`` redraws it while the
    task is already done there, ``doorway`` while it lies in no named room.
    ``reset(options={"pose": ...})`` starts at a given pose instead.

    ## Episode End

    1. Termination: ``corner`` and ``doorway`` on success; ``explore`` never.
    2. Truncation: after the task's step budget (corner 200, doorway 300, explore 400 steps),
       by the ``TimeLimit`` wrapper that ``gymnasium.make`` adds.

    ``info["is_success"]`` is in every ``info`` and says whether the task is done so far: a
    corner or another room reached; for ``explore``, at least 40 % of the cells visited (the
    paper's random behaviour, driven through this action box, covers a median 26 % in
    ``rooms1`` and never reached 40 % in 200 episodes). ``info["coverage"]`` gives the fraction
    visited. Read at an episode's last step it is the episode's success, what
    stable-baselines3's ``EvalCallback`` reads.

    ## Arguments

    ```python
    >>> import gymnasium as gym
    >>> import sensorimotor.envs  # registers the tasks
    >>> env = gym.make("sensorimotor/LaserCorner-v0", world="rooms1")
    >>> observation, info = env.reset(seed=0)
    >>> bool(info["is_success"])
    False

    ```

    ``task`` (``"corner"``, ``"doorway"``, ``"explore"``; each id passes its own), ``world``,
    ``noise`` and ``render_mode`` as in ``LaserWorld-v0``; ``max_episode_steps`` to
    ``gym.make`` changes the budget.

    ## Version History

    * v0: Initial version.
    """

    metadata: ClassVar[dict[str, Any]] = LaserWorldEnv.metadata

    def __init__(
        self,
        task: str = "corner",
        world: str | Path | World = "rooms1",
        noise: float = 0.0,
        render_mode: str | None = None,
    ):
        if task not in TASKS:
            raise InputError(f"unknown task {task!r}: use one of {', '.join(TASKS)}")
        super().__init__(world, noise, render_mode)
        self.task = task
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.corners = corner_points(self.world)  # (C, 2)
        self.reach_layout = sim.SensorLayout(angles=tuple(self.angles), max_range=CORNER_REACH)
        if task == "doorway" and len(self.world.rooms) < 2:
            raise InputError(
                f"task doorway needs a world with at least two named rooms; world "
                f"{self.world.name!r} names {len(self.world.rooms)}"
            )
        self.visited = np.zeros((GRID, GRID), dtype=bool)  # explore: cells entered
        self.start_room = -1  # doorway: index in world.rooms
        self.done = False  # the task is done (success so far)

    # --- the task: what it measures at a pose ---------------------------------------------
    def _corner_distance(self) -> float:
        return float(corner_distances(self.corners, np.array([self.pose]))[0])

    def _at_corner(self) -> bool:
        if self._corner_distance() > CORNER_REACH:  # cheap test first: no ray cast
            return False
        return bool(corner_in_view(self.world, np.array([self.pose]), self.reach_layout)[0])

    def _cell(self) -> tuple[int, int]:
        i, j = grid_cells(self.world, np.array([self.pose]))
        return int(i[0]), int(j[0])

    def _task_info(self, info: dict[str, Any]) -> dict[str, Any]:
        info["is_success"] = self.done
        info["coverage"] = float(self.visited.mean())
        return info

    # --- Gymnasium API ----------------------------------------------------------------------
    def step(self, action):
        action = np.asarray(action, dtype=np.float64)
        if action.size != 2 or not np.isfinite(action).all():
            raise ValueError(f"action must be 2 finite numbers in [-1, 1], got {action!r}")
        a = np.clip(action.reshape(2), -1.0, 1.0)
        command = np.array([(a[0] + 1.0) / 2.0 * MAX_STEP, a[1] * MAX_TURN])  # (d, r)
        before = np.array([self._corner_distance()]) if self.task == "corner" else None
        observation, _, _, _, info = super().step(command)
        rewards, terminated, done = task_step(
            self, np.array([self.pose]), before, np.array([self.start_room]), self.visited[None]
        )
        self.done = bool(done[0])
        return observation, float(rewards[0]), bool(terminated[0]), False, self._task_info(info)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        observation, info = super().reset(seed=seed, options=options)  # seeds, draws a pose
        if (options or {}).get("pose") is None and not self._good_start():
            for _ in range(MAX_START_DRAWS):
                self.pose = sim.sample_start(self.world, self.np_random)
                if self._good_start():
                    break
            else:
                raise InputError(f"world {self.world.name!r}: no start pose for task {self.task}")
            observation, info = self._observe(), self._info(False)
        self.start_room = self._room()
        self.visited[:] = False
        self.visited[self._cell()] = True
        self.done = False
        return observation, self._task_info(info)

    def _room(self) -> int:
        """Index in ``world.rooms`` of the room holding the agent, -1 for none."""
        return int(self.world.room_index(np.array([self.pose[0]]), np.array([self.pose[1]]))[0])

    def _good_start(self) -> bool:
        if self.task == "corner":
            return not self._at_corner()
        if self.task == "doorway":
            return self._room() >= 0
        return True


def corner_distances(corners: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N,) distance from each pose (N, 3) to its nearest corner (C, 2)."""
    dx = corners[None, :, 0] - poses[:, 0, None]  # (N, C)
    dy = corners[None, :, 1] - poses[:, 1, None]
    return np.hypot(dx, dy).min(axis=1)


def grid_cells(world: World, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The explore grid's cell (i, j), (N,) each, of each pose (N, 3)."""
    i = np.clip((poses[:, 0] / world.width * GRID).astype(int), 0, GRID - 1)
    j = np.clip((poses[:, 1] / world.height * GRID).astype(int), 0, GRID - 1)
    return i, j


def task_step(
    env: LaserTaskEnv,
    poses: np.ndarray,
    before: np.ndarray | None,
    start_room: np.ndarray,
    visited: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The task's rewards (N,), terminations (N,) and success so far (N,) of N robots of
    ``env``'s task and world that have just moved to ``poses`` (N, 3); ``before`` (N,) their
    corner distances before the move (corner), ``start_room`` (N,) (doorway), ``visited``
    (N, GRID, GRID) updated in place (explore). ``LaserTaskEnv.step`` (N = 1) and
    ``rl.vec_env.TaskVecEnv`` both score through it (the class docstring's Rewards)."""
    n = len(poses)
    rewards, terminated = np.zeros(n), np.zeros(n, dtype=bool)
    x, y = poses[:, 0], poses[:, 1]
    if env.task == "corner":
        after = corner_distances(env.corners, poses)
        rewards = CORNER_PROGRESS * (before - after)
        near = np.flatnonzero(after <= CORNER_REACH)  # cheap test first: no ray cast
        if near.size:
            terminated[near[corner_in_view(env.world, poses[near], env.reach_layout)]] = True
        return rewards + terminated, terminated, terminated.copy()  # +1 on reaching a corner
    if env.task == "doorway":
        room = env.world.room_index(x, y)  # (N,)
        for k in np.unique(start_room):
            mine = np.flatnonzero(start_room == k)
            still = point_in_polygon(env.world.rooms[k].polygon, x[mine], y[mine])
            terminated[mine] = ~still & (room[mine] >= 0)  # in another named room
        return terminated.astype(np.float64), terminated, terminated.copy()
    i, j = grid_cells(env.world, poses)
    rows = np.arange(n)
    new = ~visited[rows, i, j]
    visited[rows, i, j] = True
    rewards = np.where(new, CELL_REWARD, 0.0)
    return rewards, terminated, visited.mean(axis=(1, 2)) >= EXPLORE_SUCCESS
