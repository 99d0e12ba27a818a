"""The laser robot of Kulak & Garcia Ortiz (section IV) as a Gymnasium environment."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, ClassVar

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.world import World, load_world, point_segment_distance

MAX_STEP = 1.0  # units; the largest translation d of one command (the paper's d ~ U(0, 1))
MAX_TURN = math.pi + math.pi / 10  # rad; the paper's largest turn-around, pi + pi/10
WALL_MARGIN = 1e-6  # units; a translation toward a wall stops this far short of it


class LaserWorldEnv(gym.Env[np.ndarray, np.ndarray]):
    """
    ## Description

    A point robot in a walled planar world, loosely inspired by the Thymio-II robot, from
    "Representation Learning in Partially Observable Environments using Sensorimotor
    Prediction" (Kulak & Garcia Ortiz, section IV). It carries 5 laser distance sensors, evenly spread from -0.6 to 0.6 rad around its
    heading, which see up to 10 units. A motor command ``(d, r)`` moves it forward by ``d`` along
    its heading, then turns it by ``r``; there is no friction and no noise on the motion.

    There is no task: this is a world for representation learning from sensorimotor streams.
    ``paper_policy`` (in this module) is the paper's random wall-avoiding behaviour; run with it,
    the environment records the same rows as ``sensorimotor generate`` (see ``paper_policy``).

    The physics is the package's simulation core (``sensorimotor.sim.core``, compiled with numba):
    ``sim.cast_rays`` for the readings, ``sim.move`` for the motion (``sim.apply_motor``, stopped
    short of the wall ahead by the same ray caster), ``sim.sample_start`` for the start pose.
    Worlds are ``square``, ``rooms1``, ``rooms2`` (50 x 50, paper Fig. 1) or any TOML world file.

    ## Action Space

    The action is a ``float64`` ``ndarray`` of shape ``(2,)``, in physical units:

    | Num | Action                                            | Min      | Max    |
    |-----|---------------------------------------------------|----------|--------|
    | 0   | d: forward translation along the heading (units)  | 0        | 1      |
    | 1   | r: rotation after the translation (rad, ccw)      | -1.1 pi  | 1.1 pi |

    The rotation's bound is the paper's largest turn-around (``pi + pi/10``), so every command of
    the paper's behaviour, and of a database, is an action as it is. ``d`` is clipped to
    ``[0, 1]``; ``r`` is applied as given (any rotation is valid) and the heading is kept in
    ``(-pi, pi]``.

    **Collisions.** A translation that would reach the wall ahead is shortened so the agent stops
    ``WALL_MARGIN`` (1e-6 units) short of it, measured along the heading, and
    ``info["collision"]`` is ``True``; the rotation is still applied. The agent never leaves the
    world nor crosses a wall. The paper's behaviour never collides (it only moves when every
    reading is at least 1, and ``d < 1``).

    Note: Gymnasium's ``check_env`` recommends actions normalised to ``[-1, 1]`` for
    reinforcement-learning libraries; this world keeps the paper's units so that a database's
    motor column replays unchanged. Divide ``r`` by pi (``data.scale_motors``) to normalise.

    ## Observation Space

    The observation is a ``float32`` ``ndarray`` of shape ``(5,)``, the laser readings: the
    distance along each ray to the first wall, or 10 when no wall is nearer.

    | Num | Observation: distance to the first wall along the ray at | Min | Max |
    |-----|----------------------------------------------------------|-----|-----|
    | 0   | heading - 0.6 rad (rightmost)                            | 0   | 10  |
    | 1   | heading - 0.3 rad                                        | 0   | 10  |
    | 2   | heading (straight ahead)                                 | 0   | 10  |
    | 3   | heading + 0.3 rad                                        | 0   | 10  |
    | 4   | heading + 0.6 rad (leftmost)                             | 0   | 10  |

    With ``noise > 0`` each reading gets Gaussian noise of that standard deviation, clipped to
    ``[0, 10]``, drawn from ``self.np_random`` (as ``sensorimotor generate --noise``).

    The agent does not observe its pose; ``info["pose"]`` gives it, ``(x, y, heading)``
    (float64), for analysis and plotting. ``info["readings"]`` gives the noiseless readings
    (float64), what the generator's wall-avoiding behaviour reads even when it records noisy
    ones: with noise, drive ``paper_policy`` with them to walk as ``generate --noise`` does.

    ## Rewards

    None: the reward is always 0. This is a world for representation learning, not a task.

    ## Starting State

    A position uniform over the free positions at least 1 unit from every wall, and a heading
    uniform in ``[-pi, pi)``, drawn from ``self.np_random`` by ``sim.sample_start``, the start of
    a database. ``reset(options={"pose": (x, y, heading)})`` starts at a given pose instead (it
    must lie inside the world).

    ## Episode End

    1. Termination: never.
    2. Truncation: after ``max_episode_steps`` steps (default 10,000, the length of the paper's
       Fig. 2), by the ``TimeLimit`` wrapper that ``gymnasium.make`` adds.

    ## Arguments

    ```python
    >>> import gymnasium as gym
    >>> import sensorimotor.envs  # registers sensorimotor/LaserWorld-v0
    >>> env = gym.make("sensorimotor/LaserWorld-v0", world="rooms1", max_episode_steps=1000)
    >>> env
    <TimeLimit<OrderEnforcing<PassiveEnvChecker<LaserWorldEnv<sensorimotor/LaserWorld-v0>>>>>
    >>> observation, info = env.reset(seed=0)
    >>> observation.shape, observation.dtype, sorted(info)
    ((5,), dtype('float32'), ['collision', 'paper_readings', 'pose', 'readings'])
    >>> action = sensorimotor.envs.paper_policy(observation, env.unwrapped.np_random)
    >>> observation, reward, terminated, truncated, info = env.step(action)
    >>> bool((observation >= 0).all() and (observation <= 10).all()), reward, terminated
    (True, 0.0, False)

    ```

    | Parameter           | Type                   | Default    | Description                      |
    |---------------------|------------------------|------------|----------------------------------|
    | `world`             | `str`, `Path`, `World` | `"square"` | built-in name or TOML world file |
    | `noise`             | `float`                | `0.0`      | std of Gaussian reading noise    |
    | `rays`              | `int`                  | `5`        | lasers, 1 to 1,024               |
    | `fov`               | `float`                | `1.2`      | field of view (rad, <= 2 pi)     |
    | `max_range`         | `float`                | `10.0`     | laser range (units)              |
    | `noise_kind`        | `str`                  | `absolute` | or `relative` (x the reading)    |
    | `dropout`           | `float`                | `0.0`      | P(a reading reads the range)     |
    | `motor_noise`       | `float`                | `0.0`      | std of noise on executed d and r |
    | `render_mode`       | `str` or `None`        | `None`     | `"rgb_array"`: top-view image    |
    | `max_episode_steps` | `int` (to `gym.make`)  | `10000`    | truncation (`TimeLimit` wrapper) |

    ``rays``, ``fov``, ``max_range``, ``noise_kind``, ``dropout`` and ``motor_noise`` are those of
    ``sensorimotor generate`` (``sim.spread_layout``, ``sim.rollout``): the observation then has
    ``rays`` readings (the table above is the paper's 5); a dropped reading reads the range; with
    motor noise the executed command is the action plus Gaussian noise on ``d`` and ``r`` (drawn
    from ``self.np_random``, then clipped as any action). ``info["paper_readings"]`` holds the
    paper's 5 noiseless readings, what ``paper_policy`` reads to walk as ``generate`` does.
    ``gym.make("sensorimotor.envs:sensorimotor/LaserWorld-v0")`` imports the module itself.
    ``render()`` with ``render_mode="rgb_array"`` returns an ``(H, W, 3)`` ``uint8`` image: the
    walls, the agent with its heading, and its rays to the points they perceive (red dots),
    drawn by ``sensorimotor.sim.plots.plot_perception`` (matplotlib, imported on first render).

    ## Version History

    * v0: Initial version: the paper's agent, worlds and sensors; collision-clipped translation.
    """

    metadata: ClassVar[dict[str, Any]] = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        world: str | Path | World = "square",
        noise: float = 0.0,
        render_mode: str | None = None,
        rays: int = 5,
        fov: float = 1.2,
        max_range: float = sim.MAX_RANGE,
        noise_kind: str = "absolute",
        dropout: float = 0.0,
        motor_noise: float = 0.0,
    ):
        self.world = world if isinstance(world, World) else load_world(world)
        sim.check_noise(noise, noise_kind, dropout, motor_noise)
        layout = sim.spread_layout(rays, fov, max_range)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise InputError(f"render_mode must be None or 'rgb_array', got {render_mode!r}")
        self.noise = float(noise)
        self.relative = noise_kind == "relative"
        self.dropout = float(dropout)
        self.motor_noise = float(motor_noise)
        self.render_mode = render_mode

        self.segments = np.ascontiguousarray(self.world.segments)  # (S, 4) float64 walls
        self.angles = np.asarray(layout.angles, dtype=np.float64)  # (R,) rad from heading
        self.max_range = layout.max_range  # units
        self.ahead_range = math.hypot(self.world.width, self.world.height)  # sees any wall

        self.action_space = spaces.Box(
            low=np.array([0.0, -MAX_TURN]), high=np.array([MAX_STEP, MAX_TURN]), dtype=np.float64
        )
        self.observation_space = spaces.Box(
            0.0, self.max_range, shape=(len(self.angles),), dtype=np.float32
        )

        self.pose: tuple[float, float, float] | None = None  # (x, y, heading)
        self._readings = np.empty(len(self.angles))  # (R,) noiseless readings at self.pose
        self._figure = None  # matplotlib Figure, made on first render

    def _observe(self) -> np.ndarray:
        """Cast the rays at the current pose; return the (noisy) float32 observation."""
        x, y, heading = self.pose
        sim.cast_rays(self.segments, x, y, heading, self.angles, self.max_range, self._readings)
        readings = self._readings
        if self.noise:
            extra = self.np_random.normal(0.0, self.noise, readings.shape)
            readings = readings + (readings * extra if self.relative else extra)
        if self.dropout:
            readings = np.where(
                self.np_random.random(readings.shape) < self.dropout, self.max_range, readings
            )
        return np.clip(readings, 0.0, self.max_range).astype(np.float32)

    def _info(self, collision: bool) -> dict[str, Any]:
        return {
            "pose": np.array(self.pose, dtype=np.float64),
            "readings": self._readings.copy(),
            "paper_readings": sim.read_sensors(self.world, np.array(self.pose))[0],
            "collision": collision,
        }

    def step(self, action):
        assert self.pose is not None, "Call reset before using step method."
        action = np.asarray(action, dtype=np.float64)
        if action.size != 2:
            raise ValueError(f"action must be (d, r), 2 numbers, got shape {action.shape}")
        action = action.reshape(2)
        if not np.isfinite(action).all():
            raise ValueError(f"action must be finite, got {action!r}")
        if self.motor_noise:  # the executed command is not quite the one given
            action = action + self.np_random.normal(0.0, self.motor_noise, 2)
        d = min(max(float(action[0]), 0.0), MAX_STEP)  # translation (units)
        r = float(action[1])  # rotation (rad)
        # Collision: d stops WALL_MARGIN short of the first wall straight ahead (the same
        # ray caster as the sensors, cast up to ahead_range); then the robot turns by r.
        *pose, collision = sim.move(self.segments, *self.pose, d, r, self.ahead_range, WALL_MARGIN)
        self.pose = tuple(pose)
        return self._observe(), 0.0, False, False, self._info(bool(collision))

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        pose = (options or {}).get("pose")
        if pose is None:
            self.pose = sim.sample_start(self.world, self.np_random)
        else:
            self.pose = self._check_pose(pose)
        return self._observe(), self._info(False)

    def _check_pose(self, pose) -> tuple[float, float, float]:
        """A start pose from ``options["pose"]``: finite, inside the world, not on a wall."""
        try:
            x, y, heading = (float(v) for v in np.asarray(pose, dtype=np.float64).reshape(3))
        except (TypeError, ValueError):
            raise ValueError(f"options['pose'] must be (x, y, heading), got {pose!r}") from None
        if not all(math.isfinite(v) for v in (x, y, heading)):
            raise ValueError(f"options['pose'] must be finite, got {pose!r}")
        inside = 0 < x < self.world.width and 0 < y < self.world.height
        on_wall = point_segment_distance(self.segments, np.array([x]), np.array([y])).min() == 0
        if not inside or on_wall:
            raise ValueError(f"options['pose'] {pose!r} is not a free position of the world")
        return x, y, float(sim.wrap_angle(heading))

    def render(self):
        if self.render_mode is None:
            assert self.spec is not None
            gym.logger.warn(
                "You are calling render method without specifying any render mode. "
                "You can specify the render_mode at initialization, "
                f'e.g. gym.make("{self.spec.id}", render_mode="rgb_array")'
            )
            return None
        if self.pose is None:
            raise gym.error.ResetNeeded("Call reset before using render method.")
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        from sensorimotor.sim.plots import plot_perception

        if self._figure is None:
            self._figure = Figure(figsize=(4, 4), dpi=100, layout="constrained")
            FigureCanvasAgg(self._figure)
        fig = self._figure
        fig.clear()
        ax = fig.add_subplot()
        readings = self._readings  # noiseless: where the rays really end
        plot_perception(self.world, self.pose, readings, ax, self.angles, self.max_range)
        fig.canvas.draw()
        return np.asarray(fig.canvas.buffer_rgba())[:, :, :3].copy()  # (H, W, 3) uint8

    def close(self):
        self._figure = None


def paper_policy(observation: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """The paper's behaviour (section IV.C) as a policy: ``(d, r)`` from 5 readings.

    If a reading is below 1: ``(0, r)``, ``r ~ U(pi - pi/10, pi + pi/10)`` (turn around); else
    ``d ~ U(0, 1)``, ``r ~ U(-pi/6, pi/6)``. Two uniforms are drawn from ``rng`` per call and
    passed to ``sim.behaviour``, exactly as ``sim.rollout`` draws them, so that::

        rng = np.random.default_rng(seed)
        pose = sim.sample_start(world, rng)
        observation, info = env.reset(options={"pose": pose})
        for t in range(steps):
            action = paper_policy(observation, rng)
            observation, *_ = env.step(action)

    visits the poses and issues the motor commands of ``sim.rollout(world, steps, seed)`` (the
    rows of a database): the poses and commands bit for bit, the readings to float32 rounding.
    (The environment's float32 observation could flip the turn decision only for a reading
    within float32 rounding of 1.) With ``noise > 0`` pass ``info["readings"]``, not the noisy
    observation: the generator avoids walls by the true distances, so the poses and commands
    are again those of the database (its noise is drawn from another stream than the
    environment's, so the recorded readings differ by the noise). Returns a float64 array of
    shape ``(2,)``.
    """
    u0, u1 = rng.random(2)
    d, r = sim.behaviour(float(np.min(observation)), u0, u1)
    return np.array([d, r], dtype=np.float64)
