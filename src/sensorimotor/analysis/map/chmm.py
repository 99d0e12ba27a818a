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
from sensorimotor.errors import InputError

EM_ITERS = 100  # at most this many EM iterations
VITERBI_ITERS = 20  # at most this many Viterbi-training iterations
SPLIT_VITERBI_ITERS = 5  # at most this many after the context split (each pass costs N^2 more)
TOL = 1e-4  # nats per step: EM stops when an iteration improves the log-likelihood by less
PSEUDOCOUNT = 1e-3  # added to every transition count (EM) / every active target (final map)
MAX_BLOCK_BYTES = 2 * 1024**3  # one (B, C, C) float64 store; a fit holds about four at once
RANDOM_CHUNK = 2**22  # numbers drawn at a time for the random start


@dataclass(frozen=True)
class Transitions:
    """``T[a, s, s']`` of a cloned HMM (s = cell * C + clone), stored by blocks (module
    docstring): ``T[a, c C + i, c' C + j]`` is ``blocks[b, i, j]`` where ``keys[b]`` is
    (c, a, c'), else ``rest[a, c C + i] * targets[c' C + j]``."""

    keys: np.ndarray  # (B,) int64 sorted: (cell * A + action) * K + next cell
    blocks: np.ndarray  # (B, C, C) float64
    rest: np.ndarray  # (A, S) float64 the probability of each target outside the blocks
    targets: np.ndarray  # (S,) float64 1 for a state that can be a target, 0 for a pruned one
    n_cells: int  # K
    n_actions: int  # A

    @property
    def n_clones(self) -> int:
        return self.blocks.shape[1]

    @property
    def n_states(self) -> int:
        return self.n_cells * self.n_clones

    def ids(self, cells: np.ndarray, actions: np.ndarray) -> np.ndarray:
        """(n - 1,) int64 the block of each step's transition, -1 where there is none."""
        key = _triple_keys(cells, actions, self.n_cells, self.n_actions)
        if not len(self.keys):
            return np.full(len(key), -1, dtype=np.int64)
        at = np.minimum(np.searchsorted(self.keys, key), len(self.keys) - 1)
        return np.where(self.keys[at] == key, at, -1)

    def block(self, action: int, cell: int, next_cell: int) -> np.ndarray:
        """(C, C) ``T[action, clones of cell, clones of next_cell]``."""
        b = self.ids(np.array([cell, next_cell]), np.array([action, 0]))[0]
        if b >= 0:
            return self.blocks[b]
        C = self.n_clones
        rows = self.rest[action, cell * C : (cell + 1) * C]
        return np.outer(rows, self.targets[next_cell * C : (next_cell + 1) * C])

    def after(self, action: int, values: np.ndarray) -> np.ndarray:
        """(S,) ``sum_s' T[action, s, s'] values[s']``: ``values`` (S,) expected one step on."""
        K, C = self.n_cells, self.n_clones
        cell, a, nxt = _unkey(self.keys, K, self.n_actions)
        mine = a == action
        cell, nxt = cell[mine], nxt[mine]
        reached = (self.targets * values).reshape(K, C)
        inside = np.zeros((K, C))
        np.add.at(
            inside, cell, np.einsum("bij,bj->bi", self.blocks[mine], values.reshape(K, C)[nxt])
        )
        outside = np.full(K, reached.sum())  # every target's value but the blocks' own
        np.subtract.at(outside, cell, reached[nxt].sum(axis=1))
        return (inside + self.rest[action].reshape(K, C) * outside[:, None]).reshape(-1)

    def entries(self, values: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
        """(source state, target state, action, value) of every entry of the blocks, or of
        ``values`` (B, C, C) laid out as they are, each (B C^2,)."""
        C = self.n_clones
        values = self.blocks if values is None else values
        cell, a, nxt = (x.repeat(C * C) for x in _unkey(self.keys, self.n_cells, self.n_actions))
        i, j = (np.tile(x.ravel(), len(self.keys)) for x in np.indices((C, C)))
        return cell * C + i, nxt * C + j, a, values.ravel()

    def dense(self) -> np.ndarray:
        """(A, S, S) the full matrix (small maps and tests only)."""
        C = self.n_clones
        T = self.rest[:, :, None] * self.targets[None, None, :]
        cell, a, nxt = _unkey(self.keys, self.n_cells, self.n_actions)
        for b in range(len(self.keys)):
            T[a[b], cell[b] * C : (cell[b] + 1) * C, nxt[b] * C : (nxt[b] + 1) * C] = self.blocks[b]
        return T

    @classmethod
    def from_dense(cls, T: np.ndarray, n_clones: int) -> Transitions:
        """The store of a dense (A, S, S) ``T``, with a block for every triple."""
        A, S, _ = T.shape
        K, C = S // n_clones, n_clones
        keys = np.arange(K * A * K, dtype=np.int64)
        cell, a, nxt = _unkey(keys, K, A)
        blocks = T.reshape(A, K, C, K, C)[a, cell, :, nxt, :]  # (B, C, C)
        return cls(keys, np.ascontiguousarray(blocks), np.zeros((A, S)), np.ones(S), K, A)


def _triple_keys(cells: np.ndarray, actions: np.ndarray, k: int, n_actions: int) -> np.ndarray:
    """(n - 1,) the key (cell * A + action) * K + next cell of each step's transition."""
    return (cells[:-1] * n_actions + actions[:-1]) * k + cells[1:]


def _unkey(keys: np.ndarray, k: int, n_actions: int) -> tuple:
    """(cell, action, next cell) of each key."""
    return keys // (n_actions * k), (keys // k) % n_actions, keys % k


def _normalise(
    keys, counts, k: int, n_actions: int, pseudocount: float, targets=None
) -> Transitions:
    """The Transitions of ``counts`` (B, C, C) plus ``pseudocount`` on every target (only on
    ``targets`` (S,) bool, if given), rows summing to 1; a row with no mass at all becomes
    uniform over the targets."""
    C = counts.shape[1]
    S = k * C
    t = np.ones(S) if targets is None else targets.astype(np.float64)
    cell, a, nxt = _unkey(keys, k, n_actions)
    total = np.full((n_actions, k, C), pseudocount * t.sum())  # the rest's share, then the blocks
    np.add.at(total, (a, cell), counts.sum(axis=2))
    rows = total[a, cell][:, :, None]  # (B, C, 1)
    target = t.reshape(k, C)[nxt][:, None, :]  # (B, 1, C)
    fill = 1.0 / t.sum()
    blocks = np.where(rows > 0, (counts + pseudocount * target) / np.where(rows > 0, rows, 1.0),
                      target * fill)  # fmt: skip
    total = total.reshape(n_actions, S)
    rest = np.where(total > 0, pseudocount / np.where(total > 0, total, 1.0), fill)
    return Transitions(keys, blocks, rest, t, k, n_actions)


def _random_start(rng: np.random.Generator, keys, k: int, C: int, n_actions: int) -> Transitions:
    """The blocks of the dense random start ``rng.random((A, S, S))`` with rows normalised: the
    same stream, drawn a few cells' rows at a time, so a fit starts where the dense one did."""
    S = k * C
    blocks = np.empty((len(keys), C, C))
    rest = np.zeros((n_actions, S))
    nxt = keys % k
    first = np.searchsorted(keys, np.arange(k * n_actions + 1) * k)  # blocks of each (cell, a)
    per = max(1, RANDOM_CHUNK // (S * C))  # cells a draw
    for action in range(n_actions):
        for c0 in range(0, k, per):
            r = rng.random((min(per, k - c0) * C, S))
            r /= r.sum(axis=1, keepdims=True)
            for c in range(c0, min(c0 + per, k)):
                mine = slice(first[c * n_actions + action], first[c * n_actions + action + 1])
                rows = r[(c - c0) * C : (c - c0 + 1) * C]
                for b in range(mine.start, mine.stop):
                    blocks[b] = rows[:, nxt[b] * C : (nxt[b] + 1) * C]
                outside = S - C * (mine.stop - mine.start)
                if outside:  # the rest: the mean of what the blocks leave
                    inside = blocks[mine].sum(axis=(0, 2))
                    rest[action, c * C : (c + 1) * C] = (1.0 - inside) / outside
    return Transitions(keys, blocks, rest, np.ones(S), k, n_actions)


@numba.njit(cache=True)
def _forward(blocks, ids, rest, targets, cells, actions, C, alpha):
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
        b = ids[t]
        for j in range(C):
            new[j] = 0.0
        for i in range(C):
            ai = alpha[t, i]
            if ai == 0.0:
                continue
            if b >= 0:
                for j in range(C):
                    new[j] += ai * blocks[b, i, j]
            else:  # a transition the training sequence never made: the rest of the row
                r = ai * rest[actions[t], cells[t] * C + i]
                j0 = cells[t + 1] * C
                for j in range(C):
                    new[j] += r * targets[j0 + j]
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
def _backward_counts(blocks, ids, C, alpha, counts):
    """Scaled backward pass over a training sequence (every step has its block); add the
    expected transition counts ``xi_t(i, j)`` (each step's sum to 1) into ``counts`` (B, C, C)."""
    n = ids.shape[0] + 1
    beta = np.full(C, 1.0 / C)
    new = np.empty(C)
    tb = np.empty((C, C))
    for t in range(n - 2, -1, -1):
        b = ids[t]
        total = 0.0
        norm = 0.0
        for i in range(C):  # tb = T beta, once: both xi = alpha tb and the new beta use it
            s = 0.0
            for j in range(C):
                v = blocks[b, i, j] * beta[j]
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
                    counts[b, i, j] += w * tb[i, j]
        for i in range(C):
            beta[i] = new[i] / norm if norm > 0.0 else 1.0 / C


@numba.njit(cache=True)
def _viterbi(log_blocks, ids, cells, C):
    """Most likely clone path (n,) int64 (states ``cells * C + clone``) of a training sequence
    and its log-probability."""
    n = cells.shape[0]
    back = np.zeros((n, C), dtype=np.int32)
    delta = np.full(C, -math.log(C))
    new = np.empty(C)
    offset = 0.0
    for t in range(n - 1):
        b = ids[t]
        for j in range(C):
            best = -np.inf
            arg = 0
            for i in range(C):
                v = delta[i] + log_blocks[b, i, j]
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


def _path_counts(path: np.ndarray, ids: np.ndarray, C: int, n_blocks: int) -> np.ndarray:
    """(B, C, C) counts of the transitions along a state path, block by block."""
    flat = (ids * C + path[:-1] % C) * C + path[1:] % C
    return np.bincount(flat, minlength=n_blocks * C * C).astype(np.float64).reshape(-1, C, C)


@dataclass(frozen=True)
class CloneHMM:
    """A fitted cloned HMM: K cells of C clones each, A actions."""

    T: Transitions  # the transition probabilities, rows summing to 1
    active: np.ndarray  # (S,) bool: states the Viterbi path visits (the rest are pruned)
    counts: np.ndarray  # (B, C, C) the Viterbi path's transition counts, on T's blocks
    history: dict  # log-likelihood per step (nats) after each EM / Viterbi iteration
    T_em: Transitions  # after EM, before Viterbi (C / contexts clones: unsplit)

    @property
    def n_clones(self) -> int:
        return self.T.n_clones

    @property
    def n_cells(self) -> int:
        return self.T.n_cells

    @property
    def n_states(self) -> int:
        return self.T.n_states

    def state_cell(self) -> np.ndarray:
        """(S,) the cell each state emits."""
        return np.arange(self.n_states) // self.n_clones

    def transitions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(source state, target state, action, count) of every transition the Viterbi path
        takes, each (E,) int64."""
        source, target, action, count = self.T.entries(self.counts)
        taken = count > 0
        return source[taken], target[taken], action[taken], count[taken].astype(np.int64)

    def edge_counts(self):
        """(S, S) scipy sparse: the path's transitions from state to state, actions summed."""
        from scipy.sparse import coo_matrix

        source, target, _, count = self.transitions()
        S = self.n_states
        return coo_matrix((count.astype(np.float64), (source, target)), shape=(S, S)).tocsr()


def _sequence(cells, actions, k: int, n_actions: int):
    cells, actions = check_sequence(cells, actions, k, n_actions)
    return np.ascontiguousarray(cells), np.ascontiguousarray(actions)


def log_likelihood(T: Transitions, cells, actions) -> np.ndarray:
    """(n,) ``log p(c_t | c_{<t}, a_{<t})`` in nats (0 for the first, given, step)."""
    cells, actions = _sequence(cells, actions, T.n_cells, T.n_actions)
    alpha = np.empty((len(cells), T.n_clones))
    return _forward(T.blocks, T.ids(cells, actions), T.rest, T.targets, cells, actions,
                    T.n_clones, alpha)  # fmt: skip


def filtered(model: CloneHMM, cells, actions) -> np.ndarray:
    """(n, C) the filtered distribution over the clones of each step's cell (causal)."""
    T = model.T
    cells, actions = _sequence(cells, actions, T.n_cells, T.n_actions)
    alpha = np.empty((len(cells), T.n_clones))
    _forward(T.blocks, T.ids(cells, actions), T.rest, T.targets, cells, actions, T.n_clones, alpha)
    return alpha


def _viterbi_training(T, ids, cells, iters, history, stage, progress, path=None):
    """Viterbi training from ``T``: the most likely path, ``T`` from its counts, until the path's
    log-probability stops improving or ``iters``; returns the last ``T`` and its path (``path``
    if not even the first pass improves on -inf: iters = 0)."""
    n, C = len(cells), T.n_clones
    previous = -np.inf
    history[stage] = []
    for it in range(iters):
        with np.errstate(divide="ignore"):
            new_path, logp = _viterbi(np.log(T.blocks), ids, cells, C)
        ll = logp / (n - 1)
        if ll <= previous + 1e-12:
            break
        path, previous = new_path, ll
        history[stage].append(float(ll))
        if progress is not None:
            progress(stage, it, ll)
        counts = _path_counts(path, ids, C, len(T.keys))
        T = _normalise(T.keys, counts, T.n_cells, T.n_actions, 0.0)
    return T, path


def check_size(cells, actions, n_cells: int, n_clones: int, n_actions: int) -> None:
    """InputError if the blocks of this sequence's triples at ``n_clones`` clones (all clones,
    contexts included) would pass MAX_BLOCK_BYTES."""
    cells, actions = _sequence(cells, actions, n_cells, n_actions)
    n_blocks = len(np.unique(_triple_keys(cells, actions, n_cells, n_actions)))
    size = n_blocks * n_clones**2 * 8
    if size > MAX_BLOCK_BYTES:
        raise InputError(
            f"the map's transitions would take {size / 1024**3:.1f} GB ({n_blocks:,} blocks of "
            f"{n_clones} x {n_clones}); at most {MAX_BLOCK_BYTES / 1024**3:.0f} GB: fewer clones"
        )


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
    start: np.ndarray | None = None,
) -> CloneHMM:
    """Fit a cloned HMM to one training sequence: EM, then Viterbi training, the split by
    ``context`` ((n,) labels in [0, n_contexts), ``context.slow_context``) if more than one, and
    pruning (see the module docstring). ``progress(stage, iteration, loglik_per_step)`` after
    each iteration. ``start`` ((n,) clones in [0, n_clones)): EM starts from the transitions
    counted along that path (plus the pseudocount) instead of the random start."""
    if n_clones < 1:
        raise ValueError(f"the number of clones must be at least 1, got {n_clones}")
    cells, actions = _sequence(cells, actions, n_cells, n_actions)
    if n_contexts > 1:
        context = np.ascontiguousarray(context, dtype=np.int64)
        if context.shape != cells.shape or context.min() < 0 or context.max() >= n_contexts:
            raise ValueError(f"context must be {cells.shape} labels in [0, {n_contexts})")
    check_size(cells, actions, n_cells, n_clones * n_contexts, n_actions)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    K, A, C, n = n_cells, n_actions, n_clones, len(cells)
    keys, ids = np.unique(_triple_keys(cells, actions, K, A), return_inverse=True)
    ids = ids.astype(np.int64)
    if start is None:
        T = _random_start(rng, keys, K, C, A)
    else:
        start = np.asarray(start, dtype=np.int64)
        if start.shape != cells.shape or start.min() < 0 or start.max() >= C:
            raise ValueError(f"start must be {cells.shape} clones in [0, {C})")
        T = _normalise(keys, _path_counts(cells * C + start, ids, C, len(keys)), K, A, pseudocount)
    alpha = np.empty((n, C))
    history: dict[str, list[float]] = {"em": [], "viterbi": []}
    previous = -np.inf
    for it in range(em_iters):
        ll = _forward(T.blocks, ids, T.rest, T.targets, cells, actions, C, alpha)[1:].sum() / (
            n - 1
        )
        history["em"].append(float(ll))
        if progress is not None:
            progress("em", it, ll)
        if ll - previous < tol:
            break
        previous = ll
        counts = np.zeros_like(T.blocks)
        _backward_counts(T.blocks, ids, C, alpha, counts)
        T = _normalise(keys, counts, K, A, pseudocount)
    del alpha
    T_em = T
    T, path = _viterbi_training(T, ids, cells, viterbi_iters, history, "viterbi", progress)
    if n_contexts > 1:  # each clone becomes n_contexts clones, one per context, then Viterbi
        C = C * n_contexts
        path = cells * C + (path % n_clones) * n_contexts + context
        T = _normalise(keys, _path_counts(path, ids, C, len(keys)), K, A, pseudocount)
        T, path = _viterbi_training(T, ids, cells, SPLIT_VITERBI_ITERS, history, "split", progress,
                                    path)  # fmt: skip
    counts = _path_counts(path, ids, C, len(keys))
    active = np.zeros(K * C, dtype=bool)
    active[path] = True
    for cell in range(K):  # a cell never seen in training keeps one clone to be seen by
        if not active[cell * C : (cell + 1) * C].any():
            active[cell * C] = True
    T = _normalise(keys, counts, K, A, pseudocount, active)
    return CloneHMM(T, active, counts, history, T_em)
