"""The simulation core: ray casting by hand, the numba kernels against the plain-Python oracle,
and the paper's claims on long runs (no wall is ever crossed, the behaviour rule holds)."""

from __future__ import annotations

import io
import math

import numpy as np
import pytest

import reference_sim as ref
from sensorimotor.sim import core as sim
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.sim.grid import NO_GRID
from sensorimotor.sim.world import (
    BUILTIN_WORLDS,
    load_world,
    point_segment_distance,
    world_from_dict,
)

ANGLES = sim.SENSOR_ANGLES
# A world with oblique walls (none parallel to an axis, none crossing another).
OBLIQUE = world_from_dict(
    {
        "name": "oblique",
        "size": [50, 40],
        "walls": [[5, 5, 20, 30], [49.5, 0.5, 30, 35], [10, 38, 45, 36], [25, 3, 40, 18]],
    }
)
WORLDS = {name: load_world(name) for name in BUILTIN_WORLDS} | {"oblique": OBLIQUE}


def world(walls, size=50):
    return world_from_dict({"size": size, "walls": walls})


def run_kernel(
    w, angles, start, uniforms, noise, sensors, motors, poses, relative=False, dropped=None,
    motor=None, grid=NO_GRID, max_range=10.0,
):  # fmt: skip
    """``sim._rollout`` on the all-walls loop (or ``grid``), no noise unless given."""
    n = len(angles)
    return sim._rollout(
        np.ascontiguousarray(w.segments), *grid.arrays(), np.asarray(angles, dtype=np.float64),
        max_range, tuple(angles) == sim.DEFAULT_LAYOUT.angles, *start, uniforms,
        noise if noise is not None else np.zeros((0, n)), relative,
        dropped if dropped is not None else np.zeros((0, n), dtype=bool),
        motor if motor is not None else np.zeros((0, 2)), sensors, motors, poses, sim.PAPER, 0.0,
    )[:3]  # fmt: skip


def readings(w, x, y, heading):
    """The 5 readings at one pose, through the public caster."""
    return sim.read_sensors(w, np.array([x, y, heading]))[0]


# ---------------------------------------------------------------- ray casting, by hand


def test_perpendicular_wall():
    # 5 from the right wall x = 50, facing it: the middle ray is the perpendicular, a ray at
    # angle a meets the wall after 5 / cos(a).
    got = readings(load_world("square"), 45.0, 25.0, 0.0)
    expected = [5 / math.cos(a) for a in ANGLES]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    assert got[2] == 5.0


def test_perpendicular_wall_through_cast_rays():
    w = load_world("square")
    out = np.full(5, -1.0)
    sim.cast_rays(w.segments, 25.0, 3.0, -math.pi / 2, ANGLES, 10.0, out)  # facing the bottom
    np.testing.assert_allclose(out, [3 / math.cos(a) for a in ANGLES], rtol=0, atol=1e-12)
    # a 6-unit range cuts the outer rays (5 / cos(0.6) = 6.06), not the others (5.23)
    sim.cast_rays(w.segments, 25.0, 5.0, -math.pi / 2, ANGLES, 6.0, out)
    np.testing.assert_allclose(out, [6.0, 5 / math.cos(0.3), 5.0, 5 / math.cos(0.3), 6.0])


def test_oblique_wall_at_45_degrees():
    # Wall on the line y = x - 10, from (20, 10) to (30, 20). From (20, 15) a ray at angle a
    # reaches the line where 15 + t sin a = 20 + t cos a - 10, i.e. t = 5 / (cos a - sin a):
    # 5 straight ahead (meeting (25, 15)); for a = 0.6, 19.2 > 10 (and it would pass beyond
    # (30, 20)), the right wall is 30 / cos(0.6) = 36 away: nothing within range.
    got = readings(world([[20, 10, 30, 20]]), 20.0, 15.0, 0.0)
    expected = [5 / (math.cos(a) - math.sin(a)) for a in ANGLES[:4]] + [10.0]
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(got[:3], [3.5972, 3.9973, 5.0], atol=1e-4)


def test_oblique_wall_seen_from_its_normal():
    # The same wall seen along its normal (-1, 1) / sqrt(2) from (30, 10): distance from the
    # line x - y - 10 = 0 is |30 - 10 - 10| / sqrt(2) = 5 sqrt(2), met at (25, 15).
    got = readings(world([[20, 10, 30, 20]]), 30.0, 10.0, 3 * math.pi / 4)
    assert got[2] == pytest.approx(5 * math.sqrt(2), abs=1e-12)
    # ray at angle a from the normal: the distance grows as 1 / cos a, while it stays on the wall
    # (t sin a along the wall <= 5 sqrt(2) to either end)
    np.testing.assert_allclose(got, [5 * math.sqrt(2) / math.cos(a) for a in ANGLES], atol=1e-12)


def test_ray_parallel_to_a_wall_does_not_hit_it():
    # A wall along y = 20 from x = 10 to 14, a vertical wall at x = 15 behind it.
    w = world([[10, 20, 14, 20], [15, 10, 15, 30]])
    # on the wall's own line (collinear): the ray slides along it and reads the wall behind
    assert readings(w, 8.0, 20.0, 0.0)[2] == 7.0
    # parallel, off the line: same
    assert readings(w, 8.0, 21.0, 0.0)[2] == 7.0
    # parallel with nothing behind within range: the range
    w = world([[10, 20, 14, 20]])
    assert readings(w, 8.0, 20.0, 0.0)[2] == 10.0
    assert readings(w, 12.0, 21.0, math.pi)[2] == 10.0


def test_ray_through_a_wall_end_point_hits_it():
    w = world([[20, 10, 20, 20]])
    # the middle ray meets the wall exactly at its end points (20, 20) and (20, 10): s = 1, s = 0
    assert readings(w, 15.0, 20.0, 0.0)[2] == 5.0
    assert readings(w, 15.0, 10.0, 0.0)[2] == 5.0
    # a hair beyond the end: it passes
    assert readings(w, 15.0, 20.0 + 1e-9, 0.0)[2] == 10.0
    assert readings(w, 15.0, 10.0 - 1e-9, 0.0)[2] == 10.0
    # and the oracle agrees on the end points
    assert ref.cast(w.segments.tolist(), 15.0, 20.0, 1.0, 0.0, 10.0) == 5.0
    assert ref.cast(w.segments.tolist(), 15.0, 10.0, 1.0, 0.0, 10.0) == 5.0


def test_corner_hit_by_two_walls():
    # towards the corner (50, 50) at 45 degrees: 5 sqrt(2), where both walls end
    got = readings(load_world("square"), 45.0, 45.0, math.pi / 4)
    assert got[2] == pytest.approx(5 * math.sqrt(2), abs=1e-12)


def test_nothing_within_range_reads_exactly_the_range():
    w = load_world("square")
    poses = np.array([[25.0, 25.0, h] for h in np.linspace(-math.pi, math.pi, 37)])
    got = sim.read_sensors(w, poses)
    assert got.shape == (37, 5)
    assert (got == 10.0).all()


def test_wall_behind_is_not_seen():
    # 5 from the right wall, facing away: the left wall is 45 away
    assert (readings(load_world("square"), 45.0, 25.0, math.pi) == 10.0).all()


def test_custom_layout():
    layout = sim.SensorLayout(angles=(0.0, math.pi / 2), max_range=30.0)
    got = sim.read_sensors(load_world("square"), np.array([[45.0, 10.0, 0.0]]), layout)
    np.testing.assert_allclose(got, [[5.0, 30.0]])


def test_wrap_angle_and_apply_motor():
    assert sim.wrap_angle(math.pi) == math.pi
    assert sim.wrap_angle(-math.pi) == math.pi
    assert sim.wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)
    assert sim.wrap_angle(-7.0) == pytest.approx(-7.0 + 2 * math.pi)
    x, y, h = sim.apply_motor(1.0, 2.0, math.pi / 2, 0.5, math.pi)
    assert (x, y) == pytest.approx((1.0, 2.5))
    assert h == pytest.approx(-math.pi / 2)


def test_behaviour_by_hand():
    assert sim.behaviour(0.99, 0.3, 0.0) == (0.0, pytest.approx(0.9 * math.pi))
    assert sim.behaviour(0.5, 0.3, 0.5) == (0.0, pytest.approx(math.pi))
    assert sim.behaviour(1.0, 0.3, 0.0) == (0.3, pytest.approx(-math.pi / 6))
    assert sim.behaviour(7.0, 0.75, 0.75) == (0.75, pytest.approx(math.pi / 12))


# ---------------------------------------------------------------- numba core vs the oracle


@pytest.mark.parametrize("name", WORLDS)
def test_readings_match_the_reference_on_random_poses(name):
    w = WORLDS[name]
    rng = np.random.default_rng(123)
    n = 10_000
    poses = np.stack(
        [
            rng.uniform(0, w.width, n),
            rng.uniform(0, w.height, n),
            rng.uniform(-math.pi, math.pi, n),
        ],
        axis=1,
    )
    got = sim.read_sensors(w, poses)
    segments = [tuple(s) for s in w.segments.tolist()]
    angles = ANGLES.tolist()
    expected = np.array([ref.cast_rays(segments, x, y, h, angles, 10.0) for x, y, h in poses])
    assert got.shape == (n, 5)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-9)
    # the test must be able to fail: readings are spread, many below the range
    assert 0.1 < (got < 10.0).mean() < 0.99
    assert got.min() < 0.1


@pytest.mark.parametrize("name", WORLDS)
def test_rollout_kernel_matches_the_reference_step_by_step(name):
    w = WORLDS[name]
    steps = 3_000
    rng = np.random.default_rng(7)
    start = sim.sample_start(w, rng)
    uniforms = rng.random((steps, 2))
    noise = np.zeros((steps, 5))
    sensors, motors, poses = np.empty((steps, 5)), np.empty((steps, 2)), np.empty((steps, 3))
    end = run_kernel(w, ANGLES, start, uniforms, noise, sensors, motors, poses)
    r_sensors, r_motors, r_poses = ref.rollout(
        [tuple(s) for s in w.segments.tolist()], ANGLES.tolist(), 10.0, start, uniforms.tolist()
    )
    for t in range(steps):  # step by step: the first divergence is the one reported
        np.testing.assert_allclose(poses[t], r_poses[t], rtol=0, atol=1e-9, err_msg=f"step {t}")
        np.testing.assert_allclose(sensors[t], r_sensors[t], rtol=0, atol=1e-9, err_msg=f"{t}")
        np.testing.assert_allclose(motors[t], r_motors[t], rtol=0, atol=1e-9, err_msg=f"{t}")
    last = ref.apply_motor(*r_poses[-1], *r_motors[-1])
    np.testing.assert_allclose(end, last, rtol=0, atol=1e-9)
    # both behaviours happened: turning around and moving on
    turns = np.asarray(motors)[:, 0] == 0.0
    assert 0.01 < turns.mean() < 0.5


def test_noisy_rollout_kernel_matches_the_reference():
    w = WORLDS["oblique"]
    steps = 2_000
    rng = np.random.default_rng(8)
    start = sim.sample_start(w, rng)
    uniforms = rng.random((steps, 2))
    noise = rng.normal(0.0, 0.3, (steps, 5))
    sensors, motors, poses = np.empty((steps, 5)), np.empty((steps, 2)), np.empty((steps, 3))
    run_kernel(w, ANGLES, start, uniforms, noise, sensors, motors, poses)
    r_sensors, r_motors, r_poses = ref.rollout(
        [tuple(s) for s in w.segments.tolist()],
        ANGLES.tolist(),
        10.0,
        start,
        uniforms.tolist(),
        noise.tolist(),
    )
    np.testing.assert_allclose(sensors, r_sensors, rtol=0, atol=1e-9)
    np.testing.assert_allclose(motors, r_motors, rtol=0, atol=1e-9)
    np.testing.assert_allclose(poses, r_poses, rtol=0, atol=1e-9)
    assert (sensors == 0.0).any()  # clipped at 0 somewhere near a wall
    assert (sensors == 10.0).any()


def test_rollout_matches_the_reference_from_the_seed():
    """``sim.rollout`` = start pose from the generator, then two uniforms per step."""
    w = load_world("rooms1")
    steps = 2_000
    run = sim.rollout(w, steps, seed=42)
    rng = np.random.default_rng(42)
    start = sim.sample_start(w, rng)
    uniforms = rng.random((steps, 2)).tolist()
    r_sensors, r_motors, r_poses = ref.rollout(
        [tuple(s) for s in w.segments.tolist()], ANGLES.tolist(), 10.0, start, uniforms
    )
    np.testing.assert_allclose(run.sensors, r_sensors, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.motors, r_motors, rtol=0, atol=1e-9)
    np.testing.assert_allclose(run.poses, r_poses, rtol=0, atol=1e-9)


def test_noise_is_recorded_but_the_behaviour_sees_the_true_readings():
    w = load_world("square")
    steps = 3_000
    noisy = sim.rollout(w, steps, seed=3, noise_std=0.5)
    clean_at_poses = sim.read_sensors(w, noisy.poses)
    diff = noisy.sensors - clean_at_poses
    inside = (clean_at_poses > 3) & (clean_at_poses < 7)  # no clipping within 6 sigma
    assert inside.sum() > 1_000
    assert diff[inside].std() == pytest.approx(0.5, rel=0.05)
    assert abs(diff[inside].mean()) < 0.05
    assert noisy.sensors.min() >= 0.0
    assert noisy.sensors.max() <= 10.0
    # the behaviour followed the noiseless readings
    turn = clean_at_poses.min(axis=1) < 1.0
    assert ((noisy.motors[:, 0] == 0.0) == turn).all()


# ---------------------------------------------------------------- the paper's claims, 1 M steps


def distance_to_segments(px, py, ax, ay, bx, by):
    """Distance from points to segments, broadcast; a zero-length segment is its point."""
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    u = ((px - ax) * ex + (py - ay) * ey) / np.where(length2 > 0, length2, 1.0)
    u = np.clip(u, 0.0, 1.0)
    return np.hypot(px - (ax + u * ex), py - (ay + u * ey))


def crossings(starts: np.ndarray, stops: np.ndarray, segments: np.ndarray) -> int:
    """How many step segments ``starts -> stops`` (N, 2) meet a wall segment (S, 4).

    Two segments meet when each one's ends lie strictly on opposite sides of the other's line
    (signs of the cross products), or when an end point of one lies on the other (distance 0;
    this covers touching, collinear overlap and a step of length 0 standing on a wall).
    """
    px, py = starts[:, 0:1], starts[:, 1:2]  # (N, 1)
    qx, qy = stops[:, 0:1], stops[:, 1:2]
    ax, ay, bx, by = (segments[None, :, i] for i in range(4))  # (1, S)

    def cross(ux, uy, vx, vy):
        return ux * vy - uy * vx

    o1 = cross(bx - ax, by - ay, px - ax, py - ay)  # (N, S)
    o2 = cross(bx - ax, by - ay, qx - ax, qy - ay)
    o3 = cross(qx - px, qy - py, ax - px, ay - py)
    o4 = cross(qx - px, qy - py, bx - px, by - py)
    proper = (o1 * o2 < 0) & (o3 * o4 < 0)
    touch = (
        (distance_to_segments(px, py, ax, ay, bx, by) < 1e-12)
        | (distance_to_segments(qx, qy, ax, ay, bx, by) < 1e-12)
        | (distance_to_segments(ax, ay, px, py, qx, qy) < 1e-12)
        | (distance_to_segments(bx, by, px, py, qx, qy) < 1e-12)
    )
    return int((proper | touch).sum())


def test_crossing_detector_can_fail():
    segments = np.array([[0.0, 0.0, 10.0, 0.0]])
    starts = np.array([[5.0, 1.0], [5.0, 1.0], [5.0, 1.0], [12.0, 0.0], [-1.0, 0.0], [5.0, 0.0]])
    stops = np.array([[5.0, -1.0], [5.0, 0.0], [6.0, 0.5], [13.0, 0.0], [1.0, 0.0], [5.0, 0.0]])
    # through, touching, clear, collinear beyond the end, collinear overlap, standing on it
    per_row = [crossings(starts[i : i + 1], stops[i : i + 1], segments) for i in range(6)]
    assert per_row == [1, 1, 0, 0, 1, 1]


@pytest.fixture(scope="module", params=BUILTIN_WORLDS)
def long_run(request):
    w = load_world(request.param)
    return w, sim.rollout(w, 1_000_000, seed=2024)


def test_long_run_never_crosses_a_wall(long_run):
    w, run = long_run
    poses = run.poses
    # the step t -> t + 1 and the step from the last row to the pose its command leads to
    stops = np.empty((len(poses), 2))
    stops[:-1] = poses[1:, :2]
    last = sim.apply_motor(*poses[-1], *run.motors[-1])
    stops[-1] = last[:2]
    total = 0
    for lo in range(0, len(poses), 100_000):
        total += crossings(poses[lo : lo + 100_000, :2], stops[lo : lo + 100_000], w.segments)
    assert total == 0
    # every pose is inside the world and off the walls
    assert poses[:, 0].min() > 0
    assert poses[:, 0].max() < w.width
    assert poses[:, 1].min() > 0
    assert poses[:, 1].max() < w.height


def test_long_run_obeys_the_behaviour_rule(long_run):
    _, run = long_run
    s, d, r = run.sensors, run.motors[:, 0], run.motors[:, 1]
    assert run.sensors.dtype == np.float64
    assert s.shape == (1_000_000, 5)
    assert s.min() > 0
    assert s.max() <= 10.0
    turn = s.min(axis=1) < 1.0
    assert 0.01 < turn.mean() < 0.5  # both branches happen
    assert (d[turn] == 0.0).all()
    assert r[turn].min() >= math.pi - math.pi / 10
    assert r[turn].max() <= math.pi + math.pi / 10
    go = ~turn
    assert d[go].min() >= 0.0
    assert d[go].max() < 1.0
    assert r[go].min() >= -math.pi / 6
    assert r[go].max() <= math.pi / 6
    # the draws fill their ranges (uniform: mean in the middle)
    assert d[go].mean() == pytest.approx(0.5, abs=0.01)
    assert r[go].mean() == pytest.approx(0.0, abs=0.01)
    assert r[turn].mean() == pytest.approx(math.pi, abs=0.01)


def test_long_run_poses_follow_from_the_motor_commands(long_run):
    _, run = long_run
    p, m = run.poses, run.motors
    heading = p[:, 2]
    assert heading.min() > -math.pi
    assert heading.max() <= math.pi
    np.testing.assert_allclose(p[1:, 0], p[:-1, 0] + m[:-1, 0] * np.cos(heading[:-1]), atol=1e-9)
    np.testing.assert_allclose(p[1:, 1], p[:-1, 1] + m[:-1, 0] * np.sin(heading[:-1]), atol=1e-9)
    turned = (heading[1:] - heading[:-1] - m[:-1, 1] + math.pi) % (2 * math.pi) - math.pi
    np.testing.assert_allclose(turned, 0.0, atol=1e-9)


def test_long_run_visits_every_cell(long_run):
    w, run = long_run
    ix = np.clip((run.poses[:, 0] / w.width * 10).astype(int), 0, 9)
    iy = np.clip((run.poses[:, 1] / w.height * 10).astype(int), 0, 9)
    visits = np.bincount(ix * 10 + iy, minlength=100)
    assert (visits > 0).all(), np.flatnonzero(visits == 0)


def test_long_run_readings_match_the_caster_at_the_poses(long_run):
    """The recorded readings are what ``read_sensors`` sees at the recorded poses."""
    w, run = long_run
    rows = np.random.default_rng(0).integers(0, len(run.poses), 20_000)
    np.testing.assert_allclose(sim.read_sensors(w, run.poses[rows]), run.sensors[rows], atol=1e-9)


# ---------------------------------------------------------------- reproducibility


def test_same_seed_same_bytes_different_seed_different():
    w = load_world("rooms2")
    a = sim.rollout(w, 20_000, seed=5)
    b = sim.rollout(w, 20_000, seed=5)
    c = sim.rollout(w, 20_000, seed=6)
    for name in ("sensors", "motors", "poses"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes()
        assert not np.array_equal(getattr(a, name), getattr(c, name))


@pytest.mark.parametrize("noise_std", [0.0, 0.2])
def test_chunk_size_does_not_change_the_bytes(noise_std):
    w = load_world("rooms1")
    whole = sim.rollout(w, 10_000, seed=9, noise_std=noise_std)
    for chunk in (1, 997, 5_000):
        parts = sim.rollout(w, 10_000, seed=9, noise_std=noise_std, chunk=chunk)
        for name in ("sensors", "motors", "poses"):
            assert getattr(parts, name).tobytes() == getattr(whole, name).tobytes(), (chunk, name)


def test_a_generator_can_be_passed_instead_of_a_seed():
    w = load_world("square")
    a = sim.rollout(w, 1_000, seed=np.random.default_rng(11))
    b = sim.rollout(w, 1_000, seed=11)
    assert a.poses.tobytes() == b.poses.tobytes()


def test_saved_databases_of_one_seed_hold_the_same_bytes(tmp_path):
    w = load_world("rooms1")
    paths = [tmp_path / "a.npz", tmp_path / "b.npz", tmp_path / "c.npz"]
    for path, seed in zip(paths, (4, 4, 5), strict=True):
        save_database(generate(w, 5_000, seed=seed), path)
    a, b, c = (np.load(p, allow_pickle=False) for p in paths)
    for key in ("sensors", "motors", "poses", "meta"):
        assert a[key].tobytes() == b[key].tobytes(), key
    for key in ("sensors", "motors", "poses"):
        assert a[key].tobytes() != c[key].tobytes(), key
    # and a loaded database equals a freshly generated one, as float32
    db = load_database(paths[0])
    fresh = sim.rollout(w, 5_000, seed=4)
    assert db.sensors.tobytes() == fresh.sensors.astype(np.float32).tobytes()
    buf = io.BytesIO()
    np.save(buf, db.poses)
    assert len(buf.getvalue()) > 5_000 * 3 * 4


def test_start_is_clear_of_the_walls():
    for name, w in WORLDS.items():
        rng = np.random.default_rng(1)
        for _ in range(200):
            x, y, h = sim.sample_start(w, rng)
            assert point_segment_distance(w.segments, np.array([x]), np.array([y])).min() >= 1.0
            assert -math.pi < h <= math.pi, name


def test_start_heading_minus_pi_becomes_pi():
    class Edge:  # a generator whose uniform draws land on the lower bound
        def uniform(self, low, high):
            return low + 1.0 if low == 0 else low

    x, y, h = sim.sample_start(load_world("square"), Edge())
    assert (x, y) == (1.0, 1.0)
    assert h == math.pi


def test_steps_must_be_positive():
    with pytest.raises(ValueError, match="at least 1"):
        sim.rollout(load_world("square"), 0)


# ---------------------------------------------------------------- the walls' grid index


def many_walls(n: int, side: float, seed: int = 0):
    """A world of ``n`` walls, half axis-aligned on integer points (junctions, shared ends,
    collinear runs), half at any angle."""
    rng = np.random.default_rng(seed)
    walls = []
    while len(walls) < n:
        x0, y0 = rng.uniform(0, side, 2)
        if rng.random() < 0.5:
            x0, y0, k = round(x0), round(y0), int(rng.integers(1, 8))
            wall = (
                [x0, y0, min(x0 + k, side), y0]
                if rng.random() < 0.5
                else [x0, y0, x0, min(y0 + k, side)]
            )
        else:
            a, k = rng.uniform(0, 2 * math.pi), rng.uniform(0.5, 6)
            wall = [
                x0,
                y0,
                float(np.clip(x0 + k * math.cos(a), 0, side)),
                float(np.clip(y0 + k * math.sin(a), 0, side)),
            ]
        if wall[:2] != wall[2:]:
            walls.append(wall)
    return world_from_dict({"name": f"walls{n}", "size": side, "walls": walls})


@pytest.mark.parametrize("name", [*WORLDS, "many"])
def test_the_grid_reads_the_same_bits_as_the_all_walls_loop(name):
    """Every reading through the grid is the all-walls loop's to the bit: random poses, poses on
    cell edges and wall ends (integer points), rays at every angle, short and long ranges."""
    from sensorimotor.sim.grid import build_grid

    w = WORLDS[name] if name != "many" else many_walls(400, 80.0)
    rng = np.random.default_rng(5)
    n = 4000
    poses = np.stack(
        [rng.uniform(0, w.width, n), rng.uniform(0, w.height, n), rng.uniform(-4, 4, n)], 1
    )
    poses[:500, :2] = np.round(poses[:500, :2])
    angles = np.linspace(-math.pi, math.pi, 90, endpoint=False)
    segments = np.ascontiguousarray(w.segments)
    for cell in (0.0, 1.0, 2.5):
        grid = build_grid(segments, w.width, w.height, force=True, cell=cell)
        assert grid.nx > 0
        for max_range in (10.0, 200.0):
            plain = sim._read_many(segments, *NO_GRID.arrays(), poses, angles, max_range)
            fast = sim._read_many(segments, *grid.arrays(), poses, angles, max_range)
            assert (plain.view(np.int64) == fast.view(np.int64)).all()
            assert (plain < max_range).mean() > 0.2  # walls are hit: the check can fail


def test_a_world_of_many_walls_rolls_out_through_its_grid_as_without():
    w = many_walls(300, 60.0, seed=1)
    assert w.grid.nx > 0  # big enough for a grid; the paper's worlds are not
    assert all(WORLDS[name].grid.nx == 0 for name in BUILTIN_WORLDS)
    layout = sim.spread_layout(32, 2 * math.pi)
    fast = sim.rollout(w, 3000, seed=2, layout=layout)
    plain = sim.rollout(w, 3000, seed=2, layout=layout, grid=NO_GRID)
    for a, b in zip(
        (fast.sensors, fast.motors, fast.poses),
        (plain.sensors, plain.motors, plain.poses),
        strict=True,
    ):
        assert a.tobytes() == b.tobytes()
    assert (fast.motors[:, 0] == 0).mean() > 0.05  # it meets walls


def test_a_start_is_drawn_in_the_largest_free_region_never_in_a_sealed_room():
    """An imported map's building interiors are free space a walk started inside never leaves:
    a start is drawn in the world's largest free region; a world of one region draws as before."""
    from sensorimotor.sim.world import world_from_dict

    box = [[0.0, 0.0, 20.0, 0.0], [20.0, 0.0, 20.0, 20.0], [20.0, 20.0, 0.0, 20.0],
           [0.0, 20.0, 0.0, 0.0]]  # fmt: skip
    sealed = world_from_dict({"name": "sealed", "size": [50.0, 50.0], "walls": box})
    region = sim._start_region(sealed)
    assert region is not None
    assert not region.contains(10.0, 10.0)  # the 20 x 20 box is the smaller region
    assert region.contains(40.0, 40.0)
    starts = [sim.sample_start(sealed, np.random.default_rng(s))[:2] for s in range(200)]
    assert not any(x < 20 and y < 20 for x, y in starts)  # 16 % of the world, never drawn
    for name in ("square", "rooms1", "rooms2"):
        assert sim._start_region(load_world(name)) is None


def test_walk_in_chunks_is_the_rollout_from_the_same_pose_and_uniforms():
    """``walk``, the public door to the kernel for callers that walk in chunks: two chunks give
    the rows of ``rollout`` (same start, same uniforms), the pose after each chunk joins them."""
    w = load_world("rooms1")
    steps = 300
    whole = sim.rollout(w, steps, seed=4, chunk=steps)
    rng = np.random.default_rng(4)
    pose = sim.sample_start(w, rng)
    uniforms = rng.random((steps, 2))
    grid = sim.for_rays(w.grid, len(w.segments), 5).arrays()
    angles = np.asarray(sim.DEFAULT_LAYOUT.angles)
    first = sim.walk(w.segments, grid, angles, 10.0, pose, uniforms[:120])
    second = sim.walk(w.segments, grid, angles, 10.0, first[3], uniforms[120:])
    for k, rows in enumerate((whole.sensors, whole.motors, whole.poses)):
        np.testing.assert_array_equal(np.concatenate([first[k], second[k]]), rows)
    assert first[3] == tuple(second[2][0])  # the pose after a chunk is the next one's first
