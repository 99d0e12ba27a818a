"""What any representation learnt from Square's readings and commands can tell of the position
(issue 32): the ceiling under the world's symmetry.

    python docs/results/memory/square_symmetry.py square_fresh1.npz

Square is its outer walls alone, so a rotation by a quarter turn about its centre, or a
mirror through it, maps a trajectory onto another that the sensors and the behaviour make
just as likely. A representation of the readings and commands can then hold the pose only up
to those 8 maps. This probes the pose brought into one eighth of the square (u >= v >= 0 about
the centre, the heading moved with it): the most such a representation can hold, through the
same probes as ``experiments.memory.probe_job``'s true-pose ceiling.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from sensorimotor.analysis.probes import place_probes
from sensorimotor.sim.database import load_database


def canonical(poses: np.ndarray, size: float) -> np.ndarray:
    """(N, 4): x, y, cos, sin of each pose mapped by the square's symmetry into u >= v >= 0."""
    u, v, h = poses[:, 0] - size / 2, poses[:, 1] - size / 2, poses[:, 2]
    best = np.full((len(poses), 3), np.nan)
    for mirror in (False, True):
        uu, vv, hh = (u, -v, -h) if mirror else (u, v, h)
        for _ in range(4):  # quarter turns: (u, v, h) -> (-v, u, h + pi / 2)
            uu, vv, hh = -vv, uu, hh + np.pi / 2
            inside = (uu >= vv) & (vv >= 0)
            best[inside] = np.stack([uu, vv, hh], axis=1)[inside]
    x, y, h = best[:, 0] + size / 2, best[:, 1] + size / 2, best[:, 2]
    return np.stack([x, y, np.cos(h), np.sin(h)], axis=1)


def main(data: str) -> None:
    db = load_database(data)
    if db.world.width != db.world.height or len(db.world.walls):
        raise SystemExit(f"{data}: not a square of outer walls alone")
    fit, test = db.take("train"), db.take("test")
    size = float(db.world.width)
    z_fit, z = canonical(fit.poses, size), canonical(test.poses, size)
    print(json.dumps(place_probes(z_fit, fit.poses, z, test.poses, world_size=(size, size))))


if __name__ == "__main__":
    main(sys.argv[1])
