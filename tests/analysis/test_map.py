"""The map (``analysis.cells``, ``analysis.chmm``, ``analysis.mapping``): cells, the cell graph,
the cloned HMM, what it predicts and where it thinks the agent is."""

from __future__ import annotations

import inspect
import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from sklearn.metrics import adjusted_rand_score

import reference_chmm as reference
from conftest import assert_one_line_error
from sensorimotor.analysis.analyze import representation_of
from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans
from sensorimotor.analysis.map import graphs, mapping, planning
from sensorimotor.analysis.map.cells import (
    ACTION_NAMES,
    Steps,
    action_bins,
    baseline_bits,
    bits,
    cell_graph,
    unigram,
)
from sensorimotor.analysis.map.chmm import (
    CloneHMM,
    Transitions,
    _backward_counts,
    _forward,
    check_size,
    fit_chmm,
    log_likelihood,
)
from sensorimotor.analysis.map.context import (
    N_CONTEXTS,
    decayed_history,
    fine_clones,
    slow_context,
)
from sensorimotor.analysis.map.graphs import communities
from sensorimotor.analysis.map.localisation import localisation
from sensorimotor.analysis.map.mapping import cell_steps, map_files
from sensorimotor.analysis.map.planning import goal_distances
from sensorimotor.errors import InputError
from sensorimotor.sim.core import SensorLayout
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.sim.world import load_world, world_from_dict

RING = np.array([0, 1, 2, 0, 2, 1, 0, 1, 0, 2, 1, 2])  # 12 places, 3 aliased observations
SLIP = 0.2  # a move fails (the agent stays) with this probability


def ring_walk(n: int, seed: int = 1) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A walk on RING: actions 0 (forward), 1 (back), 2 (stay); (observations, actions, places)."""
    rng = np.random.default_rng(seed)
    actions = rng.integers(0, 3, n)
    slips = rng.random(n) < SLIP
    places = np.zeros(n, dtype=np.int64)
    for t in range(1, n):
        step = 0 if slips[t - 1] else (1, -1, 0)[actions[t - 1]]
        places[t] = (places[t - 1] + step) % len(RING)
    return RING[places], actions, places


def test_actions_bin_the_behaviour_and_the_turn_around_is_its_own():
    r = np.array([np.pi, -np.pi + 0.1, -0.5, -0.1, 0.0, 0.1, 0.5])
    motors = np.stack([np.zeros_like(r), r], axis=1)
    names = [ACTION_NAMES[a] for a in action_bins(motors)]
    assert names == ["turn", "turn", "right", "straight", "straight", "straight", "left"]
    # The lattice's and the grid's commands as recorded (float32): a quarter turn is a turn to
    # one side, the grid reflex's 3 pi/2 a right turn, every turn-around near pi a turn.
    turns = np.float32([np.pi / 6, -np.pi / 6, 5 * np.pi / 6, 7 * np.pi / 6, np.pi / 2, -np.pi / 2,
                        np.pi, 3 * np.pi / 2])  # fmt: skip
    names = [ACTION_NAMES[a] for a in action_bins(np.stack([np.zeros_like(turns), turns], axis=1))]
    assert names == ["left", "right", "turn", "turn", "left", "right", "turn", "right"]


def test_unigram_bits_are_the_entropy_by_hand():
    cells = np.array([0, 0, 0, 1, 1, 2, 0, 1])
    p = unigram(cells, 3, alpha=0.0)
    freq = np.bincount(cells[1:], minlength=3) / 7  # the predicted steps
    by_hand = -(freq * np.log2(p)).sum()
    assert bits(p[cells[1:]]) == pytest.approx(by_hand)
    assert p.tolist() == pytest.approx([4 / 8, 3 / 8, 1 / 8])


def test_cell_graph_counts_edges_and_their_motor_statistics():
    cells = np.array([0, 1, 0, 1, 2])
    actions = np.array([2, 2, 2, 0, 0])
    motors = np.array([[0.2, 0.0], [0.4, 0.0], [0.6, 0.0], [0.0, 3.1], [0.0, 3.0]])
    g = cell_graph(cells, actions, motors, 3)
    assert g.counts.sum() == 4
    assert g.counts[2, 0, 1] == 2  # 0 -straight-> 1 twice, with d = 0.2 and 0.6
    assert g.motor_mean[2, 0, 1, 0] == pytest.approx(0.4)
    assert g.motor_sd[2, 0, 1, 0] == pytest.approx(np.std([0.2, 0.6], ddof=1))
    assert {(e["source"], e["action"], e["target"]) for e in g.edges()} == {
        (0, "straight", 1),
        (1, "straight", 0),
        (1, "turn", 2),
    }


def test_the_map_recovers_an_aliased_ring():
    """Three observations on twelve places: the first-order Markov model cannot tell the places
    apart; the cloned HMM finds them and predicts near the true entropy rate (a move slips with
    probability 0.2, staying is certain)."""
    obs, actions, _ = ring_walk(12_000)
    train, test = slice(0, 10_000), slice(10_000, None)
    base = baseline_bits(obs[train], actions[train], obs[test], actions[test], 3, 3)
    model = fit_chmm(obs[train], actions[train], 3, 6, 3, seed=0)
    nats = -log_likelihood(model.T, obs[test], actions[test])[1:].mean()
    truth = 2 / 3 * -(SLIP * np.log2(SLIP) + (1 - SLIP) * np.log2(1 - SLIP))
    assert base["markov"] > truth + 0.4  # the observations alone do not say where one is
    assert nats / np.log(2) < truth + 0.1
    assert 12 <= model.active.sum() <= 18  # about one active state per place


def test_the_fine_start_splits_a_cell_by_its_representations():
    """``context.fine_clones``: within each cell, one clone per cluster of the representation,
    at most ``clones`` and at most the cell's distinct representations."""
    rng = np.random.default_rng(0)
    points = np.array([[0.0, 0.0], [5.0, 0.0], [0.0, 5.0]])
    which = rng.integers(0, 3, 300)
    z = np.concatenate([points[which], np.full((100, 2), 9.0)])  # cell 0: three places; 1: one
    cells = np.r_[np.zeros(300, dtype=np.int64), np.ones(100, dtype=np.int64)]
    fine = fine_clones(z, cells, 4)
    assert adjusted_rand_score(which, fine[:300]) == 1.0
    assert len(np.unique(fine[:300])) == 3
    assert (fine[300:] == 0).all()
    assert len(np.unique(fine_clones(z, cells, 2)[:300])) == 2  # at most ``clones``


def test_em_starts_from_a_given_path_of_clones():
    """``start``: EM's first model is the one counted along that path. From the ring's true
    places (clone = the place's rank among its cell's places) it already predicts near the
    true entropy rate at its first iteration, where the random start is far from it."""
    obs, actions, places = ring_walk(6_000)
    truth = 2 / 3 * -(SLIP * np.log(SLIP) + (1 - SLIP) * np.log(1 - SLIP))  # nats
    rank = np.array([(RING[:p] == RING[p]).sum() for p in range(len(RING))])  # 0..3
    given = fit_chmm(obs, actions, 3, 6, 3, seed=0, em_iters=1, start=rank[places])
    drawn = fit_chmm(obs, actions, 3, 6, 3, seed=0, em_iters=1)
    assert -given.history["em"][0] < truth + 0.01
    assert -drawn.history["em"][0] > truth + 0.3
    with pytest.raises(ValueError, match="start must be"):
        fit_chmm(obs, actions, 3, 6, 3, start=np.full(len(obs), 6))


def test_the_clone_kernels_match_a_plain_hmm_over_every_state():
    """The numba forward and expected counts, which only ever touch the clones of the observed
    cells, equal the textbook forward-backward over all states with a 0/1 emission matrix."""
    rng = np.random.default_rng(0)
    K, C, A, n = 3, 4, 2, 60
    T = rng.random((A, K * C, K * C))
    T /= T.sum(axis=2, keepdims=True)
    cells, actions = rng.integers(0, K, n), rng.integers(0, A, n)
    logp, counts = reference.forward_backward(T, cells, actions, C)
    blocked = Transitions.from_dense(T, C)
    assert log_likelihood(blocked, cells, actions)[1:] == pytest.approx(logp, rel=1e-10)
    alpha = np.empty((n, C))
    ids = blocked.ids(cells, actions)
    _forward(blocked.blocks, ids, blocked.rest, blocked.targets, cells, actions, C, alpha)
    mine = np.zeros_like(blocked.blocks)
    _backward_counts(blocked.blocks, ids, C, alpha, mine)
    mine = replace(blocked, blocks=mine).dense()
    assert mine == pytest.approx(counts, abs=1e-10)
    assert mine.sum() == pytest.approx(n - 1)


def test_the_map_is_deterministic_given_its_seed():
    obs, actions, _ = ring_walk(2_000)
    a, b = (fit_chmm(obs, actions, 3, 4, 3, seed=5) for _ in range(2))
    assert np.array_equal(a.T.blocks, b.T.blocks)
    c = fit_chmm(obs, actions, 3, 4, 3, seed=6)
    assert not np.array_equal(a.T.blocks, c.T.blocks)


# ---------------------------------------------------------------------------------------------
# Localisation on a world with known rooms


def ring_world(rooms: bool = True):
    """A 12 x 10 world, its west half and east half named rooms (or no rooms)."""
    data = {"name": "ring", "size": [12, 10], "walls": []}
    if rooms:
        data["rooms"] = [
            {"name": "west", "rect": [0, 0, 6, 10]},
            {"name": "east", "rect": [6, 0, 12, 10]},
        ]
    return world_from_dict(data)


def ring_steps(obs, actions, places) -> Steps:
    """The ring's places 0..11 laid out west to east along y = 5."""
    poses = np.stack([places + 0.5, np.full(len(places), 5.0), np.zeros(len(places))], axis=1)
    return Steps(obs, actions, np.zeros((len(obs), 2)), poses)


def test_the_map_localises_the_room_where_the_cell_alone_cannot():
    """Every observation occurs in both rooms: the cell alone is little better than chance;
    the filtered map state knows the room and the place."""
    obs, actions, places = ring_walk(12_000)
    train = ring_steps(obs[:10_000], actions[:10_000], places[:10_000])
    test = ring_steps(obs[10_000:], actions[10_000:], places[10_000:])
    model = fit_chmm(train.cells, train.actions, 3, 6, 3, seed=0)
    loc, state_mean, _ = localisation(model, train, test, ring_world())
    rooms, errors = loc["room_accuracy"], loc["position_error"]
    assert rooms["cells"] < 0.7
    assert rooms["chance"] < 0.6
    assert rooms["map"] > 0.9
    assert errors["map"] < 0.5 * errors["cells"]
    assert errors["cells"] < errors["chance"] * 1.01
    assert loc["grid_accuracy"]["map"] > loc["grid_accuracy"]["cells"] + 0.3
    x = state_mean[model.active, 0]  # the states' place fields spread over both rooms
    assert x.min() < 2
    assert x.max() > 10
    # a world without rooms: the room numbers are n/a, the rest is computed
    loc, _, _ = localisation(model, train, test, ring_world(rooms=False))
    assert loc["room_accuracy"] == {"map": None, "cells": None, "chance": None}
    assert loc["position_error"]["map"] == pytest.approx(errors["map"])


def two_rooms_walk(n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Cells 0, 1, 2 drawn independently at each step, more often 0 in the west room and 2
    in the east one; the robot changes room about every 300 steps. One action."""
    rng = np.random.default_rng(seed)
    room = np.cumsum(rng.random(n) < 1 / 300) % 2
    p = np.where(room[:, None] == 0, [0.45, 0.3, 0.25], [0.25, 0.3, 0.45])
    cells = (rng.random(n)[:, None] > np.cumsum(p, axis=1)).sum(axis=1)
    return cells.astype(np.int64), room


def test_the_slow_context_follows_where_the_robot_has_been():
    cells, room = two_rooms_walk(20_000)
    history = decayed_history(cells, 3, tau=50)
    assert history.sum(axis=1) == pytest.approx(1.0)
    context = slow_context(cells, 3, 2, tau=50, seed=0)
    agree = (context == room).mean()
    assert max(agree, 1 - agree) > 0.85  # the two contexts are the two rooms, in some order
    assert not slow_context(cells, 3, 1).any()


def test_the_context_split_gives_a_one_clone_map_the_room():
    """One clone per cell is the cells alone; split by two slow contexts, each cell gets a
    west and an east clone, and the filter knows the room where neither cell nor Markov can."""
    cells, room = two_rooms_walk(25_000)
    actions = np.zeros(len(cells), dtype=np.int64)
    poses = np.stack([3.0 + 6.0 * room, np.full(len(room), 5.0), np.zeros(len(room))], axis=1)
    train = Steps(cells[:20_000], actions[:20_000], np.zeros((20_000, 2)), poses[:20_000])
    test = Steps(cells[20_000:], actions[20_000:], np.zeros((5_000, 2)), poses[20_000:])
    context = slow_context(train.cells, 3, 2, tau=50, seed=0)
    plain = fit_chmm(train.cells, train.actions, 3, 1, 1, seed=0)
    split = fit_chmm(train.cells, train.actions, 3, 1, 1, seed=0, context=context, n_contexts=2)
    assert split.n_clones == 2
    assert split.T.dense().shape == (1, 6, 6)
    assert split.T.dense().sum(axis=2) == pytest.approx(1.0)
    assert plain.T_em.dense().shape == split.T_em.dense().shape == (1, 3, 3)  # before the split
    plain_rooms = localisation(plain, train, test, ring_world())[0]["room_accuracy"]
    rooms = localisation(split, train, test, ring_world())[0]["room_accuracy"]
    assert plain_rooms["map"] == pytest.approx(plain_rooms["cells"])
    assert rooms["cells"] < 0.65
    assert rooms["map"] > 0.85
    bits = [-log_likelihood(m.T, test.cells, test.actions)[1:].mean() for m in (plain, split)]
    assert bits[1] < bits[0] - 0.005  # nats: knowing the room predicts the next cell (at most 0.03)
    with pytest.raises(ValueError, match="context"):
        fit_chmm(train.cells, train.actions, 3, 1, 1, context=context[:-1], n_contexts=2)


def test_communities_of_the_map_find_the_two_rooms():
    """Two cliques joined by one weak edge: two communities."""
    w = np.zeros((6, 6))
    w[:3, :3] = w[3:, 3:] = 10.0
    w[2, 3] = 1.0
    label = communities(w, np.arange(6), seed=0)
    assert label.tolist() == [0, 0, 0, 1, 1, 1]
    assert communities(w, np.array([0, 1, 2]), seed=0)[3:].tolist() == [-1, -1, -1]


def test_a_smaller_resolution_joins_communities_along_their_strongest_edges():
    """Four cliques, joined in pairs by stronger edges than the pairs are to each other: four
    communities at networkx's default resolution (1), the two pairs at a small one."""
    w = np.zeros((12, 12))
    for c in range(4):
        w[3 * c : 3 * c + 3, 3 * c : 3 * c + 3] = 10.0
    w[2, 3] = w[8, 9] = 3.0
    w[5, 6] = 0.3
    four = communities(w, np.arange(12), seed=0, resolution=1.0)
    assert four.tolist() == np.repeat(range(4), 3).tolist()
    pairs = communities(w, np.arange(12), seed=0, resolution=0.03)
    assert pairs.tolist() == np.repeat(range(2), 6).tolist()


def test_communities_keep_the_louvain_run_of_highest_modularity():
    """Five noisy groups on which Louvain's runs disagree (the best is not the first seed's):
    ``communities`` keeps, of its ``runs`` seeds, the partition of highest modularity."""
    nx = pytest.importorskip("networkx")
    rng = np.random.default_rng(3)
    group = np.repeat(np.arange(5), 8)
    linked = rng.random((40, 40)) < np.where(group[:, None] == group[None, :], 0.5, 0.12)
    w = rng.random((40, 40)) * linked
    graph = graphs.undirected(w, np.arange(40))
    kw = {"weight": "weight", "resolution": 1.0}

    def modularity(label):
        parts = [set(np.flatnonzero(label == c).tolist()) for c in range(label.max() + 1)]
        return nx.community.modularity(graph, parts, **kw)

    singles = [modularity(communities(w, np.arange(40), s, 1.0, runs=1)) for s in range(30, 40)]
    assert max(singles) > singles[0] + 1e-3  # the first run is not the best: a choice is made
    kept = communities(w, np.arange(40), 3, 1.0, runs=10)  # seeds 30..39
    assert modularity(kept) == pytest.approx(max(singles), abs=1e-12)


def test_goal_distances_follow_the_map_to_the_goal():
    """A chain 0 -> 1 -> 2 -> 3 under action 1 (certain), state 4 pruned: distances 3, 2, 1, 0."""
    T = np.zeros((2, 5, 5))
    T[:, :, 0] = 1.0  # every other action and state: back to the start
    T[1, [0, 1, 2], [1, 2, 3]] = 1.0
    T[1, [0, 1, 2], 0] = 0.0
    active = np.array([True, True, True, True, False])
    blocked = Transitions.from_dense(T, 1)
    model = CloneHMM(blocked, active, blocked.blocks, {}, blocked)
    d = goal_distances(model, np.array([3]))
    assert d[:4].tolist() == pytest.approx([3, 2, 1, 0])
    assert np.isinf(d[4])


def test_on_a_lattice_map_the_plan_follows_the_paths_the_map_took():
    """``own_paths``: an entry the Viterbi path never took (here 0 -> 3, likely but uncounted)
    is no edge, and the pseudocount's jumps cost FALLBACK more, so the plan follows 0 -> 1 -> 2
    -> 3; the default graph takes the likely shortcut."""
    T = np.full((1, 4, 4), 1e-3)
    T[0, [0, 1, 2, 3], [1, 2, 3, 0]] = 0.6
    T[0, 0, 3] = 0.35
    T /= T.sum(axis=2, keepdims=True)
    blocked = Transitions.from_dense(T, 1)
    counts = np.zeros_like(blocked.blocks)  # (16, 1, 1): block b is (cell b // 4, cell b % 4)
    counts[[1, 6, 11, 12]] = 5.0
    model = CloneHMM(blocked, np.ones(4, dtype=bool), counts, {}, blocked)
    assert goal_distances(model, np.array([3]))[0] < 3  # the shortcut: one step of cost ~2
    own = planning.reverse_graph(model, own_paths=True)
    d = goal_distances(model, np.array([3]), own)
    assert d[0] == pytest.approx(sum(1 - np.log(T[0, i, i + 1]) for i in range(3)))
    assert own[:4, 4].toarray() == pytest.approx(1 + planning.FALLBACK)  # landing from the hub


def test_the_figure_keeps_the_first_reached_and_the_first_missed_episodes(monkeypatch):
    """``planning`` keeps N_TRACES reached and N_TRACES missed episodes of the map, the first
    of each in pair order, with their pair (so that the true pose is drawn on the same pair)."""
    outcome = iter([5, None, 7, 9, None, None, 3])  # the map's steps on pairs 0..6
    monkeypatch.setattr(planning, "reverse_graph", lambda *a, **k: None)
    monkeypatch.setattr(planning, "goal_states", lambda *a, **k: None)
    monkeypatch.setattr(planning, "goal_distances", lambda *a, **k: None)

    def episode(*args, use_map, trace=None, **kwargs):
        if trace is not None:
            trace.append(args[7][:2])  # the start
        return next(outcome) if use_map else None

    monkeypatch.setattr(planning, "run_episode", episode)
    out, traces = planning.planning(load_world("rooms1"), None, None, None, None, None, None,
                                    n_pairs=7)  # fmt: skip
    assert planning.N_TRACES == 2
    assert [(t[0], t[3]) for t in traces] == [(0, 5), (1, None), (2, 7), (4, None)]
    assert all(t[1].shape == (1, 2) for t in traces)
    assert out["success"]["map"] == 4 / 7


def test_a_map_whose_blocks_would_not_fit_is_refused_before_it_is_fitted():
    rng = np.random.default_rng(0)
    cells, actions = rng.integers(0, 200, 50_000), rng.integers(0, 4, 50_000)
    check_size(cells, actions, 200, 10, 4)  # about 45,000 blocks of 10 x 10: 36 MB
    with pytest.raises(InputError, match=r"GB .*blocks of 100 x 100.*fewer clones"):
        fit_chmm(cells, actions, 200, 50, 4, context=cells % 2, n_contexts=2)


def test_the_blocked_store_is_the_dense_matrix():
    """A fit keeps blocks for the training triples only; EM from the same random start equals
    the textbook EM over the dense matrix, and every use of T (a step's block, the expectation
    one step on, the planner's distances with their pseudocount jumps) equals the dense one."""
    obs, actions, _ = ring_walk(400)
    K, C, A = 3, 6, 3
    model = fit_chmm(obs, actions, K, C, A, seed=3, em_iters=8, tol=-1.0)
    seen = len(np.unique((obs[:-1] * A + actions[:-1]) * K + obs[1:]))
    assert model.T.blocks.shape == (seen, C, C)
    assert seen < K * A * K
    T = np.random.default_rng(3).random((A, K * C, K * C))
    for _ in range(8):
        T = T / T.sum(axis=2, keepdims=True)
        T = reference.forward_backward(T, obs, actions, C)[1] + 1e-3
    assert model.T_em.dense() == pytest.approx(T / T.sum(axis=2, keepdims=True), rel=1e-9)
    dense = model.T.dense()
    assert dense.sum(axis=2) == pytest.approx(1.0)
    assert (~model.active).any()
    assert dense[:, :, ~model.active].max() == 0.0  # the pruned states are never reached
    unseen = next(
        (a, c, d) for a in range(A) for c in range(K) for d in range(K)
        if not ((obs[:-1] == c) & (actions[:-1] == a) & (obs[1:] == d)).any()
    )  # fmt: skip
    for a, c, d in [unseen, (actions[0], obs[0], obs[1])]:
        block = dense[a, c * C : (c + 1) * C, d * C : (d + 1) * C]
        assert np.array_equal(model.T.block(a, c, d), block)
    values = np.random.default_rng(0).random(K * C)
    for a in range(A):
        assert model.T.after(a, values) == pytest.approx(dense[a] @ values, rel=1e-12)
    goals = np.flatnonzero(model.active)[:2]
    best = dense.max(axis=0) * np.outer(model.active, model.active)  # the dense planner's graph
    np.fill_diagonal(best, 0.0)
    best[best < 1e-6] = 0.0
    cost = np.where(best > 0, 1.0 - np.log(np.where(best > 0, best, 1.0)), 0.0)
    from scipy.sparse import csr_matrix
    from scipy.sparse.csgraph import dijkstra

    truth = dijkstra(csr_matrix(cost.T), directed=True, indices=goals, min_only=True)
    assert goal_distances(model, goals) == pytest.approx(truth, rel=1e-12)
    assert np.isfinite(truth[model.active]).all()
    assert np.isinf(truth[~model.active]).all()


# ---------------------------------------------------------------------------------------------
# The command


def strict_json(path: Path) -> dict:
    def refuse(name):
        raise ValueError(f"{name} in {path}")

    return json.loads(path.read_text(), parse_constant=refuse)


def test_cli_map_writes_strict_json_graphml_and_figures(cli, rooms1_db_path, tmp_path):
    out = tmp_path / "map"
    args = ("--data", rooms1_db_path, "--out", out, "--clusters", "6", "--clones", "3")
    proc = cli("map", "raw", *args, "--pairs", "2")
    assert proc.returncode == 0, proc.stderr
    m = strict_json(out / "map.json")
    b = m["bits_per_step"]
    assert set(b) >= {"unigram", "markov", "cell_graph", "map"}
    assert b["markov"] < b["unigram"]
    assert b["map"] < b["unigram"]
    higher = m["baselines"]["bits_per_step"]
    assert set(higher) == {"markov2", "markov3", "rnn", "hmm"}
    assert m["baselines"]["plain_hmm"]["states"] == m["states"]["active"]
    assert set(m["baselines"]["backoff_beta"]) == {"markov2", "markov3"}
    top = m["ceiling"]
    assert 0 <= top["localisation"]["balanced_room_accuracy"] <= 1  # its quality: test_map_ceilings
    assert top["localisation"]["no_odometry"]["balanced_room_accuracy"] is not None
    assert top["planning"]["success"] in (0.0, 0.5, 1.0)
    assert m["planning"]["explore"] == 0.0  # the paper's behaviour: the plan alone
    assert "ceilings: balanced room accuracy of MCL" in proc.stdout
    assert all(0 < v < b["unigram"] for v in higher.values())
    assert "baselines: bits/step markov2" in proc.stdout
    readout = m["baselines"]["localisation"]["history_readout"]
    assert 1 / 3 - 0.2 <= readout <= 1.0  # balanced accuracy over the three rooms of Rooms1
    for key in ("room_accuracy", "position_error"):
        assert set(m["localisation"][key]) == {"map", "cells", "chance"}
    assert m["rooms"]["names"] == ["southwest", "northwest", "east"]
    assert -1 <= m["rooms"]["adjusted_rand"] <= 1
    assert (m["planning"]["pairs"], m["planning"]["moves"]) == (2, "paper")
    assert top["planning"]["moves"] == "paper"
    for rate in m["planning"]["success"].values():
        assert rate in (0.0, 0.5, 1.0)
    assert m["settings"]["contexts"] == N_CONTEXTS == 2  # the default, chosen on validation
    from sensorimotor.analysis.map import chmm
    from sensorimotor.cli.analysis import map_cmd
    from sensorimotor.cli.app import MAX_CLONES, MAX_CLUSTERS, MAX_CONTEXTS
    from sensorimotor.cli.app import N_CONTEXTS as CLI_CONTEXTS

    assert CLI_CONTEXTS == N_CONTEXTS  # the CLI's copies, kept to refuse before imports
    from sensorimotor.analysis.map import graphs
    from sensorimotor.cli.app import MAX_RESOLUTION, RESOLUTION

    assert (RESOLUTION, MAX_RESOLUTION) == (graphs.RESOLUTION, graphs.MAX_RESOLUTION)
    assert m["settings"]["louvain_resolution"] == graphs.RESOLUTION
    assert (MAX_CLUSTERS, MAX_CLONES, MAX_CONTEXTS) == (
        mapping.MAX_CLUSTERS,
        mapping.MAX_CLONES,
        mapping.MAX_CONTEXTS,
    )
    defaults = inspect.signature(map_cmd).parameters
    assert (defaults["em_iters"].default, defaults["tol"].default) == (chmm.EM_ITERS, chmm.TOL)
    assert (m["settings"]["em_iters"], m["settings"]["em_tol"]) == (chmm.EM_ITERS, chmm.TOL)
    assert (defaults["pseudocount"].default, defaults["start"].default) == (
        chmm.PSEUDOCOUNT,
        mapping.STARTS[0],
    )
    assert (m["settings"]["pseudocount"], m["settings"]["start"]) == (chmm.PSEUDOCOUNT, "random")
    assert 1 <= m["states"]["active"] <= 6 * 3 * N_CONTEXTS
    import networkx as nx

    graph = nx.read_graphml(out / "map.graphml")
    assert graph.number_of_nodes() == m["states"]["active"]
    assert nx.read_graphml(out / "cell_graph.graphml").number_of_nodes() == 6
    for png in ("place_fields.png", "map_graph.png", "plans.png"):
        assert (out / png).read_bytes()[:4] == b"\x89PNG"
    assert "bits/step" in proc.stdout


def test_cli_map_bad_input_is_one_line_and_writes_nothing(cli, rooms1_db_path, tmp_path):
    out = tmp_path / "o"
    proc = cli("map", "raw", "--data", rooms1_db_path, "--out", out, "--clusters", "1")
    assert_one_line_error(proc, "--clusters")
    proc = cli("map", "raw", "--data", rooms1_db_path, "--out", out, "--start", "best")
    assert_one_line_error(proc, "--start", "random, fine")
    proc = cli("map", "raw", "--data", rooms1_db_path, "--out", out, "--pseudocount", "0")
    assert_one_line_error(proc, "--pseudocount")
    short = tmp_path / "short.npz"
    save_database(generate(load_world("rooms1"), 150, seed=0), short)
    proc = cli("map", "raw", "--data", short, "--out", out)
    assert_one_line_error(proc, str(short), "split")
    assert not out.exists()


def test_a_map_is_scored_on_a_fresh_database_of_its_world_only(
    rooms1_db_path, square_db_path, tmp_path
):
    """--test-data: the map learned on the training split of --data, scored on the test split
    of the fresh database (its steps, its ceilings); a database of another world is refused
    before anything is written."""
    fresh = tmp_path / "fresh.npz"
    save_database(generate(load_world("rooms1"), 6_000, seed=7), fresh)
    with pytest.raises(InputError, match="world differs"):
        map_files("raw", rooms1_db_path, tmp_path / "no", clusters=5, clones=2, pairs=0,
                  test_data=square_db_path)  # fmt: skip
    assert not (tmp_path / "no").exists()
    with pytest.raises(InputError, match="--resolution"):
        map_files("raw", rooms1_db_path, tmp_path / "no", resolution=0.0)
    kw = dict(clusters=5, clones=2, contexts=1, pairs=0, em_iters=3)
    own = map_files("raw", rooms1_db_path, tmp_path / "own", **kw).metrics
    m = map_files("raw", rooms1_db_path, tmp_path / "f", test_data=fresh, resolution=0.5, **kw)
    m = m.metrics
    assert m["test_data"] == str(fresh)
    assert own["test_data"] is None
    assert m["steps"]["test"] == len(load_database(fresh).take("test"))
    assert m["steps"]["train"] == own["steps"]["train"]
    assert m["states"] == own["states"]  # the same map
    assert m["bits_per_step"]["map"] != own["bits_per_step"]["map"]  # other steps scored
    mcl = m["ceiling"]["localisation"]["odometry"]["steps"]
    n_own = len(load_database(rooms1_db_path).take("test"))
    assert mcl == len(load_database(fresh).take("test")) != n_own
    assert m["settings"]["louvain_resolution"] == 0.5


def test_transfer_takes_the_cells_of_another_world(rooms1_db_path, square_db_path):
    """--fit-data: the k-means is fitted on the other database's training split and assigns
    this database's steps; the map itself is learned on this database."""
    rooms1, square = load_database(rooms1_db_path), load_database(square_db_path)
    train, test, kmeans = cell_steps("raw", rooms1, 5, 0, fit_db=square)
    own = fit_kmeans(representation_of("raw", square, "train"), 5, 0)
    assert np.array_equal(kmeans.cluster_centers_, own.cluster_centers_)
    z = representation_of("raw", rooms1, "test")
    assert np.array_equal(test.cells, assign_clusters(own, z))
    assert len(train.cells) == len(rooms1.take("train"))


def test_map_start_fine_hands_em_the_clones_of_the_cells_clusters(
    rooms1_db_path, tmp_path, monkeypatch
):
    """``map_files(start="fine")`` starts EM from ``fine_clones`` of the training split's
    representation and cells, with the pseudocount asked for."""
    seen = {}

    class Stop(Exception):
        pass

    def spy(cells, *args, **kwargs):
        seen.update(kwargs, cells=cells)
        raise Stop

    monkeypatch.setattr(mapping, "fit_chmm", spy)
    with pytest.raises(Stop):
        map_files("raw", rooms1_db_path, tmp_path / "o", clusters=5, clones=3, start="fine",
                  pseudocount=1e-4, pairs=0)  # fmt: skip
    db = load_database(rooms1_db_path)
    z = representation_of("raw", db, "train")
    assert np.array_equal(seen["start"], fine_clones(z, seen["cells"], 3))
    assert len(np.unique(seen["start"])) == 3
    assert seen["pseudocount"] == 1e-4


def test_map_refuses_bad_settings_and_other_layouts(rooms1_db_path, tmp_path):
    with pytest.raises(InputError, match="--clones"):
        map_files("raw", rooms1_db_path, tmp_path / "o", clones=0)
    with pytest.raises(InputError, match="states"):
        map_files("raw", rooms1_db_path, tmp_path / "o", clusters=200, clones=101, contexts=2)
    with pytest.raises(InputError, match="--contexts"):
        map_files("raw", rooms1_db_path, tmp_path / "o", contexts=0)
    other = tmp_path / "other.npz"
    layout = SensorLayout(angles=(-0.5, -0.25, 0.0, 0.25, 0.5))
    save_database(generate(load_world("rooms1"), 2_000, seed=0, layout=layout), other)
    with pytest.raises(InputError, match="layout"):
        map_files("raw", rooms1_db_path, tmp_path / "o", fit_data=other)
    assert not (tmp_path / "o").exists()


def test_a_map_of_a_recording_whose_walls_are_unknown_says_n_a_where_walls_are_needed(
    rooms1_db_path, tmp_path
):
    """An imported robot recording (meta.world names it alone): the map, its bits and positions
    within the region the path covers; rooms and planning n/a (null), not a failure."""
    from sensorimotor.sim.database import Database, load_database, save_database

    db = load_database(rooms1_db_path)
    shift = np.array([-120.0, 35.0, 0.0], dtype=np.float32)  # an odometry frame of its own
    meta = {"world": {"name": "robot"}, "source": {"kind": "test"}}
    save_database(Database(db.sensors, db.motors, db.poses + shift, meta), tmp_path / "rec.npz")
    result = map_files("raw", tmp_path / "rec.npz", tmp_path / "map", clusters=6, clones=3, pairs=5)
    m = result.metrics
    assert m["world"] == "robot"
    assert m["bits_per_step"]["map"] < m["bits_per_step"]["unigram"]
    assert m["localisation"]["room_accuracy"]["map"] is None
    assert m["planning"]["success"] == {"map": None, "random": None}
    errors = m["localisation"]["position_error"]
    assert 0 < errors["map"] < 60  # within the 50 x 50 region the path covers, shift or not


def test_a_world_of_unknown_walls_is_drawn_and_labelled_as_a_bounding_box():
    """A recording's frame is the box of its path, dashed and said so; a world's is its walls."""
    from sensorimotor.analysis.map.plots import plot_map_graph, plot_place_fields
    from sensorimotor.sim.world import World

    box = World("robot", 10.0, 8.0, np.zeros((0, 4)))
    poses = np.array([[1.0, 1.0, 0.0], [9.0, 7.0, 0.0], [5.0, 4.0, 0.0]])
    states, occupancy = np.array([0, 0, 1]), np.array([2.0, 1.0])
    for bounding_box in (True, False):
        fig = plot_place_fields(box, poses, states, occupancy, "t", bounding_box=bounding_box)
        dashed = [
            patch
            for ax in fig.axes
            for patch in ax.patches
            if patch.get_linestyle() == "--" and (patch.get_width(), patch.get_height()) == (10, 8)
        ]
        assert len(dashed) == (2 if bounding_box else 0)  # one per drawn field
        walls = [line for ax in fig.axes for line in ax.lines if line.get_gid() == "wall"]
        assert (len(walls) == 0) == bounding_box  # the box is not drawn as walls
        assert ("bounding box" in fig._suptitle.get_text()) == bounding_box
        ax = plot_map_graph(
            box,
            poses[:2, :2],
            np.ones((2, 2)),
            np.ones(2, dtype=bool),
            np.zeros(2, dtype=np.int64),
            occupancy,
            "t",
            bounding_box=bounding_box,
        )
        assert ("bounding box" in ax.get_title()) == bounding_box


def test_the_summary_warns_when_the_planner_does_not_beat_the_random_behaviour():
    from sensorimotor.analysis.map.mapping import _planning_warning

    assert _planning_warning({"success": {"map": 0.41, "random": 0.34}}) == []
    (line,) = _planning_warning({"success": {"map": 0.34, "random": 0.34}})
    assert "no more goals than the random behaviour (0.34 vs 0.34)" in line
    assert _planning_warning({"success": {"map": None, "random": 0.34}}) == []


def test_the_higher_order_baselines_back_off_to_markov_and_learn_a_second_order_process():
    from sensorimotor.analysis.map.cells import baseline_bits, ngram_bits

    rng = np.random.default_rng(0)
    k = 6

    def second_order(n):  # the next cell depends on the last two cells: order 2 knows it
        c, a = np.zeros(n, dtype=np.int64), rng.integers(0, 4, n)
        c[1] = 1
        for t in range(2, n):
            c[t] = (c[t - 1] + c[t - 2]) % k if rng.random() < 0.95 else rng.integers(k)
        return c, a

    train, test = second_order(20_000), second_order(5_000)
    base = baseline_bits(*train, *test, k)
    assert ngram_bits(*train, *test, k, 0) == pytest.approx(base["unigram"])
    assert ngram_bits(*train, *test, k, 1) == pytest.approx(base["markov"])
    assert ngram_bits(*train, *test, k, 2) < base["markov"] - 0.5
