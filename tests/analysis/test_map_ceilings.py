"""The map's ceilings and baselines (``analysis.map.ceilings``, ``analysis.map.baselines``):
Monte-Carlo localisation with and without odometry, the true-pose planner, the back-off
models and the recurrent net."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from sensorimotor.analysis.map import ceilings, planning
from sensorimotor.analysis.map.baselines import rnn_bits
from sensorimotor.analysis.map.cells import (
    Steps,
    _histories,
    baseline_bits,
    ngram_bits,
    ngram_probs,
)
from sensorimotor.analysis.map.planning import Moves, start_goal_pairs
from sensorimotor.sim.core import DEFAULT_LAYOUT
from sensorimotor.sim.database import generate
from sensorimotor.sim.world import load_world, world_from_dict

# a 24 x 12 box cut by a wall with a 4-wide gap at its top: a small room and a big one
TWO_ROOMS = {
    "name": "two",
    "size": [24, 12],
    "walls": [[8, 0, 8, 8]],
    "rooms": [{"name": "small", "rect": [0, 0, 8, 12]}, {"name": "big", "rect": [8, 0, 24, 12]}],
}


def test_mcl_with_exact_odometry_localises_and_without_it_does_worse():
    world = world_from_dict(TWO_ROOMS)
    db = generate(world, 600, seed=0)
    run = {
        odometry: ceilings.mcl(
            world,
            db.layout,
            db.sensors,
            db.motors,
            db.poses,
            0.3,
            odometry=odometry,
            n_particles=300,
            window=600,
            windows=1,
        )
        for odometry in (True, False)
    }
    late = [b for b in run[True]["by_steps"] if b["steps"][0] >= 100]
    assert late
    assert all(b["balanced_room_accuracy"] >= 0.9 for b in late)
    assert late[-1]["position_error"] < 1.0  # the pose itself, not only the room
    assert run[True]["balanced_room_accuracy"] >= 0.9
    assert run[False]["balanced_room_accuracy"] < run[True]["balanced_room_accuracy"] - 0.2
    assert run[False]["position_error"] > 3 * run[True]["position_error"]
    assert run[True]["steps"] == 600


def test_a_move_through_a_wall_is_found_by_the_ray_caster():
    world = world_from_dict(TWO_ROOMS)
    start = np.array([[6.0, 4.0], [6.0, 10.0], [6.0, 4.0]])
    end = np.array([[10.0, 4.0], [10.0, 10.0], [7.0, 4.0]])  # through, over the wall, short
    assert ceilings.crossed(world, start, end).tolist() == [True, False, False]


def test_mcl_windows_spread_over_the_split():
    assert ceilings.window_starts(100_000, 10_000, 3) == [0, 40_000, 90_000]
    assert ceilings.window_starts(15_000, 10_000, 3) == [0, 10_000]


def test_the_true_pose_planner_reaches_goals_on_the_map_planners_pairs():
    world = load_world("rooms1")
    plans = ceilings.true_pose_planning(world, DEFAULT_LAYOUT, seed=0, n_pairs=8)
    assert plans["success"] == 1.0
    assert plans["median_steps"] < 200
    # the pairs are the map planner's: a function of the seed alone
    a, b = start_goal_pairs(world, 0, 3), start_goal_pairs(world, 0, 3)
    assert all(np.array_equal(x[0], y[0]) and x[1] == y[1] for x, y in zip(a, b, strict=True))


def test_the_true_pose_traces_are_its_episodes_and_are_drawn_beside_the_maps():
    """``traces`` holds each episode from its start to the goal disc, as many steps as it
    reports; ``plot_plans`` draws them beneath the map's paths, one more line a panel."""
    from sensorimotor.analysis.map.plots import plot_plans

    world = load_world("rooms1")
    traces: list = []
    plans = ceilings.true_pose_planning(world, DEFAULT_LAYOUT, 0, 3, traces=traces)
    assert plans == ceilings.true_pose_planning(world, DEFAULT_LAYOUT, 0, 3)  # same episodes
    for (path, goal, steps), (goal_xy, start, _) in zip(
        traces, start_goal_pairs(world, 0, 3), strict=True
    ):
        assert np.array_equal(goal, goal_xy)
        assert np.allclose(path[0], start[:2])
        assert steps is not None
        assert len(path) == steps + 1
        assert math.hypot(*(path[-1] - goal)) <= planning.GOAL_RADIUS
        assert math.hypot(*(path[-2] - goal)) > planning.GOAL_RADIUS
    mine = [(p + 1.0, g, None) for p, g, _ in traces]
    lines = [len(ax.lines) for ax in plot_plans(world, mine, 4.0, "t", traces).axes]
    alone = [len(ax.lines) for ax in plot_plans(world, mine, 4.0, "t").axes]
    assert [a - b for a, b in zip(lines, alone, strict=True)] == [1, 1, 1]


def _spy(module, monkeypatch) -> list:
    """Record every (heading, d, r) that ``module`` executes through ``apply_motor``."""
    seen, real = [], module.apply_motor

    def spy(x, y, heading, d, r):
        seen.append((heading, d, r))
        return real(x, y, heading, d, r)

    monkeypatch.setattr(module, "apply_motor", spy)
    return seen


def _on_the_lattice(seen) -> None:
    turn = math.pi / 6
    allowed = [(0.9, 0.0), (0.0, turn), (0.0, -turn)] + [
        (0.0, math.pi + k * turn) for k in (-1, 0, 1)
    ]
    for heading, d, r in seen:
        assert min(math.hypot(d - a, r - b) for a, b in allowed) < 1e-12, (d, r)
        assert abs(heading / turn - round(heading / turn)) < 1e-9, heading


def test_on_a_lattice_database_the_planners_move_as_the_lattice_behaviour(monkeypatch):
    """The true-pose planner, the map's planner and its random baseline execute the lattice's
    own commands from headings on its lattice (``planning.Moves``), and the true pose still
    reaches its goals; the paper's moves are not lattice commands."""
    world = load_world("rooms1")
    seen = _spy(ceilings, monkeypatch)
    plans = ceilings.true_pose_planning(world, DEFAULT_LAYOUT, 0, 6, moves=Moves("lattice"))
    assert (plans["success"], plans["moves"]) == (1.0, "lattice")
    assert len(seen) > 50
    _on_the_lattice(seen)
    walked = _spy(planning, monkeypatch)
    goal, start, _ = start_goal_pairs(world, 0, 1)[0]
    for use_map in (False, True):  # the random baseline, then the map's planner (a 1-cell map)
        model = _one_cell_map()
        kmeans = type("K", (), {"cluster_centers_": np.zeros((1, 5))})()
        planning.run_episode(world, DEFAULT_LAYOUT, lambda: lambda z, m: np.zeros(5), kmeans, model,
                             np.zeros(model.n_states), goal, start, np.random.default_rng(0),
                             budget=60, use_map=use_map, moves=Moves("lattice"))  # fmt: skip
    assert len(walked) > 60
    _on_the_lattice(walked)
    paper = [Moves().command(a, np.random.default_rng(a)) for a in planning.MOVING]
    assert all(0 <= d < 1 and abs(r) <= math.pi / 6 for d, r in paper)
    assert paper != [Moves("lattice").lattice_command(a) for a in planning.MOVING]
    assert Moves("grid").lattice_command(3) == (0.0, math.pi / 2)


def test_explore_hands_that_share_of_the_map_planners_steps_to_the_behaviour(monkeypatch):
    """``run_episode(explore=p)``: with p = 0 the behaviour's step comes only at the reflex and
    the episode is the one it always was; with p = 1 every step is the behaviour's."""
    world = load_world("rooms1")
    goal, start, _ = start_goal_pairs(world, 0, 1)[0]
    kmeans = type("K", (), {"cluster_centers_": np.zeros((1, 5))})()
    walks = {}
    for explore in (0.0, 1.0):
        calls = []
        walk = Moves.walk

        def counted(self, reading, rng, calls=calls, walk=walk):
            calls.append(reading)
            return walk(self, reading, rng)

        monkeypatch.setattr(Moves, "walk", counted)
        trace: list = []
        model = _one_cell_map()
        planning.run_episode(world, DEFAULT_LAYOUT, lambda: lambda z, m: np.zeros(5), kmeans, model,
                             np.zeros(model.n_states), goal, start, np.random.default_rng(0),
                             budget=80, trace=trace, explore=explore)  # fmt: skip
        monkeypatch.setattr(Moves, "walk", walk)
        walks[explore] = (calls, trace)
    reflex = walks[0.0][0]
    assert all(r < planning.TURN_THRESHOLD for r in reflex)
    assert len(walks[1.0][0]) == len(walks[1.0][1]) - 1 > len(reflex)  # every step but the last


def test_on_the_grid_the_true_pose_planner_turns_once_and_goes():
    """The grid's turns move nothing: judged as the paper's moves are (the heading LOOK units
    ahead), its planner turned left and right in place and missed 2 of these 12 goals."""
    world = load_world("rooms1")
    plans = ceilings.true_pose_planning(world, DEFAULT_LAYOUT, 0, 12, moves=Moves("grid"))
    assert plans["success"] == 1.0
    assert plans["median_steps"] < 80


def test_the_reflex_reads_the_paper_rays_whatever_rays_the_database_records():
    """The behaviour that recorded a database turned on the paper's five forward rays; with 16
    rays over a full turn, a wall 0.5 behind the robot is seen but does not turn it."""
    from sensorimotor.sim.core import read_sensors, spread_layout

    world = load_world("square")
    full = spread_layout(16, 2 * math.pi - 1e-3, 50.0)
    pose = np.array([0.5, 25.0, 0.0])  # facing east, the west wall behind
    assert read_sensors(world, pose, full)[0].min() < 1.0
    assert planning.reflex_reading(world, pose, full) > 1.0
    paper = read_sensors(world, pose, DEFAULT_LAYOUT)[0]
    assert planning.reflex_reading(world, pose, DEFAULT_LAYOUT, paper) == paper.min()


def _one_cell_map():
    """A cloned HMM of one cell, two clones, uniform transitions under every action."""
    from sensorimotor.analysis.map.chmm import CloneHMM, Transitions

    T = Transitions.from_dense(np.full((4, 2, 2), 0.5), 2)
    return CloneHMM(T, np.ones(2, dtype=bool), T.blocks, {}, T)


def _second_order(n, k, rng):
    """Cells whose next one is the sum of the last two (mod k), 5 % noise; random actions."""
    c, a = np.zeros(n, dtype=np.int64), rng.integers(0, 4, n)
    c[1] = 1
    for t in range(2, n):
        c[t] = (c[t - 1] + c[t - 2]) % k if rng.random() < 0.95 else rng.integers(k)
    return c, a


def test_markov2_learns_a_second_order_process_and_markov3_backs_off_where_unseen():
    rng = np.random.default_rng(0)
    k = 6
    train, test = _second_order(3_000, k, rng), _second_order(1_000, k, rng)
    base = baseline_bits(*train, *test, k)
    assert ngram_bits(*train, *test, k, 2) < base["markov"] - 0.5
    p2, p3 = ngram_probs(*train, *test, k, 2), ngram_probs(*train, *test, k, 3)
    seen = set(_histories(*train, k, 4, 3).tolist()) - {-1}
    test_h = _histories(*test, k, 4, 3)
    unseen = np.array([h < 0 or h not in seen for h in test_h])
    assert 0 < unseen.sum() < len(unseen)  # 3 000 steps leave some of (6 x 4)^3 histories out
    np.testing.assert_array_equal(p3[unseen], p2[unseen])  # unseen: the order below, as is
    assert not np.allclose(p3[~unseen], p2[~unseen])


def test_the_recurrent_net_learns_the_second_order_process():
    rng = np.random.default_rng(1)
    k = 6
    steps = []
    for n in (4_000, 1_000, 1_000):
        c, a = _second_order(n, k, rng)
        steps.append(Steps(c, a, np.zeros((n, 2)), np.zeros((n, 3))))
    markov = baseline_bits(steps[0].cells, steps[0].actions, steps[2].cells, steps[2].actions, k)
    got = rnn_bits(*steps, k, seed=0, updates=150)
    assert got < markov["markov"] - 0.3
    assert got == rnn_bits(*steps, k, seed=0, updates=150)  # seeded: the same bits


@pytest.mark.parametrize(("noise", "want"), [(0.0, ceilings.SIGMA_FLOOR), (0.5, 0.5)])
def test_the_reading_model_takes_the_databases_noise_with_a_floor(noise, want):
    assert ceilings.reading_sigma({"noise_std": noise}) == want


@pytest.mark.parametrize("kind", ["rec-sm", "rec-sma"])
def test_the_planners_online_encoder_is_the_models_encode_of_the_recording(kind):
    """Fed one reading and the command before it at a time, the planner's encoder gives the
    representation ``models.encode`` gives the whole recording (Rec-SMA's memory reads the
    commands, so a planner that dropped them would differ)."""
    import torch

    from sensorimotor.learn.evaluate import Run
    from sensorimotor.learn.models import build_model
    from sensorimotor.sim.database import generate, scale_motors, scale_sensors

    db = generate(load_world("rooms1"), 40, seed=3)
    model = build_model(kind, seed=0).eval()
    with torch.no_grad():
        s = torch.from_numpy(scale_sensors(db.sensors, db.max_range))[None]
        m = torch.from_numpy(scale_motors(db.motors))[None]
        offline = model.encode(s, None, m)[0][0].numpy()  # (T, 10)
    encode = planning.encoder_of(Run(Path("run"), model, {}), db.max_range)()
    online = [encode(db.sensors[t], None if t == 0 else tuple(db.motors[t - 1])) for t in range(40)]
    np.testing.assert_allclose(np.array(online), offline, atol=1e-6)
    if kind == "rec-sma":  # the commands matter: without them the memory drifts elsewhere
        blind = planning.encoder_of(Run(Path("run"), model, {}), db.max_range)()
        dropped = np.array([blind(db.sensors[t], None) for t in range(40)])
        assert np.abs(dropped - offline).max() > 1e-3
