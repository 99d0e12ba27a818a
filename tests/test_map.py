"""The map (``analysis.cells``, ``analysis.chmm``, ``analysis.mapping``): cells, the cell graph,
the cloned HMM, what it predicts and where it thinks the agent is."""

from __future__ import annotations

import numpy as np
import pytest

from sensorimotor.analysis.cells import (
    ACTION_NAMES,
    action_bins,
    baseline_bits,
    bits,
    cell_graph,
    unigram,
)
from sensorimotor.analysis.chmm import fit_chmm, log_likelihood

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
    nats = -log_likelihood(model.T, obs[test], actions[test], 6)[1:].mean()
    truth = 2 / 3 * -(SLIP * np.log2(SLIP) + (1 - SLIP) * np.log2(1 - SLIP))
    assert base["markov"] > truth + 0.4  # the observations alone do not say where one is
    assert nats / np.log(2) < truth + 0.1
    assert 12 <= model.active.sum() <= 18  # about one active state per place


def test_the_map_is_deterministic_given_its_seed():
    obs, actions, _ = ring_walk(2_000)
    a, b = (fit_chmm(obs, actions, 3, 4, 3, seed=5) for _ in range(2))
    assert np.array_equal(a.T, b.T)
    c = fit_chmm(obs, actions, 3, 4, 3, seed=6)
    assert not np.array_equal(a.T, c.T)
