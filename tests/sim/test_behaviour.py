"""The second behaviour (``generate --behaviour smooth``): the paper's keeps its bytes, the smooth
one is seeded, turns smoothly, goes at the paper's speeds and never leaves the world."""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest
from test_core import crossings

from conftest import assert_one_line_error, run_cli
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.database import (
    BEHAVIOUR_TEXT,
    Database,
    generate,
    load_database,
    save_database,
)
from sensorimotor.sim.motion import motion_statistics, reflex_steps
from sensorimotor.sim.world import load_world

# sha256 of sensors, motors, poses and meta (less its version) of the paper's behaviour,
# computed with the code of main before there were two behaviours (commit 0cefbf0)
BEFORE = {
    "square": "f48d443ea023144b75b12c018a45782f3ba787e21f4f2738fead1628bf5b0a37",
    "rooms1 16 rays, noises": "9e11117cd88ea0e50829a94c2ac9e015428f69874990a15b72df35267705e0fe",
    "rooms2 64 rays, full turn": "60042ba106a7e9adaf4cfbb38c83ae9e8a45e9b550956b5e2b852fee9afca5da",
}
SETTINGS = {
    "square": ("square", {}),
    "rooms1 16 rays, noises": (
        "rooms1",
        {
            "layout": sim.spread_layout(16, 1.2),
            "noise_std": 0.05,
            "dropout": 0.01,
            "motor_noise_std": 0.02,
        },
    ),
    "rooms2 64 rays, full turn": ("rooms2", {"layout": sim.spread_layout(64, 2 * math.pi)}),
}


def digest(db: Database) -> str:
    h = hashlib.sha256()
    for a in (db.sensors, db.motors, db.poses):
        h.update(a.tobytes())
    h.update(json.dumps({k: v for k, v in db.meta.items() if k != "version"}).encode())
    return h.hexdigest()


@pytest.mark.parametrize("case", BEFORE)
def test_the_papers_behaviour_gives_the_bytes_of_before(case):
    world, settings = SETTINGS[case]
    db = generate(load_world(world), 3000, 7, **settings)
    assert digest(db) == BEFORE[case]
    assert "behaviour_name" not in db.meta  # and a database without it is the paper's
    assert db.behaviour == "paper"
    explicit = generate(load_world(world), 3000, 7, **settings, behaviour="paper")
    assert digest(explicit) == BEFORE[case]


def test_smooth_same_seed_same_bytes_whatever_the_chunks():
    w = load_world("rooms1")
    a = sim.rollout(w, 6_000, seed=5, behaviour="smooth")
    b = sim.rollout(w, 6_000, seed=5, behaviour="smooth", chunk=997)
    c = sim.rollout(w, 6_000, seed=6, behaviour="smooth")
    paper = sim.rollout(w, 6_000, seed=5)
    for name in ("sensors", "motors", "poses"):
        assert getattr(a, name).tobytes() == getattr(b, name).tobytes(), name
        assert not np.array_equal(getattr(a, name), getattr(c, name))
        assert not np.array_equal(getattr(a, name)[1:], getattr(paper, name)[1:])
    assert a.poses[0].tobytes() == paper.poses[0].tobytes()  # the same start pose


def test_smooth_database_records_its_behaviour(tmp_path):
    db = generate(load_world("square"), 2_000, 3, behaviour="smooth")
    assert db.meta["behaviour_name"] == "smooth"
    assert db.meta["behaviour"] == BEHAVIOUR_TEXT["smooth"]
    path = save_database(db, tmp_path / "s.npz")
    again = load_database(path)
    assert again.behaviour == "smooth"
    assert digest(again) == digest(generate(load_world("square"), 2_000, 3, behaviour="smooth"))
    bad = Database(db.sensors, db.motors, db.poses, {**db.meta, "behaviour_name": "zigzag"})
    save_database(bad, tmp_path / "bad.npz")
    with pytest.raises(InputError, match="behaviour_name must be one of paper, smooth"):
        load_database(tmp_path / "bad.npz")
    assert set(BEHAVIOUR_TEXT) == set(sim.BEHAVIOURS)


def test_an_unknown_behaviour_is_refused():
    with pytest.raises(InputError, match="--behaviour must be one of paper, smooth, lattice, grid, got 'ou'"):
        sim.rollout(load_world("square"), 10, behaviour="ou")


@pytest.fixture(scope="module")
def runs():
    w = load_world("rooms2")
    return w, {b: sim.rollout(w, 100_000, seed=11, behaviour=b) for b in sim.BEHAVIOURS}


def test_the_turning_rate_is_smooth_only_under_the_smooth_behaviour(runs):
    _, by = runs
    smooth = motion_statistics(by["smooth"].motors)
    paper = motion_statistics(by["paper"].motors)
    assert smooth["turn_lag1_autocorrelation"] == pytest.approx(sim.SMOOTH_A, abs=0.02)
    assert smooth["turn_lag1_autocorrelation"] > 0.7
    assert abs(paper["turn_lag1_autocorrelation"]) < 0.02
    assert smooth["turn_sd"] == pytest.approx(sim.SMOOTH_SD, rel=0.05)
    assert paper["turn_sd"] == pytest.approx(sim.PAPER_TURN_SD, rel=0.02)
    assert abs(smooth["turn_mean"]) < 0.01
    # the heading diffuses as fast as under the paper's behaviour over 50 free steps
    spread = {}
    for name, run in by.items():
        r = np.where(reflex_steps(run.motors), np.nan, run.motors[:, 1])
        sums = np.add.reduceat(r[: len(r) // 50 * 50], np.arange(0, len(r) // 50 * 50, 50))
        spread[name] = np.nanstd(sums)
    assert spread["smooth"] == pytest.approx(spread["paper"], rel=0.15)


def test_the_smooth_speed_is_the_papers(runs):
    _, by = runs
    m = by["smooth"].motors
    free = ~reflex_steps(m)
    d = m[free, 0]
    assert d.min() >= 0.0
    assert d.max() < 1.0
    deciles = np.histogram(d, bins=10, range=(0.0, 1.0))[0] / len(d)
    np.testing.assert_allclose(deciles, 0.1, atol=0.01)  # U(0, 1)
    assert 0.005 < 1 - free.mean() < 0.1  # the reflex happens
    turned = m[~free]
    assert (turned[:, 0] == 0.0).all()
    assert turned[:, 1].min() >= math.pi - math.pi / 10
    assert turned[:, 1].max() <= math.pi + math.pi / 10


def test_the_smooth_robot_never_leaves_the_world_nor_crosses_a_wall(runs):
    w, by = runs
    run = by["smooth"]
    p, d = run.poses, run.motors[:, 0]
    assert (d < run.sensors[:, 2]).all()  # each step stops short of the wall straight ahead
    stops = np.vstack([p[1:, :2], sim.apply_motor(*p[-1], *run.motors[-1])[:2]])
    assert crossings(p[:, :2], stops, w.segments) == 0
    assert p[:, 0].min() > 0
    assert p[:, 0].max() < w.width
    assert p[:, 1].min() > 0
    assert p[:, 1].max() < w.height
    np.testing.assert_allclose(sim.read_sensors(w, p[::97]), run.sensors[::97], atol=1e-9)


def test_generate_cli_names_and_records_the_behaviour(tmp_path):
    proc = run_cli("generate", "square", "--steps", "500", "--behaviour", "smooth", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert "smooth behaviour" in proc.stderr
    assert load_database(tmp_path / "square_s0_smooth.npz").behaviour == "smooth"
    bad = run_cli("generate", "square", "--steps", "500", "--behaviour", "zigzag", cwd=tmp_path)
    assert_one_line_error(bad, "--behaviour must be one of paper, smooth, lattice, grid, got 'zigzag'")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["square_s0_smooth.npz"]


def test_the_lattice_behaviour_keeps_its_headings_and_commands_on_the_lattice():
    """``generate --behaviour lattice`` (issue 37: a map in its own regime): a few exact
    commands, headings on the multiples of pi/6, seeded, and never through a wall."""
    w = load_world("rooms1")
    run = sim.rollout(w, 20_000, seed=3, behaviour="lattice")
    again = sim.rollout(w, 20_000, seed=3, behaviour="lattice", chunk=777)
    assert np.array_equal(run.poses, again.poses)
    assert np.array_equal(run.sensors, again.sensors)
    turns = run.poses[:, 2] / sim.LATTICE_TURN
    np.testing.assert_allclose(turns, np.round(turns), atol=1e-9)
    d, r = run.motors[:, 0], run.motors[:, 1]
    assert set(np.unique(d)) == {0.0, 0.9}
    allowed = {0.0, sim.LATTICE_TURN, -sim.LATTICE_TURN, *(math.pi + k * sim.LATTICE_TURN
                                                              for k in (-1, 0, 1))}  # fmt: skip
    assert all(min(abs(v - a) for a in allowed) < 1e-12 for v in np.unique(r))
    reflex = r > 2.0
    assert 0.0 < reflex.mean() < 0.1  # turns around at walls, and is not caught at one
    assert np.array_equal(reflex_steps(run.motors), reflex)  # each of its three reflex turns
    assert abs((d > 0).mean() - 0.5 * (1 - reflex.mean())) < 0.02  # forward half the free steps
    p = run.poses
    stops = np.vstack([p[1:, :2], sim.apply_motor(*p[-1], *run.motors[-1])[:2]])
    assert crossings(p[:, :2], stops, w.segments) == 0
    assert np.ptp(p[:, 0]) > 40  # it roams the world


def test_the_grid_behaviour_keeps_its_positions_on_a_grid_of_its_step():
    """``--behaviour grid``: the lattice with turns of pi/2, so every position the robot reaches
    lies on ``start + 0.9 Z^2`` (with the lattice's 12 headings they are dense), four headings,
    seeded, never through a wall, every room reached."""
    w = load_world("rooms1")
    run = sim.rollout(w, 20_000, seed=3, behaviour="grid")
    again = sim.rollout(w, 20_000, seed=3, behaviour="grid", chunk=777)
    assert np.array_equal(run.poses, again.poses)
    p = run.poses
    on_grid = (p[:, :2] - p[0, :2]) / sim.LATTICE_STEP
    np.testing.assert_allclose(on_grid, np.round(on_grid), atol=1e-6)
    assert len(np.unique(np.round(on_grid), axis=0)) > 1_000  # many places, each on the grid
    quarter = p[:, 2] / sim.GRID_TURN
    np.testing.assert_allclose(quarter, np.round(quarter), atol=1e-9)
    d, r = run.motors[:, 0], run.motors[:, 1]
    assert set(np.unique(d)) == {0.0, 0.9}
    allowed = [0.0, math.pi / 2, -math.pi / 2, math.pi, 1.5 * math.pi]
    assert all(min(abs(v - a) for a in allowed) < 1e-12 for v in np.unique(r))
    assert 0.0 < (r > 2.0).mean() < 0.1  # turns around at walls, and is not caught at one
    stops = np.vstack([p[1:, :2], sim.apply_motor(*p[-1], *run.motors[-1])[:2]])
    assert crossings(p[:, :2], stops, w.segments) == 0
    assert set(w.room_index(p[:, 0], p[:, 1])) == {0, 1, 2}
