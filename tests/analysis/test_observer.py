"""The ideal observer: a particle filter that finds the robot from its stream alone."""

import numpy as np
import pytest

from sensorimotor.analysis.observer import observe
from sensorimotor.sim.core import spread_layout
from sensorimotor.sim.database import load_database

STEPS, SETTLED, PARTICLES = 600, 300, 8000
WINDOWS = (0, 7500, 10000)  # starts within the fixture's 20,000 steps


@pytest.fixture(scope="module")
def db(rooms1_db_path):
    return load_database(rooms1_db_path)


def _window(db, start):
    rows = slice(start, start + STEPS)
    return db.sensors[rows], db.motors[rows], db.poses[rows]


def _scores(world, belief, poses):
    """Room accuracy of the belief's likeliest room and the median position error, after the
    filter has settled."""
    room = world.room_index(poses[SETTLED:, 0], poses[SETTLED:, 1])
    inside = room >= 0
    guess = belief[SETTLED:, 4:].argmax(axis=1)
    error = np.linalg.norm(belief[SETTLED:, :2] - poses[SETTLED:, :2], axis=1)
    return float((guess[inside] == room[inside]).mean()), float(np.median(error))


@pytest.fixture(scope="module")
def told(db):
    """The observer with the commands on each window: (belief, room accuracy, median error)."""
    out = []
    for start in WINDOWS:
        sensors, motors, poses = _window(db, start)
        belief = observe(db.world, sensors, motors, particles=PARTICLES, seed=0)
        out.append((belief, *_scores(db.world, belief, poses)))
    return out


def test_the_observer_with_the_commands_finds_the_room_and_the_position(db, told):
    for belief, _, _ in told:
        assert belief.shape == (STEPS, 4 + len(db.world.rooms))
        assert np.isfinite(belief).all()
        shares = belief[:, 4:].sum(axis=1)
        assert ((shares > 0.9) & (shares <= 1 + 1e-9)).all()  # a belief, spread over the rooms
    # a finite filter may lock onto a wrong place for a while: most windows, not every one
    found = [room >= 0.95 and error < 0.5 for _, room, error in told]
    assert sum(found) >= 2, [(room, error) for _, room, error in told]


def test_without_the_commands_the_observer_knows_less_of_the_position(db, told):
    w = next(i for i, (_, room, error) in enumerate(told) if room >= 0.95 and error < 0.5)
    sensors, motors, poses = _window(db, WINDOWS[w])
    blind = observe(db.world, sensors, motors, commands=False, particles=PARTICLES, seed=0)
    assert np.isfinite(blind).all()
    assert _scores(db.world, blind, poses)[1] > 2 * told[w][2]


def test_same_seed_same_belief_and_another_seed_another(db):
    world, (sensors, motors, _) = db.world, _window(db, 0)
    a, b, c = (observe(world, sensors[:50], motors[:50], particles=500, seed=s) for s in (3, 3, 4))
    assert a.tobytes() == b.tobytes()
    assert not np.array_equal(a, c)


def test_the_observer_refuses_a_stream_that_does_not_fit_its_lasers(db):
    world, (sensors, motors, _) = db.world, _window(db, 0)
    with pytest.raises(ValueError, match="do not fit"):
        observe(world, sensors[:, :3], motors)
    with pytest.raises(ValueError, match="do not fit"):
        observe(world, sensors, motors[:10])
    with pytest.raises(ValueError, match="paper's lasers"):
        observe(world, sensors, motors, spread_layout(5, 2.0), commands=False)
    with pytest.raises(ValueError, match="particles"):
        observe(world, sensors, motors, particles=0)
