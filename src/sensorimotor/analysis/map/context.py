"""The slow context: where the robot has been over the last few hundred steps, as a label.

A cell says almost nothing of the room it is seen in ("a wall at some distance" is found in
every room), and the cloned HMM's EM spends its clones on the last few steps, which predict the
next cell far better than the room does (``docs/results/map``). The room is in the sequence,
over hundreds of steps: the context is the k-means cluster (``N_CONTEXTS`` of them) of the
causal, exponentially decayed histogram of the cells (time constant ``CONTEXT_TAU`` steps, about
the time the robot stays in a room). ``chmm.fit_chmm`` splits each clone by it once EM is done.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans

N_CONTEXTS = 2  # contexts each clone is split into (1: the plain cloned HMM); chosen on the
# validation split (docs/results/map/diagnosis/select_contexts.py; 4 before, chosen on test)
MAX_CONTEXTS = 16
CONTEXT_TAU = 400.0  # steps; the robot stays about 330 steps in a room of Rooms1


def decayed_history(cells: np.ndarray, k: int, tau: float = CONTEXT_TAU) -> np.ndarray:
    """(n, k) at each step, the histogram of the cells seen so far, each weighted by
    ``(1 - 1/tau)`` per step of age (causal; it starts uniform and sums to 1)."""
    lam = 1.0 - 1.0 / tau
    onehot = np.zeros((len(cells), k))
    onehot[np.arange(len(cells)), cells] = 1.0
    start = np.full((1, k), lam / k)  # as if a uniform histogram preceded the first step
    return lfilter([1.0 - lam], [1.0, -lam], onehot, axis=0, zi=start)[0]


def slow_context(
    cells: np.ndarray, k: int, n_contexts: int = N_CONTEXTS, tau: float = CONTEXT_TAU, seed: int = 0
) -> np.ndarray:
    """(n,) int64 the context of each step: the k-means cluster (``n_contexts``, seeded) of its
    decayed history of cells; all zero for one context."""
    if n_contexts == 1:
        return np.zeros(len(cells), dtype=np.int64)
    history = decayed_history(cells, k, tau)
    return assign_clusters(fit_kmeans(history, n_contexts, seed), history).astype(np.int64)
