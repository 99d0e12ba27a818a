"""What each dimension of a pilot's z_s holds: linear read-outs of it from the place, the
heading, the readings now, the readings averaged over the last tau steps, and all of these.

    PYTHONPATH=src python docs/results/memory/slow_features.py FRESH.npz WEIGHTS.pt [WEIGHTS.pt ...]

``heading_pilot.py --save`` writes the weights (a Rec-SMA whose memory reads the readings and
the last command, ``--heading none``). Every dimension of z_s is regressed (least squares with an
intercept, fitted on ``FRESH``'s training split after a 200-step burn-in, scored as R^2 on its
test split) on each set of candidates in turn. A slowness prior can make a recurrent feature
slow without the place by averaging the readings over a long window: the last columns say how
much of each dimension such averages explain. First, the slowness of the candidates themselves.
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import torch
from pose_supervised import memory_z
from rich.console import Console
from rich.table import Table
from scipy.signal import lfilter

from sensorimotor.learn.models import REC_SMA, ModelConfig, build_model
from sensorimotor.learn.slowness import slowness
from sensorimotor.sim.database import load_database, scale_sensors

BURN_IN = 200
TAUS = (30, 300, 3000)  # steps: the averaging windows (a room holds the robot ~330 steps)


def averaged(x: np.ndarray, tau: int) -> np.ndarray:
    """Exponential moving average of every column of x (n, d) with time constant ``tau``."""
    a = 1.0 / tau
    return lfilter([a], [1.0, a - 1.0], x.astype(np.float64), axis=0)


def candidates(part, max_range: float, world) -> dict[str, np.ndarray]:
    """The candidate explanations of a step's features, (n, d) each: the place (x, y scaled,
    the room one-hot), the heading (cos, sin), the readings now and averaged ("avg TAU")."""
    s = scale_sensors(part.sensors, max_range)
    x, y, h = (part.poses[:, i].astype(np.float64) for i in range(3))
    rooms = world.room_index(x, y)
    one_hot = np.stack([rooms == r for r in range(int(rooms.max()) + 1)], 1).astype(float)
    sets = {
        "place": np.column_stack([x / world.width, y / world.height, one_hot]),
        "heading": np.column_stack([np.cos(h), np.sin(h)]),
        "now": s.astype(np.float64),
    }
    for tau in TAUS:
        sets[f"avg {tau}"] = averaged(s, tau)
    sets["all"] = np.hstack(list(sets.values()))
    return sets


def window_slowness(x: np.ndarray, window: int = 256) -> float:
    """``heading_pilot.slowness`` without a floor of x (n, 1) cut into windows: a constant
    window (a room's indicator while the robot stays in it) counts as still."""
    n = len(x) // window
    z = torch.from_numpy(np.asarray(x[: n * window], dtype=np.float64)).reshape(n, window, 1)
    return float(slowness(z, 1e-12))


def r2_of(fit_x, fit_y, test_x, test_y) -> np.ndarray:
    """R^2 on the test rows of a least-squares fit with an intercept, per column of y."""
    ones = np.ones((len(fit_x), 1))
    coef, *_ = np.linalg.lstsq(np.hstack([fit_x, ones]), fit_y, rcond=None)
    pred = np.hstack([test_x, np.ones((len(test_x), 1))]) @ coef
    return 1 - ((test_y - pred) ** 2).sum(0) / ((test_y - test_y.mean(0)) ** 2).sum(0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("fresh")
    ap.add_argument("weights", nargs="+")
    args = ap.parse_args()
    torch.set_num_threads(1)
    db = load_database(args.fresh)
    fit, test = db.take("train"), db.take("test")
    cand_fit, cand_test = (candidates(p, db.max_range, db.world) for p in (fit, test))
    console = Console()
    table = Table(title="slowness of the data themselves (fresh test split, 256-step windows)")
    for col in ("candidate", "column", "slowness"):
        table.add_column(col, justify="right" if col == "slowness" else "left")
    for name in ("place", "heading", "now", "avg 30"):
        cols = cand_test[name]
        for c in range(cols.shape[1]):
            table.add_row(name, str(c), f"{window_slowness(cols[:, c : c + 1]):.5f}")
    console.print(table)
    for path in args.weights:
        model = build_model(ModelConfig(kind=REC_SMA))
        model.load_state_dict(torch.load(path, weights_only=True))
        z_fit, z_test = (memory_z(model, p, db.max_range, "none") for p in (fit, test))
        table = Table(title=f"{path}: R^2 of each z_s dimension (fresh test split)")
        table.add_column("dim")
        table.add_column("slowness", justify="right")
        for name in cand_fit:
            table.add_column(name, justify="right")
        scores = {
            name: r2_of(
                cand_fit[name][BURN_IN:],
                z_fit[BURN_IN:],
                cand_test[name][BURN_IN:],
                z_test[BURN_IN:],
            )
            for name in cand_fit
        }
        for d in range(z_test.shape[1]):
            slow = window_slowness(z_test[:, d : d + 1])
            table.add_row(str(d), f"{slow:.4f}", *(f"{scores[n][d]:.2f}" for n in cand_fit))
        console.print(table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
