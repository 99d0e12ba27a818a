"""The figures of docs/results/real/README.md: the real robot's path and its scans, and the
campus world with a simulated trajectory.

    PYTHONPATH=src python docs/results/real/make_figures.py SENA.rawlog SENA.npz CAMPUS.toml CAMPUS.npz OUT_DIR
"""

from __future__ import annotations

import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from matplotlib.collections import LineCollection

from sensorimotor.sim.database import load_database
from sensorimotor.sim.mrpt import Scan, compose, read_rawlog
from sensorimotor.sim.world import load_world


def real_path(log: Path, db_path: Path, out: Path) -> None:
    """Left: every beam's end point (valid, under 20 m) of every 5th scan drawn from the
    odometry pose, and the path; right: the five kept rays' readings along the recording."""
    entries, _ = read_rawlog(log)
    db = load_database(db_path)
    odo, points = (0.0, 0.0, 0.0), []
    for entry in entries:
        for item in entry:
            if isinstance(item, Scan):
                x, y, yaw = compose(odo, item.sensor)
                n = len(item.ranges)
                a = -item.aperture / 2 + np.arange(n) * item.aperture / (n - 1)
                ok = item.valid & (item.ranges < 20)
                r = item.ranges[ok]
                points.append(
                    np.stack([x + r * np.cos(yaw + a[ok]), y + r * np.sin(yaw + a[ok])], 1)
                )
            else:
                odo = compose(odo, item.pose)
    pts = np.concatenate(points[::5])
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(13, 5.5), gridspec_kw={"width_ratios": [1, 1.3]})
    ax.scatter(pts[:, 0], pts[:, 1], s=0.3, c="0.55", lw=0, label="laser end points (every 5th scan)")
    ax.plot(db.poses[:, 0], db.poses[:, 1], "C0-", lw=1.5, label="odometry path (laser)")
    ax.plot(*db.poses[0, :2], "go", label="start")
    ax.plot(*db.poses[-1, :2], "rs", label="end")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, odometry frame)")
    ax.set_ylabel("y (m)")
    ax.set_title("SENA, Telecom faculty, one loop: 225 scans")
    ax.legend(loc="upper left", fontsize=7)
    im = bx.imshow(db.sensors.T, aspect="auto", cmap="viridis", interpolation="nearest")
    bx.set_yticks(range(5), ["-0.6", "-0.3", "0", "0.3", "0.6"])
    bx.set_ylabel("ray (rad)")
    bx.set_xlabel("row (4.3 Hz)")
    bx.set_title("the five kept rays' readings (m, capped at 10)")
    fig.colorbar(im, ax=bx, fraction=0.04)
    fig.tight_layout()
    fig.savefig(out, dpi=110)


def campus(world_path: Path, db_path: Path, out: Path, steps: int = 100_000) -> None:
    world = load_world(world_path)
    db = load_database(db_path)
    fig, ax = plt.subplots(figsize=(7, 10))
    w = np.asarray(world.walls)
    ax.add_collection(LineCollection(w.reshape(-1, 2, 2), colors="k", linewidths=0.4))
    ax.plot(db.poses[:steps, 0], db.poses[:steps, 1], "C0-", lw=0.15, alpha=0.7)
    ax.set_xlim(0, world.width)
    ax.set_ylim(0, world.height)
    ax.set_aspect("equal")
    ax.set_title(f"{world.name}: {len(w):,} walls, {steps:,} simulated steps (seed 0)")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    fig.tight_layout()
    fig.savefig(out, dpi=110)


if __name__ == "__main__":
    log, db, world, sim, out = map(Path, sys.argv[1:6])
    real_path(log, db, out / "sena_path_scans.png")
    campus(world, sim, out / "campus_trajectory.png")
