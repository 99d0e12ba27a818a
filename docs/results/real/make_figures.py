"""The figures of docs/results/real/README.md: the real robot's path and its scans, and the
campus world with a simulated trajectory (drawn by ``sim.figures``, as ``reproduce --experiment
real`` draws them).

    PYTHONPATH=src python docs/results/real/make_figures.py SENA.rawlog SENA.npz CAMPUS.toml CAMPUS.npz OUT_DIR
"""

from __future__ import annotations

import sys
from pathlib import Path

from sensorimotor.sim.database import load_database
from sensorimotor.sim.figures import campus_figure, real_path_figure
from sensorimotor.sim.plots import save_figure
from sensorimotor.sim.world import load_world

if __name__ == "__main__":
    log, db, world, sim, out = map(Path, sys.argv[1:6])
    save_figure(real_path_figure(log, load_database(db)), out / "sena_path_scans.png", dpi=110)
    save_figure(
        campus_figure(load_world(world), load_database(sim)), out / "campus_trajectory.png", dpi=110
    )
