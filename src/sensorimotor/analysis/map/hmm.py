"""The plain HMM: the map's baseline with as many hidden states and nothing cloned.

The map's states each emit one cell (``chmm``); a plain action-conditioned HMM lets every state
emit every cell, ``E`` (S, K), and learns it with the transitions ``T[a]`` (A, S, S) and the
start ``pi`` (S,) by Baum-Welch. A step then costs S^2, not C^2, so EM runs on the first
``HMM_STEPS`` steps of the training split, cut into chunks of ``HMM_CHUNK`` steps (each starts
from ``pi``); the chunks of a group are filtered together, one matrix product per action and
step. The iteration whose model predicts the validation split best is scored on the test split,
in bits per step as the map is (``chmm.log_likelihood``: the first cell given).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

HMM_STEPS = 100_000  # training steps EM sees (S^2 a step: the map's 800 states cost 5 s a pass)
HMM_MAX_STATES = 1_000  # a map with more states gets a plain HMM of this many (8 s a pass)
HMM_CHUNK = 200  # steps per chunk
HMM_GROUP = 100  # chunks filtered together
HMM_ITERS = 20  # EM iterations at most ...
HMM_PATIENCE = 2  # ... stopped after this many without a better validation score
HMM_VAL_STEPS = 20_000  # validation steps scored after each iteration
HMM_PSEUDOCOUNT = 1e-3  # added to every expected count before normalising


@dataclass(frozen=True)
class PlainHMM:
    """An action-conditioned HMM: ``T[a, s, s']``, emissions ``E[s, cell]``, start ``pi[s]``."""

    T: np.ndarray  # (A, S, S) rows sum to 1
    E: np.ndarray  # (S, K) rows sum to 1
    pi: np.ndarray  # (S,)


def _normalise(counts: np.ndarray) -> np.ndarray:
    counts = counts + HMM_PSEUDOCOUNT  # float64 sums ...
    return (counts / counts.sum(axis=-1, keepdims=True)).astype(np.float32)  # ... float32 steps


def random_hmm(states: int, cells: int, actions: int, seed: int) -> PlainHMM:
    """A random start for EM (Dirichlet rows), seeded."""
    rng = np.random.default_rng(seed)
    return PlainHMM(
        rng.dirichlet(np.ones(states), (actions, states)).astype(np.float32),
        rng.dirichlet(np.ones(cells), states).astype(np.float32),
        np.full(states, 1.0 / states, dtype=np.float32),
    )


def _forward(m: PlainHMM, cells: np.ndarray, actions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Scaled forward pass of chunks ``cells`` (B, L) under ``actions`` (B, L) (action t leads
    from step t to t + 1), each from ``pi``: (L, B, S) the filtered states and (L, B) the log
    of each step's scale, ``log p(c_t | the chunk's past)``."""
    B, L = cells.shape
    emit = m.E.T  # (K, S)
    alpha = np.empty((L, B, m.pi.size), dtype=m.T.dtype)
    log_scale = np.empty((L, B))
    a = m.pi[None] * emit[cells[:, 0]]
    for t in range(L):
        if t:
            prev, a = alpha[t - 1], np.empty_like(alpha[t - 1])
            for act in range(m.T.shape[0]):
                rows = actions[:, t - 1] == act
                a[rows] = prev[rows] @ m.T[act]
            a *= emit[cells[:, t]]
        scale = a.sum(axis=1)
        alpha[t], log_scale[t] = a / scale[:, None], np.log(scale)
    return alpha, log_scale


def _em_counts(m: PlainHMM, cells: np.ndarray, actions: np.ndarray, acc: dict) -> float:
    """Add the expected counts of chunks ``cells``, ``actions`` (B, L) to ``acc``; return
    their log-likelihood in nats."""
    alpha, log_scale = _forward(m, cells, actions)
    emit = m.E.T
    beta = np.ones_like(alpha[0])
    w = np.empty_like(alpha)  # (L, B, S) e(c_t) beta_t / scale_t: the counts' right factor
    for t in range(len(alpha) - 1, 0, -1):
        acc["E"] += _emission_counts(alpha[t] * beta, cells[:, t], emit.shape[0])
        w[t] = emit[cells[:, t]] * beta / np.exp(log_scale[t]).astype(beta.dtype)[:, None]
        for act in range(m.T.shape[0]):
            rows = actions[:, t - 1] == act
            beta[rows] = w[t][rows] @ m.T[act].T
    for act in range(m.T.shape[0]):
        steps = (actions[:, :-1] == act).T  # (L - 1, B): the transitions t-1 -> t under act
        acc["T"][act] += alpha[:-1][steps].T @ w[1:][steps]  # sum over them of alpha w^T
    gamma0 = alpha[0] * beta
    acc["E"] += _emission_counts(gamma0, cells[:, 0], emit.shape[0])
    acc["pi"] += gamma0.sum(axis=0)
    return float(log_scale.sum())


def _emission_counts(gamma: np.ndarray, cells: np.ndarray, k: int) -> np.ndarray:
    """(S, K) the posterior ``gamma`` (B, S) summed by the cell each chunk sees."""
    onehot = np.zeros((len(cells), k), dtype=gamma.dtype)
    onehot[np.arange(len(cells)), cells] = 1.0
    return gamma.T @ onehot


def em_step(m: PlainHMM, cells: np.ndarray, actions: np.ndarray) -> tuple[PlainHMM, float]:
    """One Baum-Welch iteration on the chunks ``cells``, ``actions`` (n, HMM_CHUNK): the new
    model and the old one's training log-likelihood per step (nats)."""
    acc = {name: np.zeros(x.shape) for name, x in (("T", m.T), ("E", m.E), ("pi", m.pi))}
    nats = sum(
        _em_counts(m, cells[g : g + HMM_GROUP], actions[g : g + HMM_GROUP], acc)
        for g in range(0, len(cells), HMM_GROUP)
    )
    T = _normalise(acc["T"] * m.T)  # the expected transitions: alpha T e beta, T's factor last
    return PlainHMM(T, _normalise(acc["E"]), _normalise(acc["pi"])), nats / cells.size


def log_likelihood(m: PlainHMM, cells: np.ndarray, actions: np.ndarray) -> np.ndarray:
    """(n,) ``log p(c_t | c_{<t}, a_{<t})`` in nats along one sequence (0 for the first, given),
    each step filtered from the ``HMM_CHUNK`` to ``2 HMM_CHUNK`` steps before it (all of them
    near the start): windows of ``2 HMM_CHUNK`` steps filtered together, as the GRU baseline
    scores blocks after their context."""
    cells, actions = np.asarray(cells, dtype=np.int64), np.asarray(actions, dtype=np.int64)
    n, L = len(cells), HMM_CHUNK
    out = np.zeros(n)
    if n <= 2 * L:
        out[1:] = _forward(m, cells[None], actions[None])[1][1:, 0]
        return out
    starts = [*range(0, n - 2 * L, L), n - 2 * L]
    done = 1
    for g in range(0, len(starts), HMM_GROUP):
        group = np.array(starts[g : g + HMM_GROUP])
        at = group[:, None] + np.arange(2 * L)  # (B, 2L)
        log_scale = _forward(m, cells[at], actions[at])[1]  # (2L, B)
        for i, s in enumerate(group):
            first = max(done, s + L) if s else 1
            out[first : s + 2 * L] = log_scale[first - s :, i]
            done = s + 2 * L
    return out


def _bits(m: PlainHMM, cells, actions) -> float:
    return float(-log_likelihood(m, cells, actions)[1:].mean() / math.log(2))


def plain_hmm_bits(train, val, test, clusters: int, states: int, seed: int = 0,
                   n_actions: int = 4, progress=None) -> dict:  # fmt: skip
    """Bits per step on the test split of a plain HMM of ``states`` states (module docstring; at
    most HMM_MAX_STATES), with the EM iteration chosen on the validation split, and what it was
    fitted on."""
    map_states, states = states, min(states, HMM_MAX_STATES)
    L = HMM_CHUNK
    n = min(len(train.cells), HMM_STEPS) // L * L
    if n < L or len(val.cells) < 2 or len(test.cells) < 2:
        return {"bits": None, "states": states, "map_states": map_states, "train_steps": n,
                "iterations": 0}  # fmt: skip
    cells = np.asarray(train.cells[:n], dtype=np.int64).reshape(-1, L)
    actions = np.asarray(train.actions[:n], dtype=np.int64).reshape(-1, L)
    v = min(len(val.cells), HMM_VAL_STEPS)
    model = random_hmm(states, clusters, n_actions, seed)
    best, best_model, since = math.inf, model, 0
    for i in range(HMM_ITERS):
        model = em_step(model, cells, actions)[0]
        on_val = _bits(model, val.cells[:v], val.actions[:v])
        if progress is not None:
            progress("plain HMM EM", i + 1, on_val)
        if on_val < best - 1e-4:
            best, best_model, since = on_val, model, 0
        else:
            since += 1
            if since >= HMM_PATIENCE:
                break
    return {
        "bits": _bits(best_model, test.cells, test.actions),
        "states": states,
        "map_states": map_states,
        "train_steps": n,
        "iterations": i + 1,
        "val_bits": best,
    }
