"""Planner goal-state variants on VALIDATION pairs (planning seed + 1000): WORLD SEED."""

import os
import sys
import time

import numpy as np

import sensorimotor.analysis.map.planning as pl
from sensorimotor.analysis.map import mapping
from sensorimotor.analysis.map.chmm import filtered, fit_chmm
from sensorimotor.analysis.map.context import CONTEXT_TAU, N_CONTEXTS, slow_context
from sensorimotor.analysis.map.localisation import localisation
from sensorimotor.learn.evaluate import load_run
from sensorimotor.sim.database import load_database

DATA = os.environ.get("DATA", "data")  # as in context.py
Z = os.environ.get("Z", "z")
world, seed = sys.argv[1], int(sys.argv[2])
name = f"{world}__rec-sm__s{seed}"
db = load_database(f"{DATA}/{world}.npz")
run = load_run(f"docs/results/runs/{name}")
mapping.representation_of = lambda r, d, split="test": np.load(f"{Z}/{name}__{split}.npy")
tr, te, km = mapping.cell_steps(run, db, 20, seed)
ctx = slow_context(tr.cells, 20, N_CONTEXTS, CONTEXT_TAU, seed)
m = fit_chmm(tr.cells, tr.actions, 20, 20, 4, seed, context=ctx, n_contexts=N_CONTEXTS)
loc, state_mean, occ = localisation(m, tr, te, db.world)
# place-field density on a 1-unit grid
w = filtered(m, tr.cells, tr.actions)
C, S = m.n_clones, m.n_states
W, H = int(np.ceil(db.world.width)), int(np.ceil(db.world.height))
g = np.clip(tr.poses[:, 0].astype(int), 0, W - 1) * H + np.clip(
    tr.poses[:, 1].astype(int), 0, H - 1
)
field = np.zeros((S, W * H))
for i in range(C):
    np.add.at(field, (tr.cells * C + i, g), w[:, i])
del w
gx, gy = np.meshgrid(np.arange(W) + 0.5, np.arange(H) + 0.5, indexing="ij")
gx, gy = gx.ravel(), gy.ravel()
orig = pl.goal_states


def enriched(model, state_mean, occupancy, goal_xy):
    active = np.flatnonzero(model.active)
    cand = active[occupancy[active] >= np.median(occupancy[active])]
    near = np.hypot(gx - goal_xy[0], gy - goal_xy[1]) <= pl.GOAL_RADIUS
    ratio = field[cand][:, near].sum(axis=1) / occupancy[cand]
    return cand[ratio >= 0.5 * ratio.max()]


enc = pl.encoder_of(run, db.max_range)
for label, fn in (("mean", orig), ("enriched", enriched)):
    pl.goal_states = fn
    t0 = time.time()
    plans, _ = pl.planning(db.world, db.layout, enc, km, m, state_mean, occ, seed + 1000, 100)
    print(world, seed, label, plans["success"], f"{time.time() - t0:.0f} s", flush=True)
