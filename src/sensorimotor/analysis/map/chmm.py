"""The compressed map: a clone-structured, action-conditioned hidden Markov model over cells.

Written from the description of George et al., "Clone-structured graph representations enable
flexible learning and vicarious evaluation of cognitive maps", Nature Communications 12:2392
(2021); no code is taken from anywhere.

The model: each of the K cells (observation symbols) owns C hidden *clones*; state
``s = cell * C + clone`` emits its cell and nothing else, so the emission matrix is fixed and
only the action-conditioned transitions ``T[a, s, s']`` (A, S, S), S = K C, are learned. Because
the state at step t must be a clone of the cell seen at t, every message lives on C numbers
and one step costs C^2 (not S^2): Baum-Welch restricted to the clones of the observed symbols.

Training, as in the paper:

1. **EM** (Baum-Welch): from a random ``T`` (drawn from a ``numpy.random.Generator``), the
   forward pass (scaled: each message sums to 1, the log of the scale is the step's likelihood,
   so long sequences do not underflow) and the backward pass accumulate the expected
   transition counts; ``T`` becomes the counts plus ``pseudocount`` everywhere, normalised.
   Stops when the training log-likelihood per step improves by less than ``tol`` nats, or after
   ``em_iters``.
2. **Viterbi training**: the single most likely state path (max-product in log space), hard
   counts along it, ``T`` from them; repeated until the path's log-probability stops improving.
3. **The context split** (ours, not the paper's; with ``n_contexts`` > 1): EM spends the
   clones on the last few steps, which predict the next cell best, and none on the room
   (``docs/results/map``). Each clone of the Viterbi path is split into ``n_contexts`` clones,
   one per slow context of the step (``context.slow_context``: where the robot has been over
   hundreds of steps), ``T`` is counted along the split path, and Viterbi training runs again
   (``SPLIT_VITERBI_ITERS``). The result is a cloned HMM like any other, of C x n_contexts
   clones per cell: the context is only where its clones start, not an input of the filter.

States the final path never visits are **pruned**: the pseudocount of the final ``T`` goes only
to the active states, so the filter never wanders into a pruned one.

Prediction: ``p(c_{t+1} | c_{0..t}, a_{0..t})`` is the forward scale at t + 1 (the sequence's
first cell is given); the filtered state ``p(s_t | c_{0..t}, a_{0..t-1})`` is the forward message.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba
import numpy as np

from sensorimotor.analysis.map.cells import check_sequence

EM_ITERS = 100  # at most this many EM iterations
VITERBI_ITERS = 20  # at most this many Viterbi-training iterations
SPLIT_VITERBI_ITERS = 5  # at most this many after the context split (each pass costs N^2 more)
TOL = 1e-4  # nats per step: EM stops when an iteration improves the log-likelihood by less
PSEUDOCOUNT = 1e-3  # added to every transition count (EM) / every active target (final map)


@numba.njit(cache=True)
def _forward(T, cells, actions, C, alpha):
    """Scaled forward pass: fill ``alpha`` (n, C) with the filtered distribution over the clones
    of ``cells[t]`` and return (n,) the log of each step's scale, ``log p(c_t | past)`` (0 for
    t = 0, whose cell is given). A step given probability 0 (a transition the map forbids) has
    log -inf and restarts the filter uniformly on the clones of its cell."""
    n = cells.shape[0]
    logz = np.zeros(n)
    for i in range(C):
        alpha[0, i] = 1.0 / C
    new = np.empty(C)
    for t in range(n - 1):
        i0 = cells[t] * C
        j0 = cells[t + 1] * C
        a = actions[t]
        for j in range(C):
            new[j] = 0.0
        for i in range(C):
            ai = alpha[t, i]
            if ai == 0.0:
                continue
            for j in range(C):
                new[j] += ai * T[a, i0 + i, j0 + j]
        total = 0.0
        for j in range(C):
            total += new[j]
        if total > 0.0:
            for j in range(C):
                alpha[t + 1, j] = new[j] / total
            logz[t + 1] = math.log(total)
        else:
            for j in range(C):
                alpha[t + 1, j] = 1.0 / C
            logz[t + 1] = -np.inf
    return logz


@numba.njit(cache=True)
def _backward_counts(T, cells, actions, C, alpha, counts):
    """Scaled backward pass; add the expected transition counts ``xi_t(i, j)`` (each step's sum
    to 1) into ``counts`` (A, S, S)."""
    n = cells.shape[0]
    beta = np.full(C, 1.0 / C)
    new = np.empty(C)
    tb = np.empty((C, C))
    for t in range(n - 2, -1, -1):
        i0 = cells[t] * C
        j0 = cells[t + 1] * C
        a = actions[t]
        total = 0.0
        norm = 0.0
        for i in range(C):  # tb = T beta, once: both xi = alpha tb and the new beta use it
            s = 0.0
            for j in range(C):
                v = T[a, i0 + i, j0 + j] * beta[j]
                tb[i, j] = v
                s += v
            new[i] = s
            norm += s
            total += alpha[t, i] * s
        if total > 0.0:
            inv = 1.0 / total
            for i in range(C):
                w = alpha[t, i] * inv
                if w == 0.0:
                    continue
                for j in range(C):
                    counts[a, i0 + i, j0 + j] += w * tb[i, j]
        for i in range(C):
            beta[i] = new[i] / norm if norm > 0.0 else 1.0 / C


@numba.njit(cache=True)
def _viterbi(logT, cells, actions, C):
    """Most likely clone path (n,) int64 (states ``cells * C + clone``) and its log-probability."""
    n = cells.shape[0]
    back = np.zeros((n, C), dtype=np.int32)
    delta = np.full(C, -math.log(C))
    new = np.empty(C)
    offset = 0.0
    for t in range(n - 1):
        i0 = cells[t] * C
        j0 = cells[t + 1] * C
        a = actions[t]
        for j in range(C):
            best = -np.inf
            arg = 0
            for i in range(C):
                v = delta[i] + logT[a, i0 + i, j0 + j]
                if v > best:
                    best = v
                    arg = i
            new[j] = best
            back[t + 1, j] = arg
        top = new.max()
        for j in range(C):
            delta[j] = new[j] - top if top > -np.inf else 0.0
        offset += top
    path = np.empty(n, dtype=np.int64)
    clone = int(np.argmax(delta))
    for t in range(n - 1, -1, -1):
        path[t] = cells[t] * C + clone
        clone = back[t, clone]
    return path, offset


def _normalise(counts: np.ndarray, pseudocount: float, targets: np.ndarray | None = None):
    """Rows of ``counts + pseudocount`` (on ``targets`` only, if given) summing to 1; a row with
    no mass at all becomes uniform over the targets."""
    extra = pseudocount if targets is None else pseudocount * targets
    T = counts + extra
    total = T.sum(axis=2, keepdims=True)
    fill = np.ones(T.shape[2]) if targets is None else targets.astype(np.float64)
    fill = fill / fill.sum()
    return np.where(total > 0, T / np.where(total > 0, total, 1.0), fill)


def _path_counts(path: np.ndarray, actions: np.ndarray, shape: tuple) -> np.ndarray:
    """(A, S, S) counts of the transitions along a state path."""
    A, S, _ = shape
    flat = (actions[:-1] * S + path[:-1]) * S + path[1:]
    return np.bincount(flat, minlength=A * S * S).astype(np.float64).reshape(shape)


@dataclass(frozen=True)
class CloneHMM:
    """A fitted cloned HMM: K cells of C clones each, A actions."""

    T: np.ndarray  # (A, S, S) float64 transition probabilities, rows summing to 1
    n_clones: int  # C
    active: np.ndarray  # (S,) bool: states the Viterbi path visits (the rest are pruned)
    counts: np.ndarray  # (A, S, S) the Viterbi path's transition counts on the training data
    history: dict  # log-likelihood per step (nats) after each EM / Viterbi iteration
    T_em: np.ndarray  # (A, K C', K C') after EM, before Viterbi (C' = C / contexts: unsplit)

    @property
    def n_cells(self) -> int:
        return self.T.shape[1] // self.n_clones

    @property
    def n_states(self) -> int:
        return self.T.shape[1]

    def state_cell(self) -> np.ndarray:
        """(S,) the cell each state emits."""
        return np.arange(self.n_states) // self.n_clones


def _sequence(cells, actions, k: int, n_actions: int):
    cells, actions = check_sequence(cells, actions, k, n_actions)
    return np.ascontiguousarray(cells), np.ascontiguousarray(actions)


def log_likelihood(T: np.ndarray, cells, actions, n_clones: int) -> np.ndarray:
    """(n,) ``log p(c_t | c_{<t}, a_{<t})`` in nats (0 for the first, given, step)."""
    cells, actions = _sequence(cells, actions, T.shape[1] // n_clones, T.shape[0])
    alpha = np.empty((len(cells), n_clones))
    return _forward(np.ascontiguousarray(T), cells, actions, n_clones, alpha)


def filtered(model: CloneHMM, cells, actions) -> np.ndarray:
    """(n, C) the filtered distribution over the clones of each step's cell (causal)."""
    cells, actions = _sequence(cells, actions, model.n_cells, model.T.shape[0])
    alpha = np.empty((len(cells), model.n_clones))
    _forward(np.ascontiguousarray(model.T), cells, actions, model.n_clones, alpha)
    return alpha


def _viterbi_training(T, cells, actions, C, iters, history, stage, progress, path=None):
    """Viterbi training from ``T``: the most likely path, ``T`` from its counts, until the path's
    log-probability stops improving or ``iters``; returns the last ``T`` and its path (``path``
    if not even the first pass improves on -inf: iters = 0)."""
    n = len(cells)
    previous = -np.inf
    history[stage] = []
    for it in range(iters):
        with np.errstate(divide="ignore"):
            new_path, logp = _viterbi(np.log(T), cells, actions, C)
        ll = logp / (n - 1)
        if ll <= previous + 1e-12:
            break
        path, previous = new_path, ll
        history[stage].append(float(ll))
        if progress is not None:
            progress(stage, it, ll)
        T = _normalise(_path_counts(path, actions, T.shape), 0.0)
    return T, path


def fit_chmm(
    cells: np.ndarray,
    actions: np.ndarray,
    n_cells: int,
    n_clones: int,
    n_actions: int,
    seed: int | np.random.Generator = 0,
    em_iters: int = EM_ITERS,
    viterbi_iters: int = VITERBI_ITERS,
    tol: float = TOL,
    pseudocount: float = PSEUDOCOUNT,
    context: np.ndarray | None = None,
    n_contexts: int = 1,
    progress=None,
) -> CloneHMM:
    """Fit a cloned HMM to one training sequence: EM, then Viterbi training, the split by
    ``context`` ((n,) labels in [0, n_contexts), ``context.slow_context``) if more than one, and
    pruning (see the module docstring). ``progress(stage, iteration, loglik_per_step)`` after
    each iteration."""
    if n_clones < 1:
        raise ValueError(f"the number of clones must be at least 1, got {n_clones}")
    cells, actions = _sequence(cells, actions, n_cells, n_actions)
    if n_contexts > 1:
        context = np.ascontiguousarray(context, dtype=np.int64)
        if context.shape != cells.shape or context.min() < 0 or context.max() >= n_contexts:
            raise ValueError(f"context must be {cells.shape} labels in [0, {n_contexts})")
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    S, C, n = n_cells * n_clones, n_clones, len(cells)
    T = _normalise(rng.random((n_actions, S, S)), 0.0)
    alpha = np.empty((n, C))
    history: dict[str, list[float]] = {"em": [], "viterbi": []}
    previous = -np.inf
    for it in range(em_iters):
        ll = _forward(T, cells, actions, C, alpha)[1:].sum() / (n - 1)
        history["em"].append(float(ll))
        if progress is not None:
            progress("em", it, ll)
        if ll - previous < tol:
            break
        previous = ll
        counts = np.zeros_like(T)
        _backward_counts(T, cells, actions, C, alpha, counts)
        T = _normalise(counts, pseudocount)
    del alpha
    T_em = T
    T, path = _viterbi_training(T, cells, actions, C, viterbi_iters, history, "viterbi", progress)
    if n_contexts > 1:  # each clone becomes n_contexts clones, one per context, then Viterbi
        split = C * n_contexts
        path = cells * split + (path % C) * n_contexts + context
        shape = (n_actions, n_cells * split, n_cells * split)
        T = _normalise(_path_counts(path, actions, shape), pseudocount)
        S, C = n_cells * split, split
        T, path = _viterbi_training(
            T, cells, actions, C, SPLIT_VITERBI_ITERS, history, "split", progress, path
        )
    counts = _path_counts(path, actions, T.shape)
    active = np.zeros(S, dtype=bool)
    active[path] = True
    for cell in range(n_cells):  # a cell never seen in training keeps one clone to be seen by
        if not active[cell * C : (cell + 1) * C].any():
            active[cell * C] = True
    T = _normalise(counts, pseudocount, active)
    return CloneHMM(T, C, active, counts, history, T_em)
