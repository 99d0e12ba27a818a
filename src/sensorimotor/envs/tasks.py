"""Navigation tasks for the laser robot, to ask whether a representation helps it act.

A task is one ``Task`` object (name, step budget, start rule, reward, success test) in one
registry, ``TASKS``; ``register`` adds one, with its Gymnasium id. ``LaserTaskEnv`` (one robot)
and ``rl.vec_env.TaskVecEnv`` (N robots at once) read the object and score every move through
one function, ``task_step``.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sensorimotor.envs.laser_world import MAX_STEP, MAX_TURN, LaserWorldEnv
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.events import corner_in_view, corner_points
from sensorimotor.sim.world import World, point_in_polygon

CORNER_REACH = 2.0  # units; a corner counts as reached within this distance, in view
CORNER_PROGRESS = 0.05  # reward per unit of progress toward the nearest corner
GRID = 10  # the world is cut into GRID x GRID cells (explore's reward, info["coverage"])
CELL_REWARD = 0.1  # explore: reward per newly visited cell
EXPLORE_SUCCESS = 0.4  # explore: success when at least this fraction of the cells is visited
MAX_START_DRAWS = 1000  # start poses drawn before giving up on a world where the task is done
EXCURSION_EXTRA = 20  # homing: steps the excursion goes on after first entering another room
EXCURSION_CAP = 2_000  # homing: steps an excursion may take before its start is redrawn
EXCURSION_CHUNK = 256  # homing: the excursion's walk is run this many steps at a time
HOMING_BUDGET = 200  # homing: the agent's steps to come back (a straight line across Rooms1: ~50)


@dataclass
class Episodes:
    """N episodes of one task under way, as a task's functions read and write them: the scalar
    ``LaserTaskEnv`` passes N = 1, ``rl.vec_env.TaskVecEnv`` its N environments."""

    poses: np.ndarray
    """(N, 3) x, y, heading, just after the move being scored."""
    before: np.ndarray | None
    """(N,) what the task's ``measure`` gave just before the move (None: it has none)."""
    start_room: np.ndarray
    """(N,) index in ``world.rooms`` of the room each episode started in, -1 for none."""
    visited: np.ndarray
    """(N, GRID, GRID) the grid cells entered this episode (a reward may mark them)."""


def _anywhere(env: LaserTaskEnv) -> bool:
    return True


def _any_world(world: World) -> str | None:
    return None


@dataclass(frozen=True)
class Task:
    """One task: everything ``LaserTaskEnv`` and ``TaskVecEnv`` know of it. Its functions take
    the task's environment (``LaserTaskEnv``: the world, its corners, the sensor layout)."""

    name: str
    """In commands, Gymnasium ids (``env_id``) and output folders."""
    budget: int
    """Steps per episode before truncation (``TimeLimit``'s ``max_episode_steps``)."""
    reward: Callable[[LaserTaskEnv, Episodes], np.ndarray]
    """(N,) the reward of each episode's move, the success bonus aside; may update the
    episodes' state (explore marks the cells entered)."""
    success: Callable[[LaserTaskEnv, Episodes], np.ndarray]
    """(N,) bool: the task done so far, read after ``reward``."""
    success_reward: float = 1.0
    """Added to the reward of a move after which ``success`` holds."""
    terminates: bool = True
    """Success ends the episode."""
    good_start: Callable[[LaserTaskEnv], bool] = _anywhere
    """Whether an episode may start at ``env.pose``; ``reset`` redraws the pose until it may."""
    measure: Callable[[LaserTaskEnv, np.ndarray], np.ndarray] | None = None
    """(N,) a quantity of the poses (N, 3) taken before each move, ``Episodes.before``."""
    check: Callable[[World], str | None] = _any_world
    """Why a world cannot hold the task (completes "task NAME ..."), None when it can."""
    excursion: Callable[[LaserTaskEnv], dict | None] | None = None
    """Run by ``reset`` after the start is drawn: drives the robot (not the agent) from there
    and returns what it read, did and where (``{"readings" (E, R), "motors" (E, 2), "poses"
    (E, 3)}``, row t: the reading at pose t and the command taken from it; the agent's first
    observation is read where it ends), or None when it failed (the start is redrawn).
    ``reset``'s ``info["excursion"]`` holds it, for a feature wrapper to feed a memory."""
    no_memory: Callable[[str | World], dict] | None = None
    """What an agent without memory reaches in a world with no learning at all (``{"what",
    "success", ...}``), where the task knows it: the baseline ``rl.json`` shows beside a task
    that asks for a memory."""

    @property
    def env_id(self) -> str:
        """Its Gymnasium id, e.g. ``sensorimotor/LaserCorner-v0``."""
        return f"sensorimotor/Laser{self.name.capitalize()}-v0"


TASKS: dict[str, Task] = {}
"""Every task by name; add one with ``register``."""


def register(task: Task) -> Task:
    """Add ``task`` to ``TASKS`` and its ``env_id`` to Gymnasium's registry (truncated after its
    budget): from here on ``LaserTaskEnv``, ``TaskVecEnv``, ``gym.make`` and ``sensorimotor rl``
    take its name."""
    if task.name in TASKS:
        raise ValueError(f"task {task.name!r} is already taken")
    TASKS[task.name] = task
    if task.env_id not in gym.registry:  # importlib.reload must not re-register (a warning)
        gym.register(
            id=task.env_id,
            entry_point="sensorimotor.envs.tasks:LaserTaskEnv",
            max_episode_steps=task.budget,
            kwargs={"task": task.name},
        )
    return task


def unregister(name: str) -> None:
    """Remove a task ``register`` added, with its Gymnasium id (a test's toy task)."""
    task = TASKS.pop(name)
    gym.registry.pop(task.env_id, None)


def get_task(task: str | Task) -> Task:
    """The registered task of that name (InputError naming the known ones), or ``task``."""
    if isinstance(task, Task):
        return task
    if task not in TASKS:
        raise InputError(f"unknown task {task!r}: use one of {', '.join(TASKS)}")
    return TASKS[task]


# --- the tasks ---------------------------------------------------------------------------
def corner_distances(corners: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(N,) distance from each pose (N, 3) to its nearest corner (C, 2)."""
    dx = corners[None, :, 0] - poses[:, 0, None]  # (N, C)
    dy = corners[None, :, 1] - poses[:, 1, None]
    return np.hypot(dx, dy).min(axis=1)


def grid_cells(world: World, poses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The grid's cell (i, j), (N,) each, of each pose (N, 3)."""
    i = np.clip((poses[:, 0] / world.width * GRID).astype(int), 0, GRID - 1)
    j = np.clip((poses[:, 1] / world.height * GRID).astype(int), 0, GRID - 1)
    return i, j


def at_corner(env: LaserTaskEnv, poses: np.ndarray) -> np.ndarray:
    """(N,) bool: within ``CORNER_REACH`` of a corner, facing it (``corner_in_view``)."""
    done = np.zeros(len(poses), dtype=bool)
    near = np.flatnonzero(corner_distances(env.corners, poses) <= CORNER_REACH)  # no ray cast
    if near.size:
        done[near[corner_in_view(env.world, poses[near], env.reach_layout)]] = True
    return done


def _corner_distance(env: LaserTaskEnv, poses: np.ndarray) -> np.ndarray:
    return corner_distances(env.corners, poses)


def _corner_progress(env: LaserTaskEnv, e: Episodes) -> np.ndarray:
    return CORNER_PROGRESS * (e.before - corner_distances(env.corners, e.poses))


def _corner_done(env: LaserTaskEnv, e: Episodes) -> np.ndarray:
    return at_corner(env, e.poses)


def _not_at_corner(env: LaserTaskEnv) -> bool:
    return not at_corner(env, np.array([env.pose]))[0]


def _no_reward(env: LaserTaskEnv, e: Episodes) -> np.ndarray:
    return np.zeros(len(e.poses))


def _in_another_room(env: LaserTaskEnv, e: Episodes) -> np.ndarray:
    x, y = e.poses[:, 0], e.poses[:, 1]
    room = env.world.room_index(x, y)  # (N,)
    done = np.zeros(len(e.poses), dtype=bool)
    for k in np.unique(e.start_room):
        mine = np.flatnonzero(e.start_room == k)
        still = point_in_polygon(env.world.rooms[k].polygon, x[mine], y[mine])
        done[mine] = ~still & (room[mine] >= 0)  # in another named room
    return done


def _in_a_room(env: LaserTaskEnv) -> bool:
    return env._room() >= 0


def _two_rooms(world: World) -> str | None:
    n = len(world.rooms)
    if n >= 2:
        return None
    return f"needs a world with at least two named rooms; world {world.name!r} names {n}"


def _new_cells(env: LaserTaskEnv, e: Episodes) -> np.ndarray:
    i, j = grid_cells(env.world, e.poses)
    rows = np.arange(len(e.poses))
    new = ~e.visited[rows, i, j]
    e.visited[rows, i, j] = True
    return np.where(new, CELL_REWARD, 0.0)


def _covered(env: LaserTaskEnv, e: Episodes) -> np.ndarray:
    return e.visited.mean(axis=(1, 2)) >= EXPLORE_SUCCESS


def _in_start_room(env: LaserTaskEnv, e: Episodes) -> np.ndarray:
    x, y = e.poses[:, 0], e.poses[:, 1]
    done = np.zeros(len(e.poses), dtype=bool)
    for k in np.unique(e.start_room[e.start_room >= 0]):
        mine = np.flatnonzero(e.start_room == k)
        done[mine] = point_in_polygon(env.world.rooms[k].polygon, x[mine], y[mine])
    return done


def drive_out(env: LaserTaskEnv) -> dict | None:
    """Homing's excursion: the paper's random behaviour drives the robot from its start until
    it has been in a named room other than the start room for ``EXCURSION_EXTRA`` steps
    (counted from its first entry; it ends at the first step after that at which it is in
    such a room); None when the start is in no room or the robot is not there within
    ``EXCURSION_CAP`` steps. The walk is the simulator's own (``sim.core``'s paper behaviour,
    noiseless; it never meets a wall, so the agent's physics would move it alike), run in
    chunks of ``EXCURSION_CHUNK`` steps on uniforms from ``env.np_random`` (two a step, as
    ``laser_world.paper_policy`` draws them) and cut where the rule ends it."""
    start = env._room()
    if start < 0:
        return None
    if env._walk is None:
        grid = sim.for_rays(env.world.grid, len(env.segments), len(env.angles))
        env._walk = grid.arrays()
    pose = env.pose
    parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    entered, done = None, 0  # the step it first stood in another room; steps walked
    while done < EXCURSION_CAP:
        n = min(EXCURSION_CHUNK, EXCURSION_CAP - done)
        readings, motors, poses, pose = sim.walk(
            env.segments, env._walk, env.angles, env.max_range, pose, env.np_random.random((n, 2))
        )
        parts.append((readings, motors, poses))
        rooms = env.world.room_index(poses[:, 0], poses[:, 1])  # (n,)
        away = np.flatnonzero((rooms >= 0) & (rooms != start)) + done  # steps in another room
        if entered is None and away.size:
            entered = int(away[0])
        late = away[away >= entered + EXCURSION_EXTRA] if entered is not None else away[:0]
        done += n
        if late.size:  # the agent starts at step ``end``: the excursion is the steps before
            end = int(late[0])
            r, m, q = (np.concatenate([part[k] for part in parts]) for k in range(3))
            env.pose = tuple(float(v) for v in q[end])
            return {"readings": r[:end].astype(np.float32), "motors": m[:end], "poses": q[:end]}
    return None


HANDOVER_RESETS = 1_000  # homing's resets counted for its memoryless baseline (about 2 s)


def handovers(world: str | World, resets: int, seed: int = 0) -> np.ndarray:
    """(rooms, rooms) counts of (start room, room at the hand-over) over ``resets`` resets of
    the homing task in ``world`` (seeds ``seed``, ``seed + 1``, ...): what the room an agent
    is handed over in says about the room it must come back to."""
    env = LaserTaskEnv("homing", world)
    counts = np.zeros((len(env.world.rooms),) * 2, dtype=np.int64)
    for i in range(resets):
        env.reset(seed=seed + i)
        counts[env.start_room, env._room()] += 1
    return counts


def memoryless_bound(counts: np.ndarray) -> float:
    """The share of episodes won by guessing the likeliest start room from the hand-over room
    (sum over hand-over rooms of the largest count in its column, over all): what an agent
    without memory reaches if it knows the room it is in and goes straight to that guess. Not
    an upper bound on memoryless agents (one may tour the rooms within the budget)."""
    return float(counts.max(axis=0).sum() / counts.sum())


def guess_from_handover(world: str | World, resets: int = HANDOVER_RESETS) -> dict:
    """Homing's memoryless baseline (``Task.no_memory``): ``handovers`` over ``resets``
    resets and the share ``memoryless_bound`` wins."""
    counts = handovers(world, resets)
    return {
        "what": "best guess of the start room from the hand-over room (no memory, no learning)",
        "success": memoryless_bound(counts),
        "resets": resets,
        "counts": counts.tolist(),
    }


CORNER = register(
    Task("corner", 200, _corner_progress, _corner_done, good_start=_not_at_corner,
         measure=_corner_distance)
)  # fmt: skip
DOORWAY = register(
    Task("doorway", 300, _no_reward, _in_another_room, good_start=_in_a_room, check=_two_rooms)
)
EXPLORE = register(Task("explore", 400, _new_cells, _covered, success_reward=0.0, terminates=False))
HOMING = register(
    Task("homing", HOMING_BUDGET, _no_reward, _in_start_room, good_start=_in_a_room,
         check=_two_rooms, excursion=drive_out, no_memory=guess_from_handover)
)  # fmt: skip


class LaserTaskEnv(LaserWorldEnv):
    """
    ## Description

    The laser robot of ``LaserWorld-v0`` (same worlds, sensors, physics and collisions: this
    class only adds a task on top) given a task, to measure whether a learned representation
    helps an agent act (the paper's conclusion). A task is a ``Task`` of the registry ``TASKS``
    (its start rule, reward, success test and budget); three are registered:

    - ``corner``: reach any corner where two walls meet (``sim.events.corner_points``): be
      within 2 units of it, facing it: ``sim.events.corner_in_view`` with a 2-unit range, so the
      corner lies in the sensor fan (+-0.6 rad), in plain sight, seen as a concave corner.
    - ``doorway``: start in one named room of the world (``World.rooms``) and reach any other.
      Needs a world that names at least two rooms (``rooms1``, ``rooms2`` do; ``square`` names
      one).
    - ``explore``: visit as many cells as possible of a 10 x 10 grid laid over the world.
    - ``homing``: start in a named room, be driven out of it by the paper's random behaviour
      (the excursion, ``drive_out``: until the robot has been in another named room for 20
      steps; the agent does not act, its features see the readings), then come back to the
      start room within 200 steps. Needs two named rooms. The start room is drawn anew each
      episode and is nowhere in the agent's observation: only a memory of the excursion (or
      of the start) tells it.

    ``register(Task(...))`` adds another, with its own Gymnasium id (``Task.env_id``).

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

    A step's reward is the task's ``reward`` plus its ``success_reward`` when the task is done
    after the step (``task_step``):

    - ``corner``: ``+1`` on reaching a corner, plus ``0.05`` per unit of progress toward the
      nearest corner (``0.05 (dist_before - dist_after)``, negative when moving away).
    - ``doorway``: ``+1`` on entering another room, 0 otherwise.
    - ``explore``: ``+0.1`` for each grid cell entered for the first time (the start cell counts
      as visited).
    - ``homing``: ``+1`` on entering the start room, 0 otherwise.

    ## Starting State

    A pose drawn as in ``LaserWorld-v0`` (``sim.sample_start``), redrawn while the task's
    ``good_start`` refuses it: ``corner`` while the task is already done there, ``doorway``
    while it lies in no named room, ``explore`` never. ``reset(options={"pose": ...})`` starts
    at a given pose instead. ``homing`` then runs its excursion (``Task.excursion``): the
    episode's first observation is read where the excursion ends, ``info["excursion"]`` holds
    its readings, commands and poses, and an excursion that does not leave the room within
    2,000 steps redraws the start.

    ## Episode End

    1. Termination: on success for a task that ``terminates`` (``corner``, ``doorway``,
       ``homing``); ``explore`` never.
    2. Truncation: after the task's step ``budget`` (corner 200, doorway 300, explore 400,
       homing 200 steps after the excursion), by the ``TimeLimit`` wrapper that
       ``gymnasium.make`` adds.

    ``info["is_success"]`` is in every ``info`` and says whether the task is done so far: a
    corner or another room reached; for ``explore``, at least 40 % of the cells visited (the
    paper's random behaviour, driven through this action box, covers a median 26 % in
    ``rooms1`` and never reached 40 % in 200 episodes). ``info["coverage"]`` gives the fraction
    of the grid visited (only ``explore`` marks cells; for the others it stays at the start
    cell). Read at an episode's last step it is the episode's success, what stable-baselines3's
    ``EvalCallback`` reads.

    ## Arguments

    ```python
    >>> import gymnasium as gym
    >>> import sensorimotor.envs  # registers the tasks
    >>> env = gym.make("sensorimotor/LaserCorner-v0", world="rooms1")
    >>> observation, info = env.reset(seed=0)
    >>> bool(info["is_success"])
    False

    ```

    ``task``: a name in ``TASKS`` or a ``Task`` (each Gymnasium id passes its own name);
    ``world``, ``noise`` and ``render_mode`` as in ``LaserWorld-v0``; ``max_episode_steps`` to
    ``gym.make`` changes the budget.

    ## Version History

    * v0: Initial version.
    """

    metadata: ClassVar[dict[str, Any]] = LaserWorldEnv.metadata

    def __init__(
        self,
        task: str | Task = "corner",
        world: str | Path | World = "rooms1",
        noise: float = 0.0,
        render_mode: str | None = None,
    ):
        self.task = get_task(task)
        super().__init__(world, noise, render_mode)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(2,), dtype=np.float32)
        self.corners = corner_points(self.world)  # (C, 2)
        self.reach_layout = sim.SensorLayout(angles=tuple(self.angles), max_range=CORNER_REACH)
        problem = self.task.check(self.world)
        if problem is not None:
            raise InputError(f"task {self.task.name} {problem}")
        self.visited = np.zeros((GRID, GRID), dtype=bool)  # cells entered this episode
        self.start_room = -1  # index in world.rooms where the episode started
        self.done = False  # the task is done (success so far)
        self.excursion: dict | None = None  # the task's excursion of this episode, if any
        self._walk = None  # the walls' grid arrays of the excursion's walk, made when needed

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
        before = measure(self, np.array([self.pose]))
        observation, _, _, _, info = super().step(command)
        rewards, terminated, done = task_step(
            self, np.array([self.pose]), before, np.array([self.start_room]), self.visited[None]
        )
        self.done = bool(done[0])
        return observation, float(rewards[0]), bool(terminated[0]), False, self._task_info(info)

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        observation, info = super().reset(seed=seed, options=options)  # seeds, draws a pose
        given = (options or {}).get("pose") is not None
        if not given and not self.task.good_start(self):
            self._draw_start()
            observation, info = self._observe(), self._info(False)
        self.start_room = self._room()
        self.excursion = None
        if self.task.excursion is not None:
            for _ in range(MAX_START_DRAWS):
                self.excursion = self.task.excursion(self)
                if self.excursion is not None or given:
                    break
                self._draw_start()
                self.start_room = self._room()
            if self.excursion is None:
                where = "the given pose" if given else f"world {self.world.name!r}"
                raise InputError(
                    f"task {self.task.name}: no excursion out of the start room from {where}"
                )
            observation, info = self._observe(), self._info(False)
            info["excursion"] = self.excursion
        self.visited[:] = False
        self.visited[grid_cells(self.world, np.array([self.pose]))] = True
        self.done = False
        return observation, self._task_info(info)

    def _draw_start(self) -> None:
        """Draw start poses until the task's ``good_start`` takes one (InputError after
        ``MAX_START_DRAWS``)."""
        for _ in range(MAX_START_DRAWS):
            self.pose = sim.sample_start(self.world, self.np_random)
            if self.task.good_start(self):
                return
        raise InputError(f"world {self.world.name!r}: no start pose for task {self.task.name}")

    def _room(self) -> int:
        """Index in ``world.rooms`` of the room holding the agent, -1 for none."""
        return int(self.world.room_index(np.array([self.pose[0]]), np.array([self.pose[1]]))[0])


def measure(env: LaserTaskEnv, poses: np.ndarray) -> np.ndarray | None:
    """(N,) the task's ``measure`` of the poses (N, 3) before a move; None when it has none."""
    return None if env.task.measure is None else env.task.measure(env, poses)


def task_step(
    env: LaserTaskEnv,
    poses: np.ndarray,
    before: np.ndarray | None,
    start_room: np.ndarray,
    visited: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The rewards (N,), terminations (N,) and success so far (N,) of N robots of ``env``'s
    task and world that have just moved to ``poses`` (N, 3); ``before`` (N,) what ``measure``
    gave before the move, ``start_room`` (N,), ``visited`` (N, GRID, GRID), which the task's
    reward may update in place. ``LaserTaskEnv.step`` (N = 1) and ``rl.vec_env.TaskVecEnv``
    both score through it (the class docstring's Rewards)."""
    task = env.task
    episodes = Episodes(poses, before, start_room, visited)
    rewards = task.reward(env, episodes)
    success = np.asarray(task.success(env, episodes), dtype=bool)
    rewards = rewards + task.success_reward * success
    terminated = success.copy() if task.terminates else np.zeros_like(success)
    return rewards, terminated, success
