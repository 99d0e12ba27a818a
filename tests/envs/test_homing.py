"""The homing task: the reset starts in a room and the excursion takes the robot out of it, the
way back is rewarded and detected, replaying the excursion backwards comes home, the same seed
gives the same bytes, a world without rooms is one line."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from conftest import assert_one_line_error
from sensorimotor.envs import TASKS, LaserTaskEnv
from sensorimotor.envs.laser_world import MAX_STEP, MAX_TURN
from sensorimotor.envs.tasks import (
    EXCURSION_EXTRA,
    guess_from_handover,
    handovers,
    memoryless_bound,
)
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.world import load_world


def rooms_of(world, poses: np.ndarray) -> np.ndarray:
    return world.room_index(poses[:, 0], poses[:, 1])


@pytest.mark.parametrize("world", ["rooms1", "rooms2"])
def test_the_reset_starts_in_a_room_and_the_excursion_takes_the_robot_out(world):
    env = LaserTaskEnv("homing", world)
    for seed in range(4):
        observation, info = env.reset(seed=seed)
        e = info["excursion"]
        rooms = rooms_of(env.world, e["poses"])  # (E,) the room of each excursion step
        assert rooms[0] == env.start_room >= 0  # it starts in a named room
        here = env._room()
        assert here >= 0
        assert here != env.start_room  # it ends in another one
        away = np.flatnonzero((rooms >= 0) & (rooms != env.start_room))
        assert len(e["readings"]) >= away[0] + EXCURSION_EXTRA  # out for 20 steps at least
        assert e["readings"].shape == (len(e["poses"]), 5)
        assert e["motors"].shape == (len(e["poses"]), 2)
        np.testing.assert_allclose(  # the readings were read where it was
            e["readings"], sim.read_sensors(env.world, e["poses"]), rtol=1e-6, atol=1e-5
        )
        np.testing.assert_array_equal(info["pose"], env.pose)  # the agent starts where it ended
        np.testing.assert_allclose(observation, sim.read_sensors(env.world, info["pose"])[0],
                                   rtol=1e-6, atol=1e-5)  # fmt: skip
        assert not info["is_success"]


def test_the_same_seed_gives_the_same_bytes():
    a, b = LaserTaskEnv("homing", "rooms1"), LaserTaskEnv("homing", "rooms1")
    (oa, ia), (ob, ib) = a.reset(seed=5), b.reset(seed=5)
    assert oa.tobytes() == ob.tobytes()
    for k in ("readings", "motors", "poses"):
        assert ia["excursion"][k].tobytes() == ib["excursion"][k].tobytes()
    other = a.reset(seed=6)[1]["excursion"]["poses"]
    assert other.shape != ia["excursion"]["poses"].shape or not np.array_equal(
        other, ia["excursion"]["poses"]
    )


def reverse_actions(excursion: dict, pose: np.ndarray) -> list[np.ndarray]:
    """Actions that drive the excursion's path backwards from ``pose``: face back along the
    last step, then for each step (last first) drive its distance and face back along the
    one before (a command moves, then turns)."""
    poses, motors = excursion["poses"], excursion["motors"]

    def turn(to: float, heading: float) -> float:
        return sim.wrap_angle(to - heading)

    def action(d: float, r: float) -> np.ndarray:
        return np.array([2 * d / MAX_STEP - 1, r / MAX_TURN])

    heading = float(pose[2])
    out = [action(0.0, turn(poses[-1, 2] + np.pi, heading))]
    for t in range(len(poses) - 1, -1, -1):
        back = poses[t - 1, 2] + np.pi if t else poses[0, 2]
        out.append(action(motors[t, 0], turn(back, poses[t, 2] + np.pi)))
    return out


def test_replaying_the_excursion_backwards_comes_home_and_only_then_succeeds():
    env = LaserTaskEnv("homing", "rooms1")
    _, info = env.reset(seed=2)
    rewards = []
    for a in reverse_actions(info["excursion"], info["pose"]):
        _, reward, terminated, _truncated, info = env.step(a)
        rewards.append(reward)
        if terminated:
            break
    assert terminated
    assert info["is_success"]
    assert env._room() == env.start_room  # inside the start room
    assert rewards == [0.0] * (len(rewards) - 1) + [1.0]  # +1 on entering it, nothing before


def test_success_is_being_inside_the_start_room():
    env = LaserTaskEnv("homing", "rooms1")
    env.reset(seed=0)
    start = env.start_room
    poses = np.array([[5.0, 5.0, 0.0], [5.0, 45.0, 0.0], [45.0, 25.0, 0.0]])  # sw, nw, east
    from sensorimotor.envs.tasks import Episodes

    e = Episodes(poses, None, np.full(3, start), np.zeros((3, 10, 10), bool))
    done = TASKS["homing"].success(env, e)
    assert done.tolist() == [k == start for k in range(3)]
    assert rooms_of(env.world, poses).tolist() == [0, 1, 2]


def test_homing_needs_a_world_with_rooms_one_line(cli, tmp_path):
    with pytest.raises(InputError, match="two named rooms"):
        LaserTaskEnv("homing", load_world("square"))
    proc = cli("rl", "homing", "--world", "square", "--features", "raw", "--out", tmp_path / "h")
    assert_one_line_error(proc, "homing", "two named rooms")


def test_the_gymnasium_id_is_registered_with_the_budget():
    env = gym.make(TASKS["homing"].env_id, world="rooms2")
    assert env.spec.max_episode_steps == TASKS["homing"].budget == 200
    _, info = env.reset(seed=1)
    assert "excursion" in info


def test_the_hand_over_room_tells_a_memoryless_agent_most_of_the_way_home():
    """Rooms1's rooms are a chain (southwest - northwest - east): a start at an end is handed
    over in the middle, and a start in the middle at an end; guessing from the hand-over room
    wins every episode but those that start at the end not guessed, about 0.75."""
    counts = handovers("rooms1", 200)
    sw, nw, east = range(3)
    assert counts.sum() == 200
    assert counts[nw, nw] == 0  # the middle: handed over at an end
    assert counts[nw].sum() > 0
    assert counts[sw, nw] == counts[sw].sum() > 0  # the ends: handed over in the middle
    assert counts[east, nw] >= 0.95 * counts[east].sum()
    assert 0.6 < memoryless_bound(counts) < 0.9
    assert TASKS["homing"].no_memory is guess_from_handover  # what rl.json records
    assert TASKS["corner"].no_memory is None
    # by hand: the columns' largest counts 3 + 5 + 5 of 20
    assert memoryless_bound(np.array([[0, 5, 0], [3, 0, 4], [1, 2, 5]])) == 13 / 20
