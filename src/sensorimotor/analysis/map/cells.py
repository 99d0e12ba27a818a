"""Cells, actions and the cell graph: the paper's proposed map, taken literally.

The paper's conclusion proposes "a graph where the nodes would correspond to activations of
those cells, and the edges would correspond to motor commands". Here:

- **Cells**: k-means clusters of a representation (``clusters.fit_kmeans``), one per step.
- **Actions**: the motor command ``m_t = (d, r)`` (row t of a database; it leads from s_t to
  s_{t+1}) in ``N_ACTIONS`` bins. The behaviour draws ``r ~ U(-pi/6, pi/6)`` when it moves on and
  ``(0, r ~ U(9 pi/10, 11 pi/10))`` when a reading is below 1; the turn-around is its own action:

  ====== ============== ==================================
  action name           rule
  ====== ============== ==================================
  0      ``turn``       ``|r| > 3 pi/4``, r wrapped to [-pi, pi) (the turn-around)
  1      ``right``      ``r < -pi/18`` (clockwise thirds of the moving range)
  2      ``straight``   ``-pi/18 <= r <= pi/18``
  3      ``left``       ``r > pi/18``
  ====== ============== ==================================

  The forward distance ``d ~ U(0, 1)`` is not binned: it is recorded on each edge instead.
  The same bins serve the other behaviours: the lattice's turns of +-pi/6 are ``left`` and
  ``right``, its turn-arounds (pi -+ pi/6) ``turn``; the grid's quarter turns are ``left`` and
  ``right`` (its reflex's 3 pi/2 is a right turn, which is what it does), its half turn ``turn``.
- **The cell graph**: nodes are cells, an edge ``(i, a, j)`` is a transition seen from cell i
  under action a to cell j, with its count and the mean and sd of the motor command over it.

Next-cell prediction (``bits_per_step``, bits per predicted step on held-out data):

- **unigram**: ``p(j)``, the training frequencies;
- **markov**: ``p(j | i, a)``, first-order counts smoothed towards the unigram:
  ``(n_iaj + beta p(j)) / (n_ia + beta)``;
- **cell graph**: the graph's edges without their counts: uniform over the successors of
  ``(i, a)`` seen in training, smoothed towards the unigram in the same way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

ACTION_NAMES = ("turn", "right", "straight", "left")
N_ACTIONS = len(ACTION_NAMES)
TURN_LIMIT = 3 * math.pi / 4  # |r| above this is the turn-around (the grid's turns are pi/2)
STRAIGHT = math.pi / 18  # |r| at most this is "straight" (the middle third of [-pi/6, pi/6])
SMOOTHING = 1.0  # beta: pseudo-counts of the unigram added to each (cell, action) row


@dataclass(frozen=True)
class Steps:
    """One split as the map sees it."""

    cells: np.ndarray  # (n,) int64 cell of each step
    actions: np.ndarray  # (n,) int64 action taken at each step (leads to the next)
    motors: np.ndarray  # (n, 2) float64 (d, r)
    poses: np.ndarray  # (n, 3) float64 (x, y, heading)


def action_bins(motors: np.ndarray) -> np.ndarray:
    """(N,) int64 action of each motor command (N, 2) ``(d, r)``: see the module docstring."""
    motors = np.asarray(motors, dtype=np.float64)
    if motors.ndim != 2 or motors.shape[1] != 2:
        raise ValueError(f"motors must have shape (N, 2), got {motors.shape}")
    r = (motors[:, 1] + math.pi) % (2 * math.pi) - math.pi
    actions = np.where(r < -STRAIGHT, 1, np.where(r > STRAIGHT, 3, 2))
    return np.where(np.abs(r) > TURN_LIMIT, 0, actions).astype(np.int64)


def check_sequence(cells: np.ndarray, actions: np.ndarray, k: int, n_actions: int = N_ACTIONS):
    """``cells`` and ``actions`` as int64 arrays of one length, in range; ValueError if not."""
    cells = np.asarray(cells, dtype=np.int64)
    actions = np.asarray(actions, dtype=np.int64)
    if cells.ndim != 1 or cells.shape != actions.shape:
        raise ValueError(f"cells {cells.shape} and actions {actions.shape} must be one length")
    if len(cells) < 2:
        raise ValueError(f"a sequence needs at least 2 steps, got {len(cells)}")
    if cells.min() < 0 or cells.max() >= k:
        raise ValueError(f"cells must lie in [0, {k}), got [{cells.min()}, {cells.max()}]")
    if actions.min() < 0 or actions.max() >= n_actions:
        raise ValueError(f"actions must lie in [0, {n_actions}), got {actions.min()}..")
    return cells, actions


def transition_counts(
    cells: np.ndarray, actions: np.ndarray, k: int, n_actions: int = N_ACTIONS
) -> np.ndarray:
    """(A, K, K) float64 counts of ``cells[t], actions[t] -> cells[t + 1]``."""
    cells, actions = check_sequence(cells, actions, k, n_actions)
    flat = (actions[:-1] * k + cells[:-1]) * k + cells[1:]
    return (
        np.bincount(flat, minlength=n_actions * k * k).astype(np.float64).reshape(n_actions, k, k)
    )


@dataclass(frozen=True)
class CellGraph:
    """The cell graph: nodes = cells, edges = observed ``(cell, action) -> next cell``."""

    counts: np.ndarray  # (A, K, K) transitions seen
    unigram: np.ndarray  # (K,) frequency of each cell (smoothed: never 0)
    motor_mean: np.ndarray  # (A, K, K, 2) mean (d, r) over each edge (0 where no edge)
    motor_sd: np.ndarray  # (A, K, K, 2) sd of (d, r) over each edge (0 where fewer than 2)

    @property
    def k(self) -> int:
        return self.counts.shape[1]

    def edges(self) -> list[dict]:
        """Every edge with its count and motor statistics, as JSON-ready dicts."""
        out = []
        for a, i, j in zip(*np.nonzero(self.counts), strict=True):
            out.append(
                {
                    "source": int(i),
                    "target": int(j),
                    "action": ACTION_NAMES[a] if self.counts.shape[0] == N_ACTIONS else int(a),
                    "count": int(self.counts[a, i, j]),
                    "d_mean": float(self.motor_mean[a, i, j, 0]),
                    "r_mean": float(self.motor_mean[a, i, j, 1]),
                    "d_sd": float(self.motor_sd[a, i, j, 0]),
                    "r_sd": float(self.motor_sd[a, i, j, 1]),
                }
            )
        return out


def unigram(cells: np.ndarray, k: int, alpha: float = 0.5) -> np.ndarray:
    """(K,) cell frequencies with ``alpha`` pseudo-counts each (0: the plain frequencies)."""
    n = np.bincount(np.asarray(cells, dtype=np.int64), minlength=k)[:k].astype(np.float64)
    return (n + alpha) / (n.sum() + alpha * k)


def cell_graph(
    cells: np.ndarray, actions: np.ndarray, motors: np.ndarray, k: int, n_actions: int = N_ACTIONS
) -> CellGraph:
    """The cell graph of one sequence (cells, actions, motors (N, 2) of the same steps)."""
    counts = transition_counts(cells, actions, k, n_actions)
    motors = np.asarray(motors, dtype=np.float64)[:-1]  # (N - 1, 2) the command of each edge
    flat = (actions[:-1] * k + cells[:-1]) * k + cells[1:]
    size = n_actions * k * k
    n = counts.reshape(-1)
    mean = np.zeros((size, 2))
    sd = np.zeros((size, 2))
    for c in range(2):
        s1 = np.bincount(flat, weights=motors[:, c], minlength=size)
        s2 = np.bincount(flat, weights=motors[:, c] ** 2, minlength=size)
        m = np.divide(s1, n, out=np.zeros(size), where=n > 0)
        var = np.divide(s2 - n * m**2, n - 1, out=np.zeros(size), where=n > 1)
        mean[:, c], sd[:, c] = m, np.sqrt(np.maximum(var, 0.0))
    shape = (n_actions, k, k, 2)
    return CellGraph(counts, unigram(cells, k), mean.reshape(shape), sd.reshape(shape))


def markov_table(counts: np.ndarray, prior: np.ndarray, beta: float = SMOOTHING) -> np.ndarray:
    """(A, K, K) ``p(j | i, a) = (n_iaj + beta prior_j) / (n_ia + beta)``."""
    return (counts + beta * prior) / (counts.sum(axis=2, keepdims=True) + beta)


def graph_table(counts: np.ndarray, prior: np.ndarray, beta: float = SMOOTHING) -> np.ndarray:
    """(A, K, K) the cell graph as a predictor: uniform over the seen successors of (i, a)."""
    return markov_table((counts > 0).astype(np.float64), prior, beta)


def bits(p: np.ndarray) -> float:
    """Mean ``-log2 p`` of the probabilities given to what happened (bits per step)."""
    p = np.asarray(p, dtype=np.float64)
    return float(-np.log2(p).mean())


def table_bits(table: np.ndarray, cells: np.ndarray, actions: np.ndarray) -> float:
    """Bits per step of a (A, K, K) conditional table predicting ``cells[t + 1]``."""
    return bits(table[actions[:-1], cells[:-1], cells[1:]])


def baseline_bits(
    train_cells: np.ndarray,
    train_actions: np.ndarray,
    test_cells: np.ndarray,
    test_actions: np.ndarray,
    k: int,
    n_actions: int = N_ACTIONS,
    beta: float = SMOOTHING,
) -> dict[str, float]:
    """Bits per step on the test sequence of the unigram, the first-order (cell, action) Markov
    model and the cell graph, all estimated on the training sequence."""
    test_cells, test_actions = check_sequence(test_cells, test_actions, k, n_actions)
    counts = transition_counts(train_cells, train_actions, k, n_actions)
    prior = unigram(train_cells, k)
    return {
        "unigram": bits(prior[test_cells[1:]]),
        "markov": table_bits(markov_table(counts, prior, beta), test_cells, test_actions),
        "cell_graph": table_bits(graph_table(counts, prior, beta), test_cells, test_actions),
    }


def ngram_bits(
    train_cells: np.ndarray,
    train_actions: np.ndarray,
    test_cells: np.ndarray,
    test_actions: np.ndarray,
    k: int,
    order: int,
    n_actions: int = N_ACTIONS,
    beta: float = SMOOTHING,
) -> float:
    """Bits per step on the test sequence of an ``order``-th order (cell, action) model with
    back-off, estimated on the training sequence: the next cell given the last ``order``
    (cell, action) pairs, ``p_n(j | h_n) = (n(h_n, j) + beta p_{n-1}(j | h_{n-1})) /
    (n(h_n) + beta)``, down to the unigram at order 0. Order 1 is ``markov_table``'s model; a
    history not seen in training (or cut by the sequence's start) leaves its lower order as is.
    """
    return bits(ngram_probs(train_cells, train_actions, test_cells, test_actions, k, order,
                            n_actions, beta))  # fmt: skip


def ngram_probs(
    train_cells: np.ndarray,
    train_actions: np.ndarray,
    test_cells: np.ndarray,
    test_actions: np.ndarray,
    k: int,
    order: int,
    n_actions: int = N_ACTIONS,
    beta: float = SMOOTHING,
) -> np.ndarray:
    """(T - 1,) the probability ``ngram_bits``'s model gives each next cell of the test
    sequence."""
    train_cells, train_actions = check_sequence(train_cells, train_actions, k, n_actions)
    test_cells, test_actions = check_sequence(test_cells, test_actions, k, n_actions)
    prior = unigram(train_cells, k)
    p = prior[test_cells[1:]]  # (T - 1,) order 0
    for n in range(1, order + 1):
        train_h = _histories(train_cells, train_actions, k, n_actions, n)  # (N - 1,) or -1
        test_h = _histories(test_cells, test_actions, k, n_actions, n)
        seen = train_h >= 0
        pairs = train_h[seen] * k + train_cells[1:][seen]
        keys, counts = np.unique(pairs, return_counts=True)
        hists, totals = np.unique(train_h[seen], return_counts=True)
        n_pair = _lookup(keys, counts, np.where(test_h >= 0, test_h * k + test_cells[1:], -1))
        n_hist = _lookup(hists, totals, test_h)
        p = (n_pair + beta * p) / (n_hist + beta)
    return p


def _histories(cells: np.ndarray, actions: np.ndarray, k: int, n_actions: int, n: int):
    """(N - 1,) int64 code of the last ``n`` (cell, action) pairs before each transition
    ``t -> t + 1`` (-1 where the sequence starts too late for ``n`` of them)."""
    pair = actions[:-1] * k + cells[:-1]  # (N - 1,) in [0, A K)
    code = np.full(len(pair), -1, dtype=np.int64)
    if len(pair) >= n:
        code[n - 1 :] = 0
        for i in range(n):  # the pair i steps back, as the digit of weight (A K)^i
            code[n - 1 :] += pair[n - 1 - i : len(pair) - i] * (k * n_actions) ** i
    return code


def _lookup(keys: np.ndarray, counts: np.ndarray, queries: np.ndarray) -> np.ndarray:
    """(Q,) float64 count of each query among ``keys`` (sorted, unique); 0 where absent."""
    if len(keys) == 0:
        return np.zeros(len(queries))
    at = np.clip(np.searchsorted(keys, queries), 0, len(keys) - 1)
    return np.where((keys[at] == queries) & (queries >= 0), counts[at], 0).astype(np.float64)
