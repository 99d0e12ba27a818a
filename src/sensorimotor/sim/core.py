"""The simulation core: ray casting, the motor command, the paper's behaviour, and rollouts.

Every kernel here is a pure array function compiled with numba; randomness is drawn outside the
kernels (uniforms in bulk from a ``numpy.random.Generator``) so one seed gives the same bytes
whatever the chunking. The database generator, the Gymnasium environment and the figures all
call these kernels; there is no other ray caster in the package.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from sensorimotor.sim.world import START_CLEARANCE, World, free_start_cells, point_segment_distance

SENSOR_ANGLES = np.array([-0.6, -0.3, 0.0, 0.3, 0.6])  # rad from the heading; index 0 rightmost
MAX_SEED = 2**32 - 1  # the largest seed that every seeded library here accepts
MAX_RANGE = 10.0  # units; a ray that hits nothing nearer reads exactly this
TURN_THRESHOLD = 1.0  # units; the behaviour turns around when a reading is below this
EPS = 1e-12


@dataclass(frozen=True)
class SensorLayout:
    """Where the lasers point and how far they see."""

    angles: tuple[float, ...] = tuple(SENSOR_ANGLES.tolist())
    """Ray directions relative to the heading (rad), counter-clockwise positive."""
    max_range: float = MAX_RANGE
    """Reading when no wall is nearer (units)."""

    def to_dict(self) -> dict:
        return {"angles": list(self.angles), "max_range": self.max_range}


DEFAULT_LAYOUT = SensorLayout()


@numba.njit(cache=True, error_model="numpy")
def _cast_many(segments, x, y, dx, dy, max_range, out):
    """Write into ``out`` (R,) the distance from (x, y) along each unit direction (dx[i], dy[i])
    to the first segment, capped at ``max_range``: the ray caster of the whole package.

    A ray ``p + t u`` (t >= 0, |u| = 1) meets segment ``a + s e`` (0 <= s <= 1, e = b - a)
    where ``p + t u = a + s e``. Crossing both sides with ``e`` and with ``u`` (``c(v, w) =
    v_x w_y - v_y w_x``) gives ``t = c(a - p, e) / c(u, e)`` and ``s = c(a - p, u) / c(u, e)``.
    With the sign of ``den = c(u, e)`` moved onto the numerators (exact), the tests need no
    division: a hit is ``|den| >= EPS`` (parallel rays never hit), ``t_num >= 0`` and
    ``0 <= s_num <= |den|`` (end points count); then ``t = t_num / |den|``. ``t_num`` does not
    depend on the ray, so the loop runs over segments outside, rays inside, and the ray loop is
    branch-free (``error_model="numpy"``: a division by a zero ``den`` is masked, not raised).

    segments: (S, 4) float64 ``x0, y0, x1, y1``; dx, dy, out: (R,) float64.
    """
    for i in range(out.shape[0]):
        out[i] = max_range
    for k in range(segments.shape[0]):
        ax = segments[k, 0]
        ay = segments[k, 1]
        ex = segments[k, 2] - ax
        ey = segments[k, 3] - ay
        qx = ax - x
        qy = ay - y
        t_num = qx * ey - qy * ex  # c(a - p, e), shared by every ray
        for i in range(out.shape[0]):
            den = dx[i] * ey - dy[i] * ex  # c(u, e)
            s_num = qx * dy[i] - qy * dx[i]  # c(a - p, u)
            neg = den < 0.0
            den = -den if neg else den
            tn = -t_num if neg else t_num
            sn = -s_num if neg else s_num
            t = tn / den
            hit = (den >= EPS) & (tn >= 0.0) & (sn >= 0.0) & (sn <= den) & (t < out[i])
            out[i] = t if hit else out[i]
    return out


@numba.njit(cache=True)
def cast_rays(segments, x, y, heading, angles, max_range, out):
    """Write into ``out`` (R,) the distance along each ray ``heading + angles[i]`` to a wall.

    The reading is the smallest ``t`` at which the ray meets a segment (derived in
    ``_cast_many``; end points count, parallel rays never hit), or ``max_range`` when no wall is
    nearer.

    segments: (S, 4) float64 ``x0, y0, x1, y1``; angles: (R,) float64; out: (R,) float64.
    """
    n = angles.shape[0]
    dx = np.empty(n)
    dy = np.empty(n)
    for i in range(n):
        a = heading + angles[i]
        dx[i] = math.cos(a)
        dy[i] = math.sin(a)
    return _cast_many(segments, x, y, dx, dy, max_range, out)


@numba.njit(cache=True)
def wrap_angle(a):
    """The same angle in (-pi, pi]."""
    while a > math.pi:
        a -= 2.0 * math.pi
    while a <= -math.pi:
        a += 2.0 * math.pi
    return a


@numba.njit(cache=True)
def behaviour(min_reading, u0, u1):
    """The paper's wall-avoiding random behaviour (section IV.C) from two uniforms in [0, 1).

    If a reading is below 1: ``(0, r)``, ``r ~ U(pi - pi/10, pi + pi/10)`` (turn around);
    else ``d ~ U(0, 1)``, ``r ~ U(-pi/6, pi/6)``. Returns ``(d, r)``.
    """
    if min_reading < TURN_THRESHOLD:
        return 0.0, math.pi - math.pi / 10.0 + u1 * (math.pi / 5.0)
    return u0, -math.pi / 6.0 + u1 * (math.pi / 3.0)


@numba.njit(cache=True)
def apply_motor(x, y, heading, d, r):
    """Motor command ``(d, r)``: move ``d`` along the heading, then rotate by ``r``."""
    return x + d * math.cos(heading), y + d * math.sin(heading), wrap_angle(heading + r)


@numba.njit(cache=True)
def _rollout(segments, angles, max_range, x, y, heading, uniforms, noise, sensors, motors, poses):
    """Run ``len(uniforms)`` steps of the behaviour from pose (x, y, heading), filling the outputs.

    Row t: ``poses[t]`` is where ``sensors[t]`` is read; ``motors[t]`` is chosen from it and
    leads to row t + 1. The behaviour sees the noiseless readings (a reflex the noise does not
    fool, so the agent never crosses a wall); ``noise[t]`` (T, R) is added to what is recorded,
    and an empty ``noise`` (0, R) means none. Returns the pose after the last step.
    """
    n_rays = angles.shape[0]
    ca = np.cos(angles)
    sa = np.sin(angles)
    dx = np.empty(n_rays)
    dy = np.empty(n_rays)
    readings = np.empty(n_rays)
    noisy_run = noise.shape[0] > 0
    for t in range(uniforms.shape[0]):
        poses[t, 0] = x
        poses[t, 1] = y
        poses[t, 2] = heading
        ch = math.cos(heading)
        sh = math.sin(heading)
        for i in range(n_rays):
            # direction of heading + angle[i], by the angle-sum identities (one sincos a step)
            dx[i] = ch * ca[i] - sh * sa[i]
            dy[i] = sh * ca[i] + ch * sa[i]
        _cast_many(segments, x, y, dx, dy, max_range, readings)
        lowest = max_range
        for i in range(n_rays):
            lowest = min(lowest, readings[i])
            noisy = readings[i] + noise[t, i] if noisy_run else readings[i]
            sensors[t, i] = min(max(noisy, 0.0), max_range)
        d, r = behaviour(lowest, uniforms[t, 0], uniforms[t, 1])
        motors[t, 0] = d
        motors[t, 1] = r
        # apply_motor(x, y, heading, d, r), reusing this step's cos and sin of the heading
        x = x + d * ch
        y = y + d * sh
        heading = wrap_angle(heading + r)
    return x, y, heading


def _heading(rng: np.random.Generator) -> float:
    """A heading uniform over (-pi, pi] (``uniform`` draws [-pi, pi); -pi is the same as pi)."""
    h = float(rng.uniform(-math.pi, math.pi))
    return math.pi if h == -math.pi else h


def sample_start(world: World, rng: np.random.Generator) -> tuple[float, float, float]:
    """A start pose uniform over positions at least START_CLEARANCE from every wall."""
    segments = world.segments
    for _ in range(10_000):
        x, y = rng.uniform(0, world.width), rng.uniform(0, world.height)
        if point_segment_distance(segments, np.array([x]), np.array([y])).min() >= START_CLEARANCE:
            return x, y, _heading(rng)
    cells = free_start_cells(world)  # a sliver of free space: pick a free grid cell
    x, y = cells[rng.integers(len(cells))]
    return float(x), float(y), _heading(rng)


@dataclass(frozen=True)
class Rollout:
    """A recorded run: row t holds s_t, the command m_t chosen from it, and the pose of s_t."""

    sensors: np.ndarray  # (T, 5) float64 readings
    motors: np.ndarray  # (T, 2) float64 (d, r)
    poses: np.ndarray  # (T, 3) float64 (x, y, heading)


def rollout(
    world: World,
    steps: int,
    seed: int | np.random.Generator = 0,
    layout: SensorLayout = DEFAULT_LAYOUT,
    noise_std: float = 0.0,
    chunk: int = 200_000,
    progress: Callable[[int], None] | None = None,
) -> Rollout:
    """Run the paper's behaviour for ``steps`` steps from a random start; float64 arrays.

    The generator draws the start pose, then two uniforms per step, chunk after chunk; the
    noise (a normal per ray and step) comes from a child generator spawned from it, so its
    draws never interleave with the uniforms: the bytes depend on the seed alone, not on
    ``chunk``.
    ``progress(n)`` is called after each chunk with the number of steps done.
    """
    if steps < 1:
        raise ValueError(f"steps must be at least 1, got {steps}")
    if 0.0 not in layout.angles:
        # the behaviour moves on (d < 1) only when every reading is >= 1: without a ray
        # straight ahead a wall just in front would go unseen and be crossed
        raise ValueError(f"the behaviour needs a ray straight ahead (angle 0), got {layout.angles}")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    segments = np.ascontiguousarray(world.segments)
    angles = np.asarray(layout.angles, dtype=np.float64)
    sensors = np.empty((steps, len(angles)))
    motors = np.empty((steps, 2))
    poses = np.empty((steps, 3))
    x, y, heading = sample_start(world, rng)
    noise_rng = rng.spawn(1)[0] if noise_std else None
    no_noise = np.zeros((0, len(angles)))
    for start in range(0, steps, chunk):
        stop = min(start + chunk, steps)
        uniforms = rng.random((stop - start, 2))
        noise = (
            noise_rng.normal(0.0, noise_std, (stop - start, len(angles)))
            if noise_rng is not None
            else no_noise
        )
        x, y, heading = _rollout(
            segments,
            angles,
            layout.max_range,
            x,
            y,
            heading,
            uniforms,
            noise,
            sensors[start:stop],
            motors[start:stop],
            poses[start:stop],
        )
        if progress is not None:
            progress(stop)
    return Rollout(sensors, motors, poses)


def read_sensors(
    world: World, poses: np.ndarray, layout: SensorLayout = DEFAULT_LAYOUT
) -> np.ndarray:
    """Noiseless readings (P, R) at each pose (P, 3): the figures' and the analysis' ray caster."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return _read_many(
        np.ascontiguousarray(world.segments),
        poses,
        np.asarray(layout.angles, dtype=np.float64),
        float(layout.max_range),
    )


@numba.njit(cache=True)
def _read_many(segments, poses, angles, max_range):
    out = np.empty((poses.shape[0], angles.shape[0]))
    for p in range(poses.shape[0]):
        cast_rays(segments, poses[p, 0], poses[p, 1], poses[p, 2], angles, max_range, out[p])
    return out


def hit_walls(
    world: World,
    poses: np.ndarray,
    layout: SensorLayout = DEFAULT_LAYOUT,
    chunk: int = 65_536,
) -> np.ndarray:
    """(P, R) int: the row of ``world.segments`` each ray hits, or -1 when it reads the range.

    No second ray caster: ``read_sensors`` gives the distance ``t`` along each ray, the hit point
    is ``p + t u``, and the wall hit is the segment nearest to that point (it lies on it up to
    rounding; at a point two walls share, such as a corner, the lower row wins).
    poses: (P, 3) ``x, y, heading``; worked in chunks of ``chunk`` poses to bound memory.
    """
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    angles = np.asarray(layout.angles, dtype=np.float64)
    segments = world.segments
    out = np.full((len(poses), len(angles)), -1, dtype=np.int64)
    for start in range(0, len(poses), chunk):
        p = poses[start : start + chunk]  # (C, 3)
        t = read_sensors(world, p, layout)  # (C, R)
        a = p[:, 2, None] + angles[None, :]  # (C, R) absolute ray directions
        hx = p[:, 0, None] + t * np.cos(a)  # (C, R) hit points
        hy = p[:, 1, None] + t * np.sin(a)
        nearest = point_segment_distance(segments, hx.ravel(), hy.ravel()).argmin(axis=1)
        nearest = nearest.reshape(t.shape)  # (C, R)
        out[start : start + chunk] = np.where(t < layout.max_range, nearest, -1)
    return out
