"""The map's baselines: what a map must beat to be worth more than its cells.

- **Prediction**: the 2nd- and 3rd-order (cell, action) models with back-off
  (``cells.ngram_bits``: each order's counts smoothed towards the order below by ``beta``
  pseudo-steps, a Dirichlet back-off; an unseen history leaves the order below as it is),
  ``beta`` chosen among ``BETAS`` on the validation split, beside the first-order Markov model
  of ``cells.baseline_bits`` (beta 1, set before the data); and a small recurrent net
  (``rnn_bits``: a GRU over (cell, action) pairs predicting the next cell, trained on windows
  of the training split, its best weights chosen on the validation split); and the plain HMM
  with as many states as the map (``hmm``: every state emits every cell, EM on the first
  ``hmm.HMM_STEPS`` training steps, its iteration chosen on the validation split).
- **Localisation**: a class-balanced logistic read-out of the decayed history of cells
  (``context.decayed_history``, the feature the context split itself uses).
"""

from __future__ import annotations

import math

import numpy as np

from sensorimotor.analysis.map.cells import ngram_bits
from sensorimotor.analysis.map.context import CONTEXT_TAU, decayed_history
from sensorimotor.analysis.map.hmm import plain_hmm_bits
from sensorimotor.sim.world import World
from sensorimotor.stats import balanced_accuracy

BASELINE_ORDERS = (2, 3)  # the (cell, action) models beside the first-order Markov model
BETAS = (0.1, 0.3, 1.0, 3.0, 10.0, 30.0)  # back-off pseudo-steps, chosen on validation
RNN_EMBED = 16  # the (cell, action) pair's embedding
RNN_HIDDEN = 64  # GRU units
RNN_LENGTH = 100  # steps per training window, and the context before each test block
RNN_BATCH = 32
RNN_UPDATES = 1_500  # Adam steps at most (about a minute on one CPU thread) ...
RNN_PASSES = 10  # ... and at most this many passes over the training split's steps
RNN_LR = 3e-3
RNN_CHECKS = 5  # validation checks over training: the best weights are kept
RNN_VAL_STEPS = 20_000  # at most this many validation steps per check
READOUT_STEPS = 20_000  # training steps the history read-out is fitted on (evenly spaced)


def history_readout(train, test, world: World, clusters: int) -> float | None:
    """Balanced room accuracy on the test split of a class-balanced logistic regression on the
    decayed history of cells (``context.decayed_history``, the split's own feature), fitted on
    at most ``READOUT_STEPS`` training steps: the baseline the map's localisation must beat.
    None in a world without named rooms."""
    from sklearn.linear_model import LogisticRegression

    if not world.rooms:
        return None
    rooms_tr = world.room_index(train.poses[:, 0], train.poses[:, 1])
    rooms_te = world.room_index(test.poses[:, 0], test.poses[:, 1])
    if len(np.unique(rooms_tr)) < 2:
        return None
    x_tr = decayed_history(train.cells, clusters, CONTEXT_TAU)
    x_te = decayed_history(test.cells, clusters, CONTEXT_TAU)
    every = max(1, len(x_tr) // READOUT_STEPS)
    probe = LogisticRegression(class_weight="balanced", max_iter=1000)  # balanced: prior-free
    probe.fit(x_tr[::every], rooms_tr[::every])
    return balanced_accuracy(rooms_te, probe.predict(x_te))


def higher_orders(train, val, test, clusters: int) -> tuple[dict, dict]:
    """Bits per step on the test split of the 2nd- and 3rd-order (cell, action) models with
    back-off (``cells.ngram_bits``), each with the ``beta`` of ``BETAS`` that predicts the
    validation split best; and those betas."""
    bits, betas = {}, {}
    for n in BASELINE_ORDERS:
        on_val = [
            ngram_bits(train.cells, train.actions, val.cells, val.actions, clusters, n, beta=b)
            for b in BETAS
        ]
        betas[f"markov{n}"] = BETAS[int(np.argmin(on_val))]
        bits[f"markov{n}"] = ngram_bits(
            train.cells, train.actions, test.cells, test.actions, clusters, n,
            beta=betas[f"markov{n}"],
        )  # fmt: skip
    return bits, betas


def _net(k: int, n_actions: int):
    import torch

    class Net(torch.nn.Module):
        def __init__(self):
            super().__init__()
            self.embed = torch.nn.Embedding(k * n_actions, RNN_EMBED)
            self.gru = torch.nn.GRU(RNN_EMBED, RNN_HIDDEN, batch_first=True)
            self.out = torch.nn.Linear(RNN_HIDDEN, k)

        def forward(self, tokens):  # (B, L) -> (B, L, k) logits of the next cell
            return self.out(self.gru(self.embed(tokens))[0])

    return Net()


def _tokens(steps, k: int) -> tuple[np.ndarray, np.ndarray]:
    """(n - 1,) the (cell, action) pair of each step and (n - 1,) the next cell."""
    return steps.actions[:-1] * k + steps.cells[:-1], steps.cells[1:]


def _rnn_eval(net, steps, k: int, limit: int | None = None) -> float:
    """Bits per step of ``net`` on a split: blocks of ``RNN_LENGTH`` predictions, each after the
    ``RNN_LENGTH`` steps before it (none before the split's start)."""
    import torch

    tokens, targets = _tokens(steps, k)
    if limit is not None:
        tokens, targets = tokens[:limit], targets[:limit]
    nats = 0.0
    with torch.no_grad():
        for b in range(0, len(tokens), RNN_LENGTH):
            a = max(0, b - RNN_LENGTH)
            x = torch.from_numpy(tokens[a : b + RNN_LENGTH])[None]
            logp = torch.log_softmax(net(x)[0, b - a :].double(), dim=1)
            y = torch.from_numpy(targets[b : b + RNN_LENGTH])
            nats -= float(logp[torch.arange(len(y)), y].sum())
    return nats / len(tokens) / math.log(2)


def rnn_bits(train, val, test, clusters: int, seed: int = 0, updates: int | None = None) -> float:
    """Bits per step on the test split of a GRU over (cell, action) pairs predicting the next
    cell (module docstring): Adam on random windows of the training split (``updates`` steps:
    by default RNN_UPDATES, fewer for a short split), one thread, seeded; the weights of the
    validation check with the fewest bits are scored."""
    import torch

    from sensorimotor.analysis.map.cells import N_ACTIONS

    tokens, targets = _tokens(train, clusters)
    if updates is None:
        updates = min(RNN_UPDATES, math.ceil(RNN_PASSES * len(tokens) / (RNN_BATCH * RNN_LENGTH)))
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    try:
        with torch.random.fork_rng():
            torch.manual_seed(seed)
            net = _net(clusters, N_ACTIONS)
            opt = torch.optim.Adam(net.parameters(), lr=RNN_LR)
            rng = np.random.default_rng(seed)
            length = min(RNN_LENGTH, len(tokens))
            best, best_state = math.inf, None
            checks = {round(updates * (i + 1) / RNN_CHECKS) for i in range(RNN_CHECKS)}
            for step in range(1, updates + 1):
                at = rng.integers(0, len(tokens) - length + 1, RNN_BATCH)[:, None]
                at = at + np.arange(length)
                logits = net(torch.from_numpy(tokens[at]))
                loss = torch.nn.functional.cross_entropy(
                    logits.reshape(-1, clusters), torch.from_numpy(targets[at]).reshape(-1)
                )
                opt.zero_grad()
                loss.backward()
                opt.step()
                if step in checks:
                    on_val = _rnn_eval(net, val, clusters, RNN_VAL_STEPS)
                    if on_val < best:
                        best = on_val
                        best_state = {n: v.clone() for n, v in net.state_dict().items()}
            if best_state is not None:
                net.load_state_dict(best_state)
            return _rnn_eval(net, test, clusters)
    finally:
        torch.set_num_threads(threads)


def baselines(train, val, test, world: World, clusters: int, states: int, seed: int = 0) -> dict:
    """The map's baselines as ``map.json`` records them (module docstring); ``states``: the
    map's, which the plain HMM gets as many of."""
    bits, betas = higher_orders(train, val, test, clusters)
    bits["rnn"] = rnn_bits(train, val, test, clusters, seed)
    hmm = plain_hmm_bits(train, val, test, clusters, states, seed)
    bits["hmm"] = hmm.pop("bits")
    return {
        "bits_per_step": bits,
        "backoff_beta": betas,
        "plain_hmm": hmm,
        "localisation": {"history_readout": history_readout(train, test, world, clusters)},
    }
