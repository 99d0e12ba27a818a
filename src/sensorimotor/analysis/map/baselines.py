"""The map's baselines: what a map must beat to be worth more than its cells.

- **Prediction**: the 2nd- and 3rd-order (cell, action) models with back-off
  (``cells.ngram_bits``) beside the first-order Markov model of ``cells.baseline_bits``.
- **Localisation**: a class-balanced logistic read-out of the decayed history of cells
  (``context.decayed_history``, the feature the context split itself uses).
"""

from __future__ import annotations

import numpy as np

from sensorimotor.analysis.map.cells import ngram_bits
from sensorimotor.analysis.map.context import CONTEXT_TAU, decayed_history
from sensorimotor.sim.world import World
from sensorimotor.stats import balanced_accuracy

BASELINE_ORDERS = (2, 3)  # the (cell, action) models beside the first-order Markov model
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


def higher_orders(train, test, clusters: int) -> dict[str, float]:
    """Bits per step on the test split of the 2nd- and 3rd-order (cell, action) models with
    back-off (``cells.ngram_bits``): the baselines a map must beat beyond first-order Markov."""
    return {
        f"markov{n}": ngram_bits(train.cells, train.actions, test.cells, test.actions, clusters, n)
        for n in BASELINE_ORDERS
    }
