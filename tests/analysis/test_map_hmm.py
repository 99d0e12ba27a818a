"""The plain HMM baseline of the map (``analysis.map.hmm``): its EM, its scoring, what it learns."""

from __future__ import annotations

import math

import numpy as np
import pytest

from sensorimotor.analysis.map import hmm
from sensorimotor.analysis.map.cells import Steps, baseline_bits


def _sample(m: hmm.PlainHMM, n: int, rng) -> tuple[np.ndarray, np.ndarray]:
    """(n,) cells and (n,) actions drawn from ``m`` under uniform random actions."""
    A, S, _ = m.T.shape
    actions = rng.integers(0, A, n)
    cells = np.empty(n, dtype=np.int64)
    s = rng.choice(S, p=m.pi / m.pi.sum())
    for t in range(n):
        cells[t] = rng.choice(m.E.shape[1], p=m.E[s] / m.E[s].sum())
        s = rng.choice(S, p=m.T[actions[t], s] / m.T[actions[t], s].sum())
    return cells, actions


def _full_forward(m: hmm.PlainHMM, cells, actions) -> np.ndarray:
    """``log p(c_t | everything before)`` over the whole sequence, one step at a time."""
    out = np.zeros(len(cells))
    a = m.pi * m.E[:, cells[0]]
    a = a / a.sum()
    for t in range(1, len(cells)):
        a = (a @ m.T[actions[t - 1]]) * m.E[:, cells[t]]
        out[t] = math.log(a.sum())
        a = a / a.sum()
    return out


@pytest.fixture
def short_chunks(monkeypatch):
    monkeypatch.setattr(hmm, "HMM_CHUNK", 20)
    monkeypatch.setattr(hmm, "HMM_GROUP", 3)


def test_em_scores_its_chunks_as_the_forward_pass_does_and_never_lowers_the_likelihood(short_chunks):
    rng = np.random.default_rng(0)
    m = hmm.random_hmm(5, 4, 2, seed=1)
    cells, actions = _sample(m, 200, rng)
    c, a = cells.reshape(-1, 20), actions.reshape(-1, 20)
    want = sum(
        math.log(float((m.pi * m.E[:, ci[0]]).sum())) + _full_forward(m, ci, ai).sum()
        for ci, ai in zip(c, a, strict=True)
    )
    model, nats = hmm.em_step(m, c, a)
    assert nats * c.size == pytest.approx(want, rel=1e-5)
    lls = [nats]
    for _ in range(5):
        model, nats = hmm.em_step(model, c, a)
        lls.append(nats)
    assert np.all(np.diff(lls) > -1e-5)  # EM: each iteration at least as likely (float32 steps)
    assert lls[-1] > lls[0] + 0.02


def test_the_windowed_score_covers_every_step_once_and_matches_the_full_forward(short_chunks):
    rng = np.random.default_rng(2)
    m = hmm.random_hmm(4, 5, 3, seed=3)
    cells, actions = _sample(m, 257, rng)  # not a multiple of the chunk: a last, shorter block
    got, full = hmm.log_likelihood(m, cells, actions), _full_forward(m, cells, actions)
    assert got[0] == 0
    assert np.all(got[1:] < 0)
    assert np.allclose(got[1:41], full[1:41], atol=1e-5)  # the first window: its own start
    assert abs(got.mean() - full.mean()) < 1e-3  # later: 20 steps of context, a mixing chain


def test_a_plain_hmm_learns_a_persistent_hidden_state_a_markov_chain_cannot():
    rng = np.random.default_rng(4)
    S, K = 3, 6
    stay = np.full((1, S, S), 0.02 / (S - 1)) + np.eye(S) * (0.98 - 0.02 / (S - 1))
    E = np.full((S, K), 0.02)
    E[np.arange(S), np.arange(S)] = E[np.arange(S), np.arange(S) + S] = 0.45  # two cells a state
    truth = hmm.PlainHMM(stay, E / E.sum(1, keepdims=True), np.full(S, 1 / S))
    splits = [Steps(*_sample(truth, n, rng), np.zeros((n, 2)), np.zeros((n, 3)))
              for n in (6_000, 1_000, 2_000)]  # fmt: skip
    splits = [Steps(s.cells, np.zeros_like(s.actions), s.motors, s.poses) for s in splits]
    markov = baseline_bits(splits[0].cells, splits[0].actions, splits[2].cells,
                           splits[2].actions, K)["markov"]  # fmt: skip
    got = hmm.plain_hmm_bits(*splits, K, states=S, seed=0, n_actions=1)
    best = -_full_forward(truth, splits[2].cells, np.zeros(2_000, dtype=int))[1:].mean()
    assert got["bits"] < markov - 0.1  # measured: 1.63 against 1.81
    assert got["bits"] < best / math.log(2) + 0.02  # the process's own rate: 1.63
    assert got == hmm.plain_hmm_bits(*splits, K, states=S, seed=0, n_actions=1)  # seeded


def test_a_map_with_more_states_than_the_cap_gets_a_plain_hmm_of_the_cap(monkeypatch):
    """The plain HMM is dense (S^2 a step): a blocked map of many states is compared with one
    of ``HMM_MAX_STATES``, and map.json says both."""
    monkeypatch.setattr(hmm, "HMM_MAX_STATES", 4)
    rng = np.random.default_rng(0)
    splits = [Steps(rng.integers(0, 3, n), np.zeros(n, dtype=np.int64), np.zeros((n, 2)),
                    np.zeros((n, 3))) for n in (800, 200, 200)]  # fmt: skip
    got = hmm.plain_hmm_bits(*splits, 3, states=50, seed=0, n_actions=1)
    assert (got["states"], got["map_states"]) == (4, 50)
    assert got == hmm.plain_hmm_bits(*splits, 3, states=4, seed=0, n_actions=1) | {"map_states": 50}
