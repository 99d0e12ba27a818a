"""Where the map's clones start: the slow context, and the representation's finer clusters.

**The slow context**: where the robot has been over the last few hundred steps, as a label.

A cell says almost nothing of the room it is seen in ("a wall at some distance" is found in
every room), and the cloned HMM's EM spends its clones on the last few steps, which predict the
next cell far better than the room does (``docs/results/map``). The room is in the sequence,
over hundreds of steps: the context is the k-means cluster (``N_CONTEXTS`` of them) of the
causal, exponentially decayed histogram of the cells (time constant ``CONTEXT_TAU`` steps, about
the time the robot stays in a room). ``chmm.fit_chmm`` splits each clone by it once EM is done.

**The fine start** (``fine_clones``, ``map --start fine``): EM from the random start merges the
places a cell lumps together and keeps few clones a cell (in the grid regime, 5 active clones
for 58 place-headings a cell; ``docs/results/map/grid``). The representation itself tells
them apart better than its cell does: each step's clone for EM's start is its k-means cluster
among the representations of its cell (at most C clusters), so EM starts from the transitions
counted along the finer quantisation. The filter still sees the cell alone.
"""

from __future__ import annotations

import numpy as np
from scipy.signal import lfilter

from sensorimotor.analysis.clusters import assign_clusters, check_z, fit_kmeans

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


def fine_clones(z: np.ndarray, cells: np.ndarray, clones: int, seed: int = 0) -> np.ndarray:
    """(n,) int64 each step's clone for EM's start: the k-means cluster (k-means++, one
    initialisation: one fit a cell; at most ``clones``, and at most the cell's distinct
    representations) of its representation ``z`` (n, D) among its cell's."""
    from sklearn.cluster import KMeans

    z = check_z(z)
    out = np.zeros(len(cells), dtype=np.int64)
    for c in np.unique(cells):
        mine = np.flatnonzero(cells == c)
        k = min(clones, len(np.unique(z[mine], axis=0)))
        if k > 1:
            out[mine] = KMeans(k, n_init=1, random_state=seed).fit_predict(z[mine])
    return out
