"""A plain-numpy hidden Markov model over every state (no clone structure used): the oracle of
``analysis.chmm``'s numba kernels, which work on the clones of the observed cells only."""

from __future__ import annotations

import numpy as np


def emissions(n_cells: int, n_clones: int) -> np.ndarray:
    """(K, S) 0/1: state s emits cell s // C."""
    return (np.arange(n_cells * n_clones)[None, :] // n_clones == np.arange(n_cells)[:, None]) * 1.0


def forward_backward(T: np.ndarray, cells: np.ndarray, actions: np.ndarray, n_clones: int):
    """(log p(c_t | past) for t >= 1 (n - 1,), expected transition counts (A, S, S)), by the
    textbook scaled forward-backward over all S states, the first state uniform on the clones
    of the first cell."""
    n, S = len(cells), T.shape[1]
    emit = emissions(S // n_clones, n_clones)
    alpha = np.zeros((n, S))
    alpha[0] = emit[cells[0]] / n_clones
    logp = np.zeros(n - 1)
    for t in range(n - 1):
        pred = (alpha[t] @ T[actions[t]]) * emit[cells[t + 1]]
        logp[t] = np.log(pred.sum())
        alpha[t + 1] = pred / pred.sum()
    beta = np.ones(S)
    counts = np.zeros_like(T)
    for t in range(n - 2, -1, -1):
        xi = alpha[t][:, None] * T[actions[t]] * (emit[cells[t + 1]] * beta)[None, :]
        counts[actions[t]] += xi / xi.sum()
        beta = T[actions[t]] @ (emit[cells[t + 1]] * beta)
        beta /= beta.sum()
    return logp, counts
