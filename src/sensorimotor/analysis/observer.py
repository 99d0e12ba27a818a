"""The ideal observer: what the stream itself holds about where the robot is.

A particle filter that knows the world's walls, the laser layout and the behaviour reads the
stream a memory reads: the readings and, with ``commands``, the motor commands. It starts with
no knowledge of the pose (particles uniform over the free space and the heading), so its belief
after a burn-in is the ceiling for a memory that starts empty, where the true pose is the
ceiling for a code of the place. Being a finite filter, it approximates the ideal observer from
below.

One step ``t`` (row ``t`` of a database: ``sensors[t]`` read at ``poses[t]``, then
``motors[t]`` executed):

- weight: each reading's likelihood is a Gaussian of sd ``READING_SD`` around the particle's
  own reading, mixed with ``UNIFORM_SHARE`` uniform over the range (the beam model);
- belief: the weighted mean x, y, cos and sin of the heading, and the share of weight in each
  room;
- resample (systematic) when the effective sample size falls below half, then roughen by
  ``ROUGHEN_XY`` and ``ROUGHEN_HEADING`` and draw ``FRESH_SHARE`` of the particles afresh;
- move: by the recorded command, dropping a particle whose step would cross a wall; or, without
  ``commands``, by a command each particle draws from the paper's behaviour given its readings.

The settings were set before the filter ran (docs/results/memory/README.md, "An ideal
observer"), not tuned; the count of particles is the one the rule's check kept.
"""

from __future__ import annotations

import math

import numba
import numpy as np

from sensorimotor.sim.behaviours import behaviour
from sensorimotor.sim.core import DEFAULT_LAYOUT, SensorLayout, _cast, wrap_angle
from sensorimotor.sim.grid import for_rays
from sensorimotor.sim.world import World, free_start_cells

PARTICLES = 16000  # the rule's check: 4,000 moved Rooms1's room by 0.08 against this count
READING_SD = 0.5  # units
UNIFORM_SHARE = 0.1  # of a reading's likelihood: uniform over the range
ROUGHEN_XY = 0.1  # units, after a resampling
ROUGHEN_HEADING = 0.02  # rad, after a resampling
FRESH_SHARE = 0.01  # of the particles drawn afresh at each resampling
START_JITTER = 0.125  # units: a fresh particle's offset from its free grid point (half its step)
ROOM_CELL = 0.25  # units: the side of the raster that tells a particle's room


# Numba's kernels draw from its own copy of NumPy's legacy generator (the only one it has),
# seeded once per call of ``_filter``: same seed, same bytes.
@numba.njit(cache=True)
def _uniform():
    return np.random.random()  # noqa: NPY002


@numba.njit(cache=True)
def _normal():
    return np.random.normal()  # noqa: NPY002


@numba.njit(cache=True)
def _spawn(px, py, ph, i, free):
    """Particle ``i`` afresh: a free grid point jittered within its cell, a uniform heading."""
    k = min(int(_uniform() * free.shape[0]), free.shape[0] - 1)
    px[i] = free[k, 0] + (2.0 * _uniform() - 1.0) * START_JITTER
    py[i] = free[k, 1] + (2.0 * _uniform() - 1.0) * START_JITTER
    ph[i] = wrap_angle(2.0 * math.pi * _uniform())


@numba.njit(cache=True)
def _filter(
    segments, dims, start, items, angles, max_range, sensors, motors, commands, free,
    room_map, n, seed, belief,
):  # fmt: skip
    """Run the filter over ``sensors`` (T, R) and ``motors`` (T, 2), writing ``belief`` (T,
    4 + rooms): mean x, y, cos, sin, then each room's share (the module's docstring)."""
    np.random.seed(seed)  # noqa: NPY002
    n_rays = angles.shape[0]
    ca, sa = np.cos(angles), np.sin(angles)
    px, py, ph = np.empty(n), np.empty(n), np.empty(n)
    for i in range(n):
        _spawn(px, py, ph, i, free)
    logw = np.zeros(n)
    lowest = np.empty(n)
    w = np.empty(n)
    dx, dy, pred = np.empty(n_rays), np.empty(n_rays), np.empty(n_rays)
    one_x, one_y, one = np.empty(1), np.empty(1), np.empty(1)
    nx, ny = px.copy(), py.copy()
    nh, nl = ph.copy(), np.empty(n)
    stamp = np.zeros(segments.shape[0], dtype=np.int64)
    ray_id = 1
    norm = (1.0 - UNIFORM_SHARE) / (READING_SD * math.sqrt(2.0 * math.pi))
    floor = UNIFORM_SHARE / max_range
    for t in range(sensors.shape[0]):
        for i in range(n):
            ch, sh = math.cos(ph[i]), math.sin(ph[i])
            for k in range(n_rays):
                dx[k] = ch * ca[k] - sh * sa[k]
                dy[k] = sh * ca[k] + ch * sa[k]
            ray_id = _cast(
                segments, dims, start, items, stamp, ray_id, px[i], py[i], dx, dy, max_range, pred
            )
            low = max_range
            for k in range(n_rays):
                e = (pred[k] - sensors[t, k]) / READING_SD
                logw[i] += math.log(norm * math.exp(-0.5 * e * e) + floor)
                low = min(low, pred[k])
            lowest[i] = low
        top = logw.max()
        if not top > -np.inf:  # every particle dropped: start again
            for i in range(n):
                _spawn(px, py, ph, i, free)
            logw[:] = 0.0
            top = 0.0
        total = 0.0
        for i in range(n):
            w[i] = math.exp(logw[i] - top)
            total += w[i]
        w /= total
        belief[t, :] = 0.0
        for i in range(n):
            belief[t, 0] += w[i] * px[i]
            belief[t, 1] += w[i] * py[i]
            belief[t, 2] += w[i] * math.cos(ph[i])
            belief[t, 3] += w[i] * math.sin(ph[i])
            ix, iy = int(px[i] / ROOM_CELL), int(py[i] / ROOM_CELL)
            if 0 <= iy < room_map.shape[0] and 0 <= ix < room_map.shape[1]:
                room = room_map[iy, ix]
                if room >= 0:
                    belief[t, 4 + room] += w[i]
        if 1.0 / (w * w).sum() < 0.5 * n:  # systematic resampling
            u = _uniform() / n
            c, j = w[0], 0
            for i in range(n):
                while u > c and j < n - 1:
                    j += 1
                    c += w[j]
                nx[i] = px[j] + _normal() * ROUGHEN_XY
                ny[i] = py[j] + _normal() * ROUGHEN_XY
                nh[i] = wrap_angle(ph[j] + _normal() * ROUGHEN_HEADING)
                nl[i], u = lowest[j], u + 1.0 / n
            px[:], py[:], ph[:], lowest[:] = nx, ny, nh, nl
            logw[:] = 0.0
            for i in range(n):
                if _uniform() < FRESH_SHARE:
                    _spawn(px, py, ph, i, free)
        for i in range(n):
            if commands:
                d, r = motors[t, 0], motors[t, 1]
            else:
                d, r = behaviour(lowest[i], _uniform(), _uniform())
            if commands and d > 0.0:
                one_x[0], one_y[0] = math.cos(ph[i]), math.sin(ph[i])
                ray_id = _cast(
                    segments, dims, start, items, stamp, ray_id, px[i], py[i], one_x, one_y,
                    max_range, one,
                )  # fmt: skip
                if one[0] < d:
                    logw[i] = -np.inf
            px[i] += d * math.cos(ph[i])
            py[i] += d * math.sin(ph[i])
            ph[i] = wrap_angle(ph[i] + r)
    return belief


def room_raster(world: World) -> np.ndarray:
    """(Y, X) int64: the room of each ``ROOM_CELL`` square's centre (-1 outside every room)."""
    xs = np.arange(ROOM_CELL / 2, world.width, ROOM_CELL)
    ys = np.arange(ROOM_CELL / 2, world.height, ROOM_CELL)
    gx, gy = np.meshgrid(xs, ys)
    return world.room_index(gx.ravel(), gy.ravel()).reshape(gx.shape)


def observe(
    world: World,
    sensors: np.ndarray,
    motors: np.ndarray,
    layout: SensorLayout = DEFAULT_LAYOUT,
    commands: bool = True,
    particles: int = PARTICLES,
    seed: int = 0,
) -> np.ndarray:
    """(T, 4 + rooms) float64: the ideal observer's belief at each step of a stream that starts
    with no knowledge of the pose (mean x, y, cos, sin of the heading, each room's share).
    Without ``commands`` it draws them from the paper's behaviour, which reads the paper's
    lasers: ValueError for another layout."""
    sensors = np.ascontiguousarray(sensors, dtype=np.float64)
    motors = np.ascontiguousarray(motors, dtype=np.float64)
    if sensors.ndim != 2 or sensors.shape[1] != len(layout.angles) or len(motors) != len(sensors):
        raise ValueError(
            f"the stream's readings {sensors.shape} and commands {motors.shape} do not fit "
            f"a layout of {len(layout.angles)} rays"
        )
    if not commands and layout != DEFAULT_LAYOUT:
        raise ValueError("an observer without the commands needs the paper's lasers")
    if particles < 1:
        raise ValueError(f"particles must be at least 1, got {particles}")
    free = free_start_cells(world)
    segments = world.segments
    grid = for_rays(world.grid, len(segments), len(layout.angles)).arrays()
    belief = np.zeros((len(sensors), 4 + len(world.rooms)))
    return _filter(
        segments, *grid, np.asarray(layout.angles, dtype=np.float64), float(layout.max_range),
        sensors, motors, commands, free, room_raster(world), particles,
        seed, belief,
    )  # fmt: skip
