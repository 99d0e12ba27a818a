"""What any representation learnt from Square's readings and commands can tell of the position
(issue 32): the ceiling under the world's symmetry.

    python docs/results/memory/square_symmetry.py square_fresh1.npz

Square is its outer walls alone, so a quarter turn about its centre maps a trajectory onto
another that the sensors and the behaviour (which reads only the readings) make just as
likely. A representation of the readings and commands, from a memory that starts at the
split's start, can then hold the pose only up to those 4 turns. This probes the pose turned
into one quarter of the square (u >= |v| about the centre, the heading turned with it): the
most such a representation can hold, through the same probes as
``experiments.memory.probe_job``'s true-pose ceiling.
"""

from __future__ import annotations

import json
import sys

import numpy as np

from sensorimotor.analysis.probes import place_probes
from sensorimotor.experiments.memory import pose_features
from sensorimotor.sim.database import load_database


def canonical(poses: np.ndarray, size: float) -> np.ndarray:
    """(N, 3) each pose (x, y, heading) turned about the square's centre into u >= |v|."""
    u, v, h = poses[:, 0] - size / 2, poses[:, 1] - size / 2, poses[:, 2]
    best = np.full((len(poses), 3), np.nan)
    for _ in range(4):  # quarter turns: (u, v, h) -> (-v, u, h + pi / 2)
        u, v, h = -v, u, h + np.pi / 2
        inside = u >= np.abs(v)
        best[inside] = np.stack([u + size / 2, v + size / 2, h], axis=1)[inside]
    return best


def main(data: str) -> None:
    db = load_database(data)
    if db.world.width != db.world.height or len(db.world.walls):
        raise SystemExit(f"{data}: not a square of outer walls alone")
    fit, test = db.take("train"), db.take("test")
    size = float(db.world.width)
    z_fit, z = (pose_features(canonical(q.poses, size)) for q in (fit, test))
    print(json.dumps(place_probes(z_fit, fit.poses, z, test.poses, world_size=(size, size))))


if __name__ == "__main__":
    main(sys.argv[1])
