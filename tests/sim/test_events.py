"""Ground-truth events on poses placed by hand in small worlds, and against a Python oracle."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from sensorimotor.sim import core as sim
from sensorimotor.sim import events as ev
from sensorimotor.sim.core import SENSOR_ANGLES, SensorLayout
from sensorimotor.sim.world import load_world, world_from_dict


def make_world(walls, size=20):
    return world_from_dict({"name": "test", "size": size, "walls": walls})


def toward(x, y, px, py, offset=0.0):
    """A pose at (x, y) heading at (px, py), turned by ``offset`` rad."""
    return [x, y, math.atan2(py - y, px - x) + offset]


def as_set(points):
    return {(round(float(x), 6), round(float(y), 6)) for x, y in points}


# ---------------------------------------------------------------------------------------------
# Corner points and free wall ends


def test_builtin_corners_and_free_ends():
    square, rooms1, rooms2 = (load_world(n) for n in ("square", "rooms1", "rooms2"))
    outer = {(0, 0), (50, 0), (50, 50), (0, 50)}
    assert as_set(ev.corner_points(square)) == outer
    assert ev.free_wall_ends(square).shape == (0, 2)
    assert as_set(ev.corner_points(rooms1)) == outer | {(25, 0), (0, 25)}
    assert as_set(ev.free_wall_ends(rooms1)) == {(25, 35), (15, 25)}
    # (25, 25) is a T-junction: the vertical wall's end on the horizontal wall's interior
    assert as_set(ev.corner_points(rooms2)) == outer | {(0, 25), (17, 0), (33, 0), (25, 25)}
    assert as_set(ev.free_wall_ends(rooms2)) == {(38, 25), (17, 17), (33, 17), (25, 42)}


def test_inner_l_junction_and_crossing_are_corners():
    world = make_world([[5, 5, 10, 5], [10, 5, 10, 12], [2, 15, 8, 15], [5, 13, 5, 18]])
    corners = as_set(ev.corner_points(world))
    assert (10, 5) in corners  # two inner walls meeting end to end (listed once)
    assert (5, 15) in corners  # two inner walls crossing
    assert len(corners) == 6
    assert as_set(ev.free_wall_ends(world)) == {
        (5, 5),
        (10, 12),
        (2, 15),
        (8, 15),
        (5, 13),
        (5, 18),
    }


# ---------------------------------------------------------------------------------------------
# In view: fan, range, line of sight


def test_corner_straight_ahead_is_in_view():
    square = make_world([])
    poses = np.array([toward(5, 5, 0, 0), toward(15, 4, 20, 0)])
    assert ev.corner_in_view(square, poses).tolist() == [True, True]


def test_corner_just_inside_and_just_outside_the_fan():
    square = make_world([])
    inside = [toward(5, 5, 0, 0, offset) for offset in (0.59, -0.59)]
    outside = [toward(5, 5, 0, 0, offset) for offset in (0.61, -0.61, math.pi)]
    assert ev.corner_in_view(square, np.array(inside)).all()
    assert not ev.corner_in_view(square, np.array(outside)).any()


def test_corner_beyond_range_is_not_in_view():
    square = make_world([])
    near, far = toward(7, 7, 0, 0), toward(7.2, 7.2, 0, 0)  # 9.9 and 10.2 from (0, 0)
    assert ev.corner_in_view(square, np.array([near, far])).tolist() == [True, False]


def test_corner_hidden_behind_a_wall():
    world = make_world([[1, 4, 4, 1]])  # a free wall across the line of sight to (0, 0)
    pose = np.array([toward(5, 5, 0, 0)])
    assert ev.points_in_view(world, pose, np.array([[0.0, 0.0]])).tolist() == [[False]]
    assert not ev.corner_in_view(world, pose)[0]
    assert ev.wall_end_in_view(world, pose)[0]  # its ends (1, 4) and (4, 1) are in view
    clear = np.array([toward(5, 5, 0, 0)])
    assert ev.corner_in_view(make_world([]), clear)[0]


def test_free_wall_end_in_view():
    world = make_world([[10, 0, 10, 8]])  # free end (10, 8); corner (10, 0)
    poses = np.array(
        [
            toward(13, 14, 10, 8),  # looking at the end
            toward(13, 14, 10, 8, math.pi),  # turned away
            toward(10, 13, 10, 8),  # looking straight down the wall at its end
            toward(4, 3, 10, 8),  # from beside the wall
        ]
    )
    assert ev.wall_end_in_view(world, poses).tolist() == [True, False, True, True]
    assert ev.wall_end_in_view(make_world([]), poses).tolist() == [False] * 4


def test_t_junction_is_a_corner_only_from_its_concave_side():
    world = make_world([[0, 10, 15, 10], [8, 10, 8, 18]])  # T-junction at (8, 10)
    below = toward(8, 5, 8, 10)  # the junction is a point on a flat wall from here
    above_left = toward(5, 13, 8, 10)
    above_right = toward(11, 13, 8, 10)
    poses = np.array([below, above_left, above_right])
    point = np.array([[8.0, 10.0]])
    assert ev.points_in_view(world, poses, point)[:, 0].all()  # the point itself is visible
    assert ev.corner_in_view(world, poses).tolist() == [False, True, True]


def test_points_in_view_matches_a_plain_python_oracle():
    world = load_world("rooms2")
    rng = np.random.default_rng(3)
    poses = np.column_stack(
        [rng.uniform(1, 49, 3000), rng.uniform(1, 49, 3000), rng.uniform(-np.pi, np.pi, 3000)]
    )
    points = np.concatenate([ev.corner_points(world), ev.free_wall_ends(world)])
    got = ev.points_in_view(world, poses, points)

    def crosses(p, q, a, b):  # closed segments p-q and a-b intersect (general position)
        def side(o, s, t):
            return (s[0] - o[0]) * (t[1] - o[1]) - (s[1] - o[1]) * (t[0] - o[0])

        return side(p, q, a) * side(p, q, b) <= 0 and side(a, b, p) * side(a, b, q) <= 0

    expected = np.zeros_like(got)
    for n, (x, y, h) in enumerate(poses):
        for j, (px, py) in enumerate(points):
            r = math.hypot(px - x, py - y)
            rel = (math.atan2(py - y, px - x) - h + math.pi) % (2 * math.pi) - math.pi
            if not (abs(rel) <= 0.6 and r <= 10):
                continue
            stop = (px - 1e-4 * (px - x) / r, py - 1e-4 * (py - y) / r)  # just short of the point
            blocked = any(crosses((x, y), stop, s[:2], s[2:]) for s in world.segments)
            expected[n, j] = not blocked
    assert expected.sum() > 100  # the sample exercises both answers
    np.testing.assert_array_equal(got, expected)


def test_fan_follows_the_angles_argument():
    square = make_world([])
    pose = np.array([toward(5, 5, 0, 0, 0.8)])
    corner = np.array([[0.0, 0.0]])
    assert not ev.points_in_view(square, pose, corner)[0, 0]
    assert ev.points_in_view(square, pose, corner, angles=np.array([-1.0, 1.0]))[0, 0]
    assert not ev.points_in_view(square, pose, corner, angles=SENSOR_ANGLES, max_range=5)[0, 0]


def test_corners_and_wall_ends_in_view_follow_the_layout():
    rooms1 = load_world("rooms1")
    poses = sim.rollout(rooms1, 3000, seed=1).poses
    short = SensorLayout(max_range=4.0)
    wide = SensorLayout(angles=(-1.5, -0.75, 0.0, 0.75, 1.5))
    for in_view in (ev.corner_in_view, ev.wall_end_in_view):
        paper = in_view(rooms1, poses)
        np.testing.assert_array_equal(paper, in_view(rooms1, poses, SensorLayout()))
        near, broad = in_view(rooms1, poses, short), in_view(rooms1, poses, wide)
        assert not (near & ~paper).any()  # nearer: a subset
        assert near.sum() < paper.sum()
        assert not (paper & ~broad).any()  # wider: a superset
        assert broad.sum() > paper.sum()


# ---------------------------------------------------------------------------------------------
# Nothing in view, distance behind


def test_nothing_in_view():
    sensors = np.array([[10, 10, 10, 10, 10], [10, 10, 9.99, 10, 10], [0.5] * 5], np.float32)
    assert ev.nothing_in_view(sensors).tolist() == [True, False, False]
    assert ev.nothing_in_view(sensors / 10, max_range=1.0).tolist() == [True, False, False]


def test_distance_behind():
    world = make_world([[10, 0, 10, 8]], size=20)
    poses = np.array(
        [
            [3, 5, 0.0],  # left wall 3 behind
            [3, 5, math.pi],  # facing the left wall: the inner wall is 7 behind
            [3, 12, math.pi],  # above the inner wall: the right wall is 17 behind
            [4, 4, math.pi / 4],  # the corner (0, 0) is sqrt(32) behind
            [15, 2, math.pi / 2],  # bottom wall 2 behind
        ]
    )
    np.testing.assert_allclose(
        ev.distance_behind(world, poses), [3, 7, 17, math.sqrt(32), 2], atol=1e-9
    )
    np.testing.assert_allclose(ev.distance_behind(world, poses, max_range=5), [3, 5, 5, 5, 2])


def test_bad_pose_shape_is_refused():
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        ev.corner_in_view(make_world([]), np.zeros((4, 2)))


def test_events_of_100k_poses_take_well_under_a_second():
    world = load_world("rooms2")
    rng = np.random.default_rng(0)
    n = 100_000
    poses = np.column_stack(
        [rng.uniform(1, 49, n), rng.uniform(1, 49, n), rng.uniform(-np.pi, np.pi, n)]
    )
    ev.corner_in_view(world, poses[:10])  # compile / warm the numba cache
    ev.distance_behind(world, poses[:10])
    start = time.perf_counter()
    ev.corner_in_view(world, poses)
    ev.wall_end_in_view(world, poses)
    ev.distance_behind(world, poses)
    assert time.perf_counter() - start < 1.0


def test_points_in_view_is_the_same_in_chunks(monkeypatch):
    world = load_world("rooms1")
    rng = np.random.default_rng(5)
    poses = np.column_stack(
        [rng.uniform(1, 49, 500), rng.uniform(1, 49, 500), rng.uniform(-np.pi, np.pi, 500)]
    )
    points = ev.corner_points(world)
    whole = ev.points_in_view(world, poses, points)
    monkeypatch.setattr(ev, "CHUNK", 7)
    np.testing.assert_array_equal(ev.points_in_view(world, poses, points), whole)
    assert whole.any()


def test_a_one_sided_fan_sees_only_its_own_side():
    world = make_world([], size=50)
    corner = [[0.0, 0.0]]
    left = toward(5, 5, 0, 0, offset=-0.5)  # the corner 0.5 rad to the left of the heading
    right = toward(5, 5, 0, 0, offset=0.5)
    seen = ev.points_in_view(world, np.array([left, right]), corner, angles=np.array([0.0, 1.0]))
    assert seen[:, 0].tolist() == [True, False]


def test_a_wall_just_short_of_a_corner_hides_it():
    pose, corner = np.array([toward(5, 5, 0, 0)]), [[0.0, 0.0]]
    blocked = make_world([[0.2, 0.4, 0.4, 0.2]], size=50)  # crosses the sight line 0.4 early
    assert not ev.points_in_view(blocked, pose, corner)[0, 0]
    assert ev.points_in_view(make_world([], size=50), pose, corner)[0, 0]
