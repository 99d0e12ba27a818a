"""The Gymnasium environment: Gymnasium's own checker, registration, seeding, rendering, walls
that are never crossed, and the paper's behaviour replaying a database's rows."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from sensorimotor.envs import LASER_WORLD_ID, LaserWorldEnv, paper_policy
from sensorimotor.envs.laser_world import WALL_MARGIN
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.world import (
    BUILTIN_WORLDS,
    load_world,
    point_segment_distance,
    world_from_dict,
)

# check_env recommends actions in [-1, 1] for RL libraries; the env keeps the paper's units
# (d in [0, 1], r in [-1.1 pi, 1.1 pi]) on purpose, as its docstring says. Only that is ignored.
NORMALISED_ACTIONS = "ignore:.*we recommend using a symmetric and normalized space"


@pytest.mark.filterwarnings(NORMALISED_ACTIONS)
@pytest.mark.parametrize("name", BUILTIN_WORLDS)
def test_gymnasium_env_checker_passes(name):
    env = gym.make(LASER_WORLD_ID, world=name)
    check_env(env.unwrapped)
    env.close()


@pytest.mark.filterwarnings(NORMALISED_ACTIONS)
def test_gymnasium_env_checker_passes_with_noise_and_rendering():
    env = gym.make(LASER_WORLD_ID, world="rooms1", noise=0.1, render_mode="rgb_array")
    check_env(env.unwrapped)
    env.close()


def test_make_by_id_with_the_world_as_a_keyword():
    env = gym.make(LASER_WORLD_ID, world="rooms2")
    assert env.spec.max_episode_steps == 10_000
    assert env.unwrapped.world == load_world("rooms2")
    observation, info = env.reset(seed=0)
    assert observation.shape == (5,)
    assert observation.dtype == np.float32
    assert observation in env.observation_space
    assert info["pose"].shape == (3,)
    assert info["collision"] is False


def test_make_imports_the_module_itself():
    env = gym.make(f"sensorimotor.envs:{LASER_WORLD_ID}", world="square")
    assert isinstance(env.unwrapped, LaserWorldEnv)


def test_episode_is_truncated_never_terminated():
    env = gym.make(LASER_WORLD_ID, world="square", max_episode_steps=5)
    env.reset(seed=0)
    ends = [env.step(env.action_space.sample())[2:4] for _ in range(5)]
    assert ends == [(False, False)] * 4 + [(False, True)]


def test_world_as_object_or_toml_path(tmp_path):
    path = tmp_path / "box.toml"
    path.write_text("size = [30, 20]\nwalls = [[10, 0, 10, 12]]\n")
    env = LaserWorldEnv(world=path)
    assert (env.world.width, env.world.height) == (30.0, 20.0)
    same = LaserWorldEnv(world=env.world)
    assert same.world == env.world


def test_bad_arguments_are_input_errors():
    with pytest.raises(InputError, match="unknown world"):
        LaserWorldEnv(world="nowhere")
    with pytest.raises(InputError, match="noise"):
        LaserWorldEnv(noise=-1.0)
    with pytest.raises(InputError, match="render_mode"):
        LaserWorldEnv(render_mode="human")


def run(env, seed, steps=300):
    """Observations, rewards and poses of ``steps`` seeded random actions."""
    env.action_space.seed(seed)
    observation, info = env.reset(seed=seed)
    out = [(observation, 0.0, info["pose"])]
    for _ in range(steps):
        observation, reward, _, _, info = env.step(env.action_space.sample())
        out.append((observation, reward, info["pose"]))
    return out


@pytest.mark.parametrize("noise", [0.0, 0.2])
def test_same_seed_same_episode(noise):
    a = run(LaserWorldEnv("rooms1", noise=noise), seed=7)
    b = run(LaserWorldEnv("rooms1", noise=noise), seed=7)
    c = run(LaserWorldEnv("rooms1", noise=noise), seed=8)
    for (oa, ra, pa), (ob, rb, pb) in zip(a, b, strict=True):
        np.testing.assert_array_equal(oa, ob)
        np.testing.assert_array_equal(pa, pb)
        assert ra == rb == 0.0
    assert not np.array_equal(a[0][2], c[0][2])


def test_observation_is_the_core_reading_at_the_pose():
    env = LaserWorldEnv("rooms2")
    env.action_space.seed(1)
    observation, info = env.reset(seed=1)
    for _ in range(200):
        truth = sim.read_sensors(env.world, info["pose"][None])[0]
        np.testing.assert_allclose(observation, truth, rtol=1e-6, atol=1e-6)
        observation, _, _, _, info = env.step(env.action_space.sample())


def test_noise_is_added_to_readings_and_clipped_to_the_range():
    env = LaserWorldEnv("square", noise=0.5)
    observation, info = env.reset(seed=3, options={"pose": (25.0, 25.0, 0.0)})
    truth = sim.read_sensors(env.world, info["pose"][None])[0]  # all 10: nothing in range
    assert np.all(observation <= 10.0)
    assert np.all(observation >= 0.0)
    assert not np.allclose(observation, truth)


def test_reset_at_a_given_pose():
    env = LaserWorldEnv("square")
    observation, info = env.reset(options={"pose": (45.0, 25.0, 2 * math.pi)})
    np.testing.assert_allclose(info["pose"], [45.0, 25.0, 0.0], atol=1e-12)
    assert observation[2] == pytest.approx(5.0)
    for bad in [(60.0, 25.0, 0.0), (0.0, 25.0, 0.0), (10.0, float("nan"), 0.0), (1.0, 2.0)]:
        with pytest.raises(ValueError, match="pose"):
            env.reset(options={"pose": bad})


# ------------------------------------------------------------------ walls are never crossed


def crossed(start: np.ndarray, stop: np.ndarray, segments: np.ndarray) -> bool:
    """Whether the step ``start -> stop`` meets a wall (S, 4): a proper crossing, or touching."""
    (px, py), (qx, qy) = start, stop
    for ax, ay, bx, by in segments:
        o1 = (bx - ax) * (py - ay) - (by - ay) * (px - ax)
        o2 = (bx - ax) * (qy - ay) - (by - ay) * (qx - ax)
        o3 = (qx - px) * (ay - py) - (qy - py) * (ax - px)
        o4 = (qx - px) * (by - py) - (qy - py) * (bx - px)
        if o1 * o2 < 0 and o3 * o4 < 0:
            return True
    distance = point_segment_distance(segments, np.array([qx]), np.array([qy]))
    return bool(distance.min() == 0.0)


def test_crossing_detector_can_fail():
    wall = np.array([[0.0, 0.0, 10.0, 0.0]])
    assert crossed(np.array([5.0, 1.0]), np.array([5.0, -1.0]), wall)
    assert crossed(np.array([5.0, 1.0]), np.array([5.0, 0.0]), wall)
    assert not crossed(np.array([5.0, 1.0]), np.array([6.0, 0.5]), wall)


@pytest.mark.parametrize("name", ["rooms1", "rooms2"])
def test_ten_thousand_random_actions_never_cross_a_wall(name):
    env = LaserWorldEnv(name)
    env.action_space.seed(0)
    _, info = env.reset(seed=0)
    world = env.world
    collisions = 0
    for _ in range(10_000):
        start = info["pose"][:2]
        _, _, _, _, info = env.step(env.action_space.sample())
        stop = info["pose"][:2]
        assert 0.0 < stop[0] < world.width
        assert 0.0 < stop[1] < world.height
        assert not crossed(start, stop, env.segments), (start, stop)
        collisions += info["collision"]
    assert collisions > 0  # random actions do run into walls: the clipping was exercised


def test_a_translation_into_a_wall_stops_just_short_of_it():
    env = LaserWorldEnv("square")
    env.reset(options={"pose": (48.5, 10.0, 0.0)})
    _, _, _, _, info = env.step(np.array([1.0, 0.0]))
    assert info["collision"] is False  # 1.5 ahead: a full step of 1 is free
    _, _, _, _, info = env.step(np.array([1.0, 0.3]))
    assert info["collision"] is True
    x, _, heading = info["pose"]
    assert x == pytest.approx(50.0 - WALL_MARGIN, abs=1e-9)
    assert x < 50.0
    assert heading == pytest.approx(0.3)  # the rotation is applied all the same
    _, _, _, _, info = env.step(np.array([1.0, 0.0]))
    assert info["collision"] is True
    assert info["pose"][0] < 50.0


def test_into_a_corner_and_onto_a_free_wall_end():
    env = LaserWorldEnv(world_from_dict({"size": 20, "walls": [[10, 0, 10, 10]]}))
    env.reset(options={"pose": (15.0, 15.0, math.pi / 4)})  # straight at the corner (20, 20)
    for _ in range(10):
        _, _, _, _, info = env.step(np.array([1.0, 0.0]))
        assert np.all(info["pose"][:2] < 20.0)
    assert info["collision"] is True
    env.reset(options={"pose": (5.0, 10.0, 0.0)})  # along y = 10, at the wall end (10, 10)
    for _ in range(10):
        start = np.array(env.pose[:2])
        _, _, _, _, info = env.step(np.array([1.0, 0.0]))
        assert not crossed(start, info["pose"][:2], env.segments)
    assert info["collision"] is True
    assert info["pose"][0] == pytest.approx(10.0 - WALL_MARGIN, abs=1e-9)


def test_actions_outside_the_box_are_clipped_and_nan_refused():
    env = LaserWorldEnv("square")
    env.reset(options={"pose": (25.0, 25.0, 0.0)})
    _, _, _, _, info = env.step(np.array([-3.0, 0.0]))  # d < 0: no motion
    assert info["pose"][0] == 25.0
    _, reward, _, _, info = env.step(np.array([7.0, 0.0]))  # d > 1: one unit
    assert info["pose"][0] == pytest.approx(26.0)
    assert reward == 0.0  # no task: the paper's agent learns from prediction alone
    env.reset(options={"pose": (49.5, 25.0, 0.0)})
    _, reward, _, _, info = env.step(np.array([1.0, 0.0]))  # into the wall
    assert info["collision"]
    assert reward == 0.0
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0]))
    for bad in (0.5, [0.5, 0.1, 0.0]):
        with pytest.raises(ValueError, match=r"action must be \(d, r\), 2 numbers"):
            env.step(bad)


# --------------------------------------------------------------- the paper's behaviour


@pytest.mark.parametrize(("name", "seed"), [("square", 0), ("rooms1", 1), ("rooms2", 5)])
def test_paper_policy_replays_the_rollout_of_a_database(name, seed):
    world = load_world(name)
    steps = 3000
    run_ = sim.rollout(world, steps, seed)
    rng = np.random.default_rng(seed)  # the rollout's generator: start pose, then uniforms
    env = LaserWorldEnv(world)
    observation, info = env.reset(options={"pose": sim.sample_start(world, rng)})
    sensors, motors, poses = [], [], []
    for _ in range(steps):
        sensors.append(observation)
        poses.append(info["pose"])
        action = paper_policy(observation, rng)
        motors.append(action)
        assert action in env.action_space
        observation, _, _, _, info = env.step(action)
        assert info["collision"] is False  # the behaviour never runs into a wall
    np.testing.assert_array_equal(np.array(poses), run_.poses)  # bit for bit
    np.testing.assert_array_equal(np.array(motors), run_.motors)
    np.testing.assert_allclose(np.array(sensors), run_.sensors, rtol=1e-6, atol=1e-6)


def test_with_noise_the_policy_on_the_true_readings_walks_as_generate_does():
    world, steps, seed, noise = load_world("rooms1"), 3000, 3, 0.5
    run_ = sim.rollout(world, steps, seed, noise_std=noise)
    rng = np.random.default_rng(seed)
    env = LaserWorldEnv(world, noise=noise)
    observation, info = env.reset(seed=seed, options={"pose": sim.sample_start(world, rng)})
    poses, motors, error = [], [], []
    for _ in range(steps):
        poses.append(info["pose"])
        inside = (info["readings"] > 2) & (info["readings"] < 8)  # far from clipping
        error.extend(observation[inside] - info["readings"][inside])
        motors.append(paper_policy(info["readings"], rng))
        observation, _, _, _, info = env.step(motors[-1])
        assert info["collision"] is False
    np.testing.assert_array_equal(np.array(poses), run_.poses)
    np.testing.assert_array_equal(np.array(motors), run_.motors)
    assert 0.48 < np.std(error) < 0.52  # while the observations are noisy


def test_paper_policy_turns_around_near_a_wall():
    rng = np.random.default_rng(0)
    d, r = paper_policy(np.array([5, 5, 0.5, 5, 5], dtype=np.float32), rng)
    assert d == 0.0
    assert math.pi * 0.9 <= r <= math.pi * 1.1
    d, r = paper_policy(np.full(5, 10, dtype=np.float32), rng)
    assert 0.0 <= d < 1.0
    assert abs(r) <= math.pi / 6


# ------------------------------------------------------------------------------- render


def test_render_is_an_rgb_image_of_walls_rays_and_red_dots():
    env = gym.make(LASER_WORLD_ID, world="rooms1", render_mode="rgb_array")
    env.reset(options={"pose": (20.0, 15.0, 0.0)})  # the wall x = 25 is 5 ahead
    image = env.render()
    assert image.ndim == 3
    assert image.shape[2] == 3
    assert image.dtype == np.uint8
    white = np.all(image == 255, axis=2)
    assert (~white).mean() > 0.01  # walls, rays and the agent are drawn
    red = (image[..., 0] > 200) & (image[..., 1] < 80) & (image[..., 2] < 80)
    assert red.sum() > 20  # the red dots of the perceived points
    env.step(np.array([1.0, 1.0]))
    assert not np.array_equal(env.render(), image)
    env.close()


def test_render_draws_each_red_dot_on_the_wall_its_ray_hits():
    env = gym.make(LASER_WORLD_ID, world="square", render_mode="rgb_array")
    env.reset(options={"pose": (3.0, 20.0, math.pi - 0.4)})  # rays hit the wall x = 0 apart
    env.render()
    (dots,) = [
        c for ax in env.unwrapped._figure.axes for c in ax.collections if c.get_gid() == "percept"
    ]
    points = dots.get_offsets()  # (5, 2)
    segments = load_world("square").segments
    on_wall = point_segment_distance(segments, points[:, 0], points[:, 1]).min(axis=1)
    assert np.allclose(on_wall, 0.0, atol=1e-9)
    env.close()


def test_render_without_a_mode_warns_and_returns_none():
    env = gym.make(LASER_WORLD_ID, world="square")
    env.reset(seed=0)
    with pytest.warns(UserWarning, match="render_mode"):
        assert env.render() is None


def test_a_start_pose_is_checked_against_the_worlds_own_width_and_height():
    env = LaserWorldEnv(world_from_dict({"name": "wide", "size": [50, 20], "walls": []}))
    _, info = env.reset(options={"pose": (45.0, 10.0, 0.0)})  # x beyond the height: inside
    assert info["pose"][0] == 45.0
    with pytest.raises(ValueError, match="pose"):
        env.reset(options={"pose": (10.0, 30.0, 0.0)})  # y beyond the height


# --- the tasks (envs/tasks.py) -------------------------------------------------------------
from sensorimotor.envs import TASKS, LaserTaskEnv  # noqa: E402
from sensorimotor.envs.laser_world import MAX_TURN  # noqa: E402
from sensorimotor.envs.tasks import EXPLORE_SUCCESS, GRID, at_corner  # noqa: E402

STILL = np.array([-1.0, 0.0], dtype=np.float32)  # d = 0, r = 0


@pytest.mark.parametrize("task", list(TASKS))
def test_tasks_pass_the_checker_without_a_warning(task):
    """The [-1, 1] action box: check_env has nothing to say (pytest turns warnings to errors)."""
    env = gym.make(TASKS[task].env_id, world="rooms1")
    check_env(env.unwrapped)
    assert env.spec.max_episode_steps == TASKS[task].budget
    assert env.unwrapped.task is TASKS[task]
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (2,), np.float32)


def test_the_box_is_rescaled_to_d_and_r_and_clipped():
    env = LaserTaskEnv("explore", "rooms1")
    env.reset(options={"pose": (10.0, 10.0, 0.0)})
    _, _, _, _, info = env.step(np.array([1.0, 0.0]))  # d = 1
    np.testing.assert_allclose(info["pose"], [11.0, 10.0, 0.0])
    _, _, _, _, info = env.step(np.array([0.0, 0.5]))  # d = 0.5, r = 0.55 pi
    np.testing.assert_allclose(info["pose"], [11.5, 10.0, 0.5 * MAX_TURN])
    _, _, _, _, info = env.step(np.array([-7.0, -9.0]))  # clipped: d = 0, r = -1.1 pi
    np.testing.assert_allclose(info["pose"], [11.5, 10.0, -0.5 * MAX_TURN])
    with pytest.raises(ValueError, match="finite"):
        env.step(np.array([np.nan, 0.0]))


@pytest.mark.parametrize("task", ["corner", "explore"])
def test_extreme_actions_never_cross_a_wall(task):
    """Full-speed actions at the box's corners and beyond it, for many steps, in rooms2."""
    env = LaserTaskEnv(task, "rooms2")
    rng = np.random.default_rng(1)
    choices = np.array([[1, 0], [1, 1], [1, -1], [5, 0.01], [-1, 1], [1, 0.05]], dtype=float)
    _, info = env.reset(seed=0)
    collisions = 0
    for _ in range(3000):
        start = info["pose"][:2]
        _, _, terminated, _, info = env.step(choices[rng.integers(len(choices))])
        stop = info["pose"][:2]
        assert 0.0 < stop[0] < env.world.width
        assert 0.0 < stop[1] < env.world.height
        assert not crossed(start, stop, env.segments), (start, stop)
        collisions += info["collision"]
        if terminated:
            _, info = env.reset()
    assert collisions > 100  # the walls were hit, again and again


def test_corner_succeeds_near_a_corner_facing_it_and_only_then():
    env = LaserTaskEnv("corner", "rooms1")
    toward = math.atan2(-1.0, -1.0)  # from (1, 1) toward the corner (0, 0)
    env.reset(options={"pose": (1.0, 1.0, toward + math.pi)})  # back to it
    _, reward, terminated, _, info = env.step(STILL)
    assert not terminated
    assert not info["is_success"]
    assert reward == 0.0
    env.reset(options={"pose": (1.0, 1.0, toward)})
    _, reward, terminated, _, info = env.step(STILL)
    assert terminated
    assert info["is_success"]
    assert reward == 1.0
    env.reset(options={"pose": (3.0, 3.0, toward)})  # 4.2 units away: walk 1 unit toward it
    _, reward, terminated, _, _ = env.step(np.array([1.0, 0.0]))
    assert not terminated
    assert reward == pytest.approx(0.05)


def test_corner_starts_are_redrawn_where_the_task_is_done():
    env = LaserTaskEnv("corner", "square")
    for seed in range(200):
        _, info = env.reset(seed=seed)
        assert not info["is_success"]
        assert not at_corner(env, np.array([env.pose]))[0]


def test_doorway_succeeds_through_the_opening_not_through_the_wall():
    env = LaserTaskEnv("doorway", "rooms1")  # southwest, northwest, east
    env.reset(options={"pose": (20.0, 24.5, math.pi / 2)})  # below the opening
    _, reward, terminated, _, info = env.step(np.array([1.0, 0.0]))
    assert terminated
    assert info["is_success"]
    assert reward == 1.0
    assert env.world.room_index(*info["pose"][:2, None])[0] == 1  # northwest
    env.reset(options={"pose": (10.0, 24.5, math.pi / 2)})  # below the wall
    _, reward, terminated, _, info = env.step(np.array([1.0, 0.0]))
    assert info["collision"]
    assert not terminated
    assert not info["is_success"]
    assert reward == 0.0


def test_doorway_needs_two_named_rooms():
    with pytest.raises(InputError, match="two named rooms"):
        LaserTaskEnv("doorway", "square")
    with pytest.raises(InputError, match="unknown task"):
        LaserTaskEnv("dance", "rooms1")


def test_explore_counts_cells_and_succeeds_at_the_documented_coverage():
    env = LaserTaskEnv("explore", "square")
    _, info = env.reset(options={"pose": (0.5, 2.5, 0.0)})  # cell (0, 0), facing +x
    assert info["coverage"] == 1 / GRID**2
    total = 0.0
    for _ in range(48):  # 48 units east along y = 2.5: cells (1..9, 0)
        _, reward, terminated, _, info = env.step(np.array([1.0, 0.0]))
        total += reward
        assert not terminated
    assert info["coverage"] == pytest.approx(10 / GRID**2)
    assert total == pytest.approx(0.9)
    assert info["is_success"] == (10 / GRID**2 >= EXPLORE_SUCCESS)
    env.visited[:4] = True  # 40 % of the cells
    _, reward, _, _, info = env.step(STILL)
    assert info["is_success"]
    assert reward == 0.0
    assert EXPLORE_SUCCESS <= 0.4
