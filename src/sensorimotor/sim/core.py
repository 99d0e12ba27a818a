"""The simulation core: ray casting, the motor command, the paper's behaviour, and rollouts.

Every kernel here is a pure array function compiled with numba; randomness is drawn outside the
kernels (uniforms in bulk from a ``numpy.random.Generator``) so one seed gives the same bytes
whatever the chunking. The database generator, the Gymnasium environment and the figures all
call these kernels; there is no other ray caster in the package. Big worlds are cast through
the walls' grid (``sim.grid``), small ones with the all-walls loop (``_cast_many``), behind one
door (``_cast``, ``grid.for_rays``): the same arithmetic, the same bits.
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass

import numba
import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.sim import MAX_RAYS as _MAX_RAYS
from sensorimotor.sim.behaviours import (  # noqa: F401 (what walks the robot, read through core too)
    BEHAVIOURS,
    GRID,
    GRID_TURN,
    LATTICE,
    LATTICE_STEP,
    LATTICE_TURN,
    PAPER,
    PAPER_TURN_SD,
    SMOOTH,
    SMOOTH_A,
    SMOOTH_SD,
    SMOOTH_TAU,
    TURN_THRESHOLD,
    TURNS,
    UNIFORMS,
    behaviour,
    check_behaviour,
    lattice_behaviour,
    reflex,
    smooth_behaviour,
    snap_heading,
)
from sensorimotor.sim.grid import WallGrid, cast_grid, for_rays
from sensorimotor.sim.world import START_CLEARANCE, World, free_start_cells, point_segment_distance

SENSOR_ANGLES = np.array([-0.6, -0.3, 0.0, 0.3, 0.6])  # rad from the heading; index 0 rightmost
MAX_RANGE = 10.0  # units; a ray that hits nothing nearer reads exactly this
MAX_RAYS = _MAX_RAYS  # rays a layout may have
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

    def describe(self) -> str:
        """One short phrase: "5 rays over [-0.6, 0.6] rad, range 10"."""
        n = len(self.angles)
        span = (
            f"at {self.angles[0]:g} rad"
            if n == 1
            else (f"over [{min(self.angles):g}, {max(self.angles):g}] rad")
        )
        rays = "ray" if n == 1 else "rays"
        return f"{n} {rays} {span}, range {self.max_range:g}"


def spread_layout(rays: int = 5, fov: float = 1.2, max_range: float = MAX_RANGE) -> SensorLayout:
    """``rays`` lasers evenly spread over a field of view of ``fov`` radians centred on the
    heading, seeing ``max_range`` units; InputError naming the option that is out of range.

    Ray i of n points at ``fov (i / (n - 1) - 1/2)`` (both edges of the fan; one ray looks
    straight ahead), or at ``-pi + 2 pi i / n`` for a full turn (``fov = 2 pi``: the edges are
    the same direction, counted once). Angles are rounded to 12 decimals so that the defaults
    give the paper's layout to the bit (-0.6, -0.3, 0, 0.3, 0.6).
    """
    if isinstance(rays, bool) or not isinstance(rays, int) or not 1 <= rays <= MAX_RAYS:
        raise InputError(f"--rays must be an integer from 1 to {MAX_RAYS:,}, got {rays!r}")
    full = 2 * math.pi
    if not (math.isfinite(fov) and 0 <= fov <= full + 1e-9):
        raise InputError(f"--fov must be from 0 to 2 pi ({full:.6f}) radians, got {fov!r}")
    if rays > 1 and fov <= 0:
        raise InputError(f"--fov must be positive for {rays} rays, got {fov!r}")
    if not (math.isfinite(max_range) and max_range > 0):
        raise InputError(f"--range must be a positive number, got {max_range!r}")
    if rays == 1:
        angles = [0.0]
    elif fov >= full - 1e-9:
        angles = [-math.pi + full * i / rays for i in range(rays)]
    else:
        angles = [fov * (i / (rays - 1) - 0.5) for i in range(rays)]
    return SensorLayout(tuple(round(a, 12) + 0.0 for a in angles), float(max_range))


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
    """The same angle in (-pi, pi]: a turn or two subtracted as always (the same bits), an
    angle further out (a huge motor noise) reduced at once, never by a loop of turns."""
    if not -3.0 * math.pi < a <= 3.0 * math.pi:
        a = a % (2.0 * math.pi)  # exact, in [0, 2 pi); inf and nan give nan
    while a > math.pi:
        a -= 2.0 * math.pi
    while a <= -math.pi:
        a += 2.0 * math.pi
    return a


@numba.njit(cache=True)
def apply_motor(x, y, heading, d, r):
    """Motor command ``(d, r)``: move ``d`` along the heading, then rotate by ``r``."""
    return x + d * math.cos(heading), y + d * math.sin(heading), wrap_angle(heading + r)


@numba.njit(cache=True)
def move(segments, x, y, heading, d, r, ahead_range, margin):
    """One motor step of the Gymnasium environment's robot (``envs.laser_world``): the
    translation ``d`` stops ``margin`` short of the first wall straight ahead (cast up to
    ``ahead_range``), then the robot turns by ``r``. Returns (x, y, heading, hit a wall)."""
    ahead = np.empty(1)
    cast_rays(segments, x, y, heading, np.zeros(1), ahead_range, ahead)
    hit = d > ahead[0] - margin
    if hit:
        d = max(ahead[0] - margin, 0.0)
    x, y, heading = apply_motor(x, y, heading, d, r)
    return x, y, heading, hit


@numba.njit(cache=True)
def move_many(segments, poses, d, r, ahead_range, margin, angles, max_range, readings, hit):
    """``move`` for each of N robots in one call, then their readings: ``poses`` (N, 3) is
    updated in place, ``hit`` (N,) says who met a wall, ``readings`` (N, R) gets the rays
    ``angles`` (R,) at the new poses. The vectorised environments of ``sensorimotor.rl``
    step every environment through it."""
    for i in range(poses.shape[0]):
        x, y, heading, hit[i] = move(
            segments, poses[i, 0], poses[i, 1], poses[i, 2], d[i], r[i], ahead_range, margin
        )
        poses[i, 0] = x
        poses[i, 1] = y
        poses[i, 2] = heading
        cast_rays(segments, x, y, heading, angles, max_range, readings[i])


@numba.njit(cache=True)
def _cast(segments, dims, start, items, stamp, ray_id, x, y, dx, dy, max_range, out):
    """The one door to the ray caster: the walls' grid (``sim.grid``) when the world has one
    (``dims[1] > 0``), else the all-walls loop; the same readings either way. Returns the next
    ``ray_id`` (see ``grid.cast_grid``)."""
    if dims[1] == 0.0:
        _cast_many(segments, x, y, dx, dy, max_range, out)
        return ray_id
    return cast_grid(segments, dims, start, items, stamp, ray_id, x, y, dx, dy, max_range, out)


@numba.njit(cache=True)
def _rollout(
    segments,
    dims,
    start,
    items,
    angles,
    max_range,
    paper_rays,
    x,
    y,
    heading,
    uniforms,
    noise,
    relative,
    dropped,
    motor_noise,
    sensors,
    motors,
    poses,
    kind,
    rate,
):
    """Run ``len(uniforms)`` steps of behaviour ``kind`` (``PAPER``, ``SMOOTH``, ``LATTICE``,
    ``GRID``: its uniforms a step are ``uniforms[t]``, the smooth one's state ``rate``, a
    lattice's heading step ``TURNS[kind]``) from pose (x, y, heading), filling the outputs.

    Row t: ``poses[t]`` is where ``sensors[t]`` is read; ``motors[t]`` is chosen from it and
    leads to row t + 1. The behaviour reads the paper's five rays, noiseless (a reflex the
    noise does not fool, so the agent never crosses a wall): the layout's own readings when
    ``paper_rays`` (the layout is the paper's), else five hidden rays cast for it alone.
    What is recorded: ``noise[t]`` (T, R) added to the reading (times the reading when
    ``relative``); then the range where ``dropped[t]`` (T, R); then clipped to [0, range].
    ``motor_noise[t]`` (T, 2) is added to the command executed, not to the one recorded; the
    translation stays within [0, 0.99 x the distance straight ahead], so the noise never
    carries the agent through a wall. An empty array (0, .) means none of that kind.
    Returns the pose after the last step and the behaviour's state (its turning rate).
    """
    n_rays = angles.shape[0]
    ca = np.cos(angles)
    sa = np.sin(angles)
    pa = np.cos(SENSOR_ANGLES), np.sin(SENSOR_ANGLES)
    dx = np.empty(n_rays)
    dy = np.empty(n_rays)
    readings = np.empty(n_rays)
    pdx = np.empty(5)
    pdy = np.empty(5)
    hidden = np.empty(5)
    stamp = np.zeros(segments.shape[0], dtype=np.int64)
    ray_id = 1
    noisy_run = noise.shape[0] > 0
    drop_run = dropped.shape[0] > 0
    motor_run = motor_noise.shape[0] > 0
    all_walls = dims[1] == 0.0
    turn = TURNS[kind]  # the heading lattice's step (0: none)
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
        if all_walls:  # the paper's worlds: the all-walls loop, called here to be inlined
            _cast_many(segments, x, y, dx, dy, max_range, readings)
        else:
            ray_id = cast_grid(
                segments, dims, start, items, stamp, ray_id, x, y, dx, dy, max_range, readings
            )
        if not paper_rays:
            for i in range(5):
                pdx[i] = ch * pa[0][i] - sh * pa[1][i]
                pdy[i] = sh * pa[0][i] + ch * pa[1][i]
            ray_id = _cast(
                segments, dims, start, items, stamp, ray_id, x, y, pdx, pdy, MAX_RANGE, hidden
            )
        lowest = max_range if paper_rays else MAX_RANGE
        if not paper_rays:
            for i in range(5):
                lowest = min(lowest, hidden[i])
        for i in range(n_rays):
            value = readings[i]
            if paper_rays:  # one loop, as before layouts of any size
                lowest = min(lowest, value)
            if noisy_run:
                value = value + (value * noise[t, i] if relative else noise[t, i])
            if drop_run and dropped[t, i]:
                value = max_range
            sensors[t, i] = min(max(value, 0.0), max_range)
        if kind == SMOOTH:
            u = uniforms[t]
            d, r, rate = smooth_behaviour(lowest, u[0], u[1], u[2], u[3], rate)
        elif turn > 0.0:  # the lattice, the grid
            d, r = lattice_behaviour(lowest, uniforms[t, 0], turn)
        else:
            d, r = behaviour(lowest, uniforms[t, 0], uniforms[t, 1])
        motors[t, 0] = d
        motors[t, 1] = r
        if motor_run:
            ahead = readings[2] if paper_rays else hidden[2]  # the paper's ray straight ahead
            d = min(max(d + motor_noise[t, 0], 0.0), 0.99 * ahead)
            r = r + motor_noise[t, 1]
        # apply_motor(x, y, heading, d, r), reusing this step's cos and sin of the heading
        x = x + d * ch
        y = y + d * sh
        heading = wrap_angle(heading + r)
        if turn > 0.0 and not motor_run:  # rounding's drift, not a motor noise's
            heading = wrap_angle(snap_heading(heading, turn))
    return x, y, heading, rate


def walk(
    segments: np.ndarray,
    grid: tuple[np.ndarray, np.ndarray, np.ndarray],
    angles: np.ndarray,
    max_range: float,
    pose: tuple[float, float, float],
    uniforms: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, tuple[float, float, float]]:
    """``len(uniforms)`` noiseless steps of the paper's behaviour from ``pose``: readings (T, R),
    commands (T, 2), poses (T, 3) and the pose after. The one door to ``_rollout`` for a caller
    that walks in chunks of its own (``envs.tasks``' excursion); ``grid`` is
    ``WallGrid.arrays()`` of ``for_rays``' choice."""
    n, rays = len(uniforms), len(angles)
    readings, motors, poses = np.empty((n, rays)), np.empty((n, 2)), np.empty((n, 3))
    paper_rays = tuple(angles) == DEFAULT_LAYOUT.angles and max_range >= TURN_THRESHOLD
    none = np.zeros((0, rays))
    x, y, heading, _ = _rollout(
        segments, *grid, angles, max_range, paper_rays, *pose, uniforms, none, False,
        none.astype(bool), np.zeros((0, 2)), readings, motors, poses, PAPER, 0.0,
    )  # fmt: skip
    return readings, motors, poses, (x, y, heading)


def _heading(rng: np.random.Generator) -> float:
    """A heading uniform over (-pi, pi] (``uniform`` draws [-pi, pi); -pi is the same as pi)."""
    h = float(rng.uniform(-math.pi, math.pi))
    return math.pi if h == -math.pi else h


_REGIONS: dict[bytes, object] = {}  # start_region of each world seen, by its walls' digest


def _start_region(world: World):
    """``floorplan.start_region`` of ``world``, computed once per process."""
    from sensorimotor.sim.floorplan import start_region

    key = hashlib.sha256(
        np.asarray([world.width, world.height]).tobytes() + world.segments.tobytes()
    ).digest()
    if key not in _REGIONS:
        _REGIONS[key] = start_region(world)
    return _REGIONS[key]


def sample_start(world: World, rng: np.random.Generator) -> tuple[float, float, float]:
    """A start pose uniform over positions at least START_CLEARANCE from every wall, in the
    world's largest free region when its walls leave several (``floorplan.start_region``: an
    imported map's building interiors are left out; one region, as in the paper's worlds,
    draws as before)."""
    segments = world.segments
    region = _start_region(world)
    for _ in range(10_000):
        x, y = rng.uniform(0, world.width), rng.uniform(0, world.height)
        clear = point_segment_distance(segments, np.array([x]), np.array([y])).min()
        if clear >= START_CLEARANCE and (region is None or region.contains(x, y)):
            return x, y, _heading(rng)
    cells = free_start_cells(world)  # a sliver of free space: pick a free grid cell
    if region is not None:
        cells = cells[[region.contains(x, y) for x, y in cells]] if len(cells) else cells
    x, y = cells[rng.integers(len(cells))]
    return float(x), float(y), _heading(rng)


@dataclass(frozen=True)
class Rollout:
    """A recorded run: row t holds s_t, the command m_t chosen from it, and the pose of s_t."""

    sensors: np.ndarray  # (T, R) float64 readings
    motors: np.ndarray  # (T, 2) float64 (d, r) as chosen (before any motor noise)
    poses: np.ndarray  # (T, 3) float64 (x, y, heading)


NOISE_KINDS = ("absolute", "relative")


def check_noise(
    noise_std: float = 0.0, noise_kind: str = "absolute", dropout: float = 0.0, motor: float = 0.0
) -> None:
    """InputError naming the ``generate`` option out of range: a negative or infinite standard
    deviation, a dropout outside [0, 1], an unknown noise kind."""
    for name, value in (("--noise", noise_std), ("--motor-noise", motor)):
        if not (isinstance(value, int | float) and 0 <= value < math.inf):
            raise InputError(f"{name} must be a non-negative number, got {value!r}")
    if not (isinstance(dropout, int | float) and 0 <= dropout <= 1):
        raise InputError(f"--dropout must be a probability from 0 to 1, got {dropout!r}")
    if noise_kind not in NOISE_KINDS:
        kinds = ", ".join(NOISE_KINDS)
        raise InputError(f"--noise-kind must be one of {kinds}, got {noise_kind!r}")


def rollout(
    world: World,
    steps: int,
    seed: int | np.random.Generator = 0,
    layout: SensorLayout = DEFAULT_LAYOUT,
    noise_std: float = 0.0,
    chunk: int = 200_000,
    progress: Callable[[int], None] | None = None,
    noise_kind: str = "absolute",
    dropout: float = 0.0,
    motor_noise_std: float = 0.0,
    grid: WallGrid | None = None,
    behaviour: str = "paper",
) -> Rollout:
    """Run ``behaviour`` (``BEHAVIOURS``: the paper's, the smooth random motion or the lattice)
    for ``steps`` steps from a random start; float64 arrays.

    The generator draws the start pose, then ``UNIFORMS`` uniforms per step (the paper's
    behaviour two), chunk after chunk; the smooth behaviour's turning rate starts at 0 and is
    carried from chunk to chunk; the
    noises come from three child generators spawned from it (reading noise, dropouts, motor
    noise, in that order, and only when one is asked for), so their draws never interleave
    with the uniforms: the bytes depend on the seed alone, not on ``chunk``. The behaviour
    reads the paper's five rays whatever ``layout`` records, so one seed walks the same path
    with every layout (motor noise aside). Noise: ``noise_std`` is the standard deviation of a
    normal added to each reading (``noise_kind="absolute"``, units) or to it as a fraction
    (``"relative"``); a reading drops out (reads the range) with probability ``dropout``; the
    executed command is the recorded one plus a normal of ``motor_noise_std`` on ``d`` and on
    ``r`` (see ``_rollout``). ``grid`` overrides the choice of ``grid.for_rays`` (the
    world's grid, or none where the all-walls loop is faster): the same bits either way.
    ``progress(n)`` is called after each chunk with the number of steps done.
    """
    if steps < 1:
        raise ValueError(f"steps must be at least 1, got {steps}")
    check_noise(noise_std, noise_kind, dropout, motor_noise_std)
    kind = check_behaviour(behaviour)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    segments = np.ascontiguousarray(world.segments)
    if grid is None:
        grid = for_rays(world.grid, len(segments), len(layout.angles))
    dims, start_, items = grid.arrays()
    angles = np.asarray(layout.angles, dtype=np.float64)
    paper_rays = layout.angles == DEFAULT_LAYOUT.angles and layout.max_range >= TURN_THRESHOLD
    n = len(angles)
    sensors = np.empty((steps, n))
    motors = np.empty((steps, 2))
    poses = np.empty((steps, 3))
    x, y, heading = sample_start(world, rng)
    if TURNS[kind]:  # the lattice's headings from the start
        heading = float(wrap_angle(snap_heading(heading, TURNS[kind])))
    children = rng.spawn(3) if (noise_std or dropout or motor_noise_std) else None
    rate = 0.0
    for begin in range(0, steps, chunk):
        stop = min(begin + chunk, steps)
        c = stop - begin
        uniforms = rng.random((c, UNIFORMS[kind]))
        noise = children[0].normal(0.0, noise_std, (c, n)) if noise_std else np.zeros((0, n))
        dropped = children[1].random((c, n)) < dropout if dropout else np.zeros((0, n), bool)
        motor = (
            children[2].normal(0.0, motor_noise_std, (c, 2))
            if motor_noise_std
            else np.zeros((0, 2))
        )
        x, y, heading, rate = _rollout(
            segments,
            dims,
            start_,
            items,
            angles,
            layout.max_range,
            paper_rays,
            x,
            y,
            heading,
            uniforms,
            noise,
            noise_kind == "relative",
            dropped,
            motor,
            sensors[begin:stop],
            motors[begin:stop],
            poses[begin:stop],
            kind,
            rate,
        )
        if progress is not None:
            progress(stop)
    return Rollout(sensors, motors, poses)


def read_sensors(
    world: World, poses: np.ndarray, layout: SensorLayout = DEFAULT_LAYOUT
) -> np.ndarray:
    """Noiseless readings (P, R) at each pose (P, 3): the figures' and the analysis' ray caster
    (through the world's grid, as the rollout)."""
    poses = np.asarray(poses, dtype=np.float64).reshape(-1, 3)
    return _read_many(
        np.ascontiguousarray(world.segments),
        *for_rays(world.grid, len(world.segments), len(layout.angles)).arrays(),
        poses,
        np.asarray(layout.angles, dtype=np.float64),
        float(layout.max_range),
    )


@numba.njit(cache=True)
def _read_many(segments, dims, start, items, poses, angles, max_range):
    out = np.empty((poses.shape[0], angles.shape[0]))
    dx = np.empty(angles.shape[0])
    dy = np.empty(angles.shape[0])
    stamp = np.zeros(segments.shape[0], dtype=np.int64)
    ray_id = 1
    for p in range(poses.shape[0]):
        for i in range(angles.shape[0]):  # as cast_rays: one cos and sin of the sum per ray
            a = poses[p, 2] + angles[i]
            dx[i] = math.cos(a)
            dy[i] = math.sin(a)
        ray_id = _cast(
            segments, dims, start, items, stamp, ray_id, poses[p, 0], poses[p, 1], dx, dy,
            max_range, out[p],
        )  # fmt: skip
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
    chunk = max(1, min(chunk, 2**22 // (len(angles) * len(segments))))  # (C R, S) distances
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
