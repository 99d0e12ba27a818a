"""Motion statistics of a recorded behaviour: how it turns and how fast it goes, from the motor
commands alone (``sim.core.BEHAVIOURS``: the paper's random walk, the smooth motion, the lattice).

A step is the wall reflex when it stands still and turns by at least ``5 pi/6`` (the smallest
reflex turn of any behaviour: the lattice's ``pi - pi/6``; the paper's ``sim.core.reflex`` turns
by at least ``pi - pi/10``, and no free step turns by more than a few tenths); every other step is a free step, and the turning statistics are over
free steps and pairs of consecutive free steps (a reflex's half turn is not a turning rate).
"""

from __future__ import annotations

import math

import numpy as np

REFLEX_TURN = math.pi - math.pi / 6.0  # the smallest reflex turn of any behaviour (the lattice's)


def reflex_steps(motors: np.ndarray) -> np.ndarray:
    """(N,) bool: the rows whose command is the wall reflex (d = 0, r >= 5 pi/6 up to float32
    rounding)."""
    m = np.asarray(motors, dtype=np.float64)
    return (m[:, 0] == 0.0) & (m[:, 1] >= REFLEX_TURN - 1e-6)


def lag1_autocorrelation(values: np.ndarray, keep: np.ndarray) -> float:
    """The correlation of ``values[t]`` with ``values[t + 1]`` over the pairs where both rows
    are kept; NaN with fewer than 3 pairs or no spread."""
    v = np.asarray(values, dtype=np.float64)
    pair = keep[:-1] & keep[1:]
    a, b = v[:-1][pair], v[1:][pair]
    if len(a) < 3 or a.std() == 0 or b.std() == 0:
        return math.nan
    return float(np.corrcoef(a, b)[0, 1])


def motion_statistics(motors: np.ndarray) -> dict:
    """A recorded behaviour's motion: the share of reflex steps, the turning rate's lag-1
    autocorrelation, mean and sd, the speed's mean, min and max, over free steps (floats;
    NaN where no free step is)."""
    m = np.asarray(motors, dtype=np.float64)
    free = ~reflex_steps(m)
    d, r = m[free, 0], m[free, 1]
    some = len(d) > 0
    return {
        "steps": len(m),
        "reflex_share": float(1.0 - free.mean()) if len(m) else math.nan,
        "turn_lag1_autocorrelation": lag1_autocorrelation(m[:, 1], free),
        "turn_mean": float(r.mean()) if some else math.nan,
        "turn_sd": float(r.std()) if some else math.nan,
        "speed_mean": float(d.mean()) if some else math.nan,
        "speed_min": float(d.min()) if some else math.nan,
        "speed_max": float(d.max()) if some else math.nan,
    }
