"""A confirmatory planning test on FRESH pairs, its rule written before it ran:
the stage's map (refitted exactly as `sensorimotor map` fits it, seed s), the stage's planner,
300 start/goal pairs seeded by s + 2000 (the shipped maps used s; the planner variants of
goals.py used s + 1000). The claim "the planner beats the random behaviour" holds on a world
if map_stage.verdict over the 5 seeds, with trials = 300, says it holds. Arguments: WORLD."""

import json
import os
import sys
import time

import numpy as np

from sensorimotor.analysis.map import mapping
from sensorimotor.analysis.map.chmm import fit_chmm, log_likelihood
from sensorimotor.analysis.map.context import CONTEXT_TAU, N_CONTEXTS, slow_context
from sensorimotor.analysis.map.localisation import localisation
from sensorimotor.analysis.map.planning import encoder_of, planning
from sensorimotor.learn.evaluate import load_run
from sensorimotor.sim.database import load_database

DATA = os.environ.get("DATA", "data")  # as in context.py
Z = os.environ.get("Z", "z")
world = sys.argv[1]
db = load_database(f"{DATA}/{world}.npz")
for seed in range(5):
    t0 = time.time()
    name = f"{world}__rec-sm__s{seed}"
    run = load_run(f"docs/results/runs/{name}")
    mapping.representation_of = lambda r, d, split="test", name=name: np.load(
        f"{Z}/{name}__{split}.npy"
    )
    tr, te, km = mapping.cell_steps(run, db, 20, seed)
    ctx = slow_context(tr.cells, 20, N_CONTEXTS, CONTEXT_TAU, seed)
    m = fit_chmm(tr.cells, tr.actions, 20, 20, 4, seed, context=ctx, n_contexts=N_CONTEXTS)
    bits = -log_likelihood(m.T, te.cells, te.actions, m.n_clones)[1:].mean() / np.log(2)
    loc, state_mean, occ = localisation(m, tr, te, db.world)
    plans, _ = planning(
        db.world, db.layout, encoder_of(run, db.max_range), km, m, state_mean, occ, seed + 2000, 300
    )
    print(
        json.dumps(
            {
                "world": world,
                "seed": seed,
                "bits_map": bits,
                "success": plans["success"],
                "pairs": 300,
                "seconds": round(time.time() - t0),
            }
        ),
        flush=True,
    )
