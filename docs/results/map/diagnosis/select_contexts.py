"""The number of slow contexts, chosen on the validation split (issue 36, item 3).

The split's N = 4 was first chosen on the *test* split of Rec-SM seeds 0 and 1 (``split.py``,
``split.log``). Here the same candidates are fitted on the training split and scored on the
validation split only; the test split is not read. The rule, written before this ran:

    among N in CANDIDATES whose validation bits/step are at most TOLERANCE above the plain
    map's (N = 1), the one with the largest validation balanced room accuracy over its cells
    (map - cells); a tie (within 0.005) goes to the smaller N.

As ``split.py`` did: the plain map (``chmm.fit_chmm``, EM then Viterbi, 20 cells x 20 clones),
its Viterbi path, each clone split by N slow contexts (``context.slow_context``, tau 400) and
counted along the split path, then ``SPLIT_VITERBI_ITERS`` Viterbi passes and pruning as
``fit_chmm`` does them. Arguments: WORLD RUN (``raw`` or a run folder's name under
docs/results/runs) SEED [N_TRAIN]; DATA (the folder of {world}.npz) from the environment.

    DATA=data PYTHONPATH=src python docs/results/map/diagnosis/select_contexts.py rooms1 raw 0
"""

import json
import math
import os
import sys
import time

import numpy as np

from sensorimotor.analysis.analyze import representation_of
from sensorimotor.analysis.clusters import N_CLUSTERS, fit_kmeans
from sensorimotor.analysis.map import chmm
from sensorimotor.analysis.map.cells import Steps
from sensorimotor.analysis.map.context import CONTEXT_TAU, slow_context
from sensorimotor.analysis.map.localisation import localisation
from sensorimotor.analysis.map.mapping import N_CLONES, split_steps
from sensorimotor.learn.evaluate import load_run
from sensorimotor.sim.database import load_database

CANDIDATES = (1, 2, 4, 6)  # 8 left out: one split pass costs 64 plain ones (94 s on 16,000 steps)
TOLERANCE = 0.01  # bits/step the split may cost on validation against the plain map
TIE = 0.005

world_name, name, seed = sys.argv[1], sys.argv[2], int(sys.argv[3])
n_train = int(sys.argv[4]) if len(sys.argv) > 4 else None
db = load_database(f"{os.environ.get('DATA', 'data')}/{world_name}.npz")
world = db.world
run = "raw" if name == "raw" else load_run(f"docs/results/runs/{name}")
t0 = time.time()
z_tr = representation_of(run, db, "train")
kmeans = fit_kmeans(z_tr, N_CLUSTERS, seed)
train = split_steps(db, kmeans, z_tr, "train")
if n_train is not None:
    train = Steps(*(np.asarray(a)[:n_train] for a in (train.cells, train.actions, train.motors,
                                                       train.poses)))  # fmt: skip
val = split_steps(db, kmeans, representation_of(run, db, "val"), "val")
K, C, A = N_CLUSTERS, N_CLONES, 4
plain = chmm.fit_chmm(train.cells, train.actions, K, C, A, seed)
with np.errstate(divide="ignore"):
    path, _ = chmm._viterbi(np.log(plain.T), train.cells, train.actions, C)
print(f"{name} {world_name} seed {seed}: plain map fitted, {time.time() - t0:.0f} s", flush=True)

rows = {}
for n in CANDIDATES:
    t = time.time()
    if n == 1:
        model = plain
    else:
        context = slow_context(train.cells, K, n, CONTEXT_TAU, seed)
        split = C * n
        p = train.cells * split + (path % C) * n + context
        shape = (A, K * split, K * split)
        T = chmm._normalise(chmm._path_counts(p, train.actions, shape), chmm.PSEUDOCOUNT)
        history = {"em": [], "viterbi": []}
        T, p = chmm._viterbi_training(
            T, train.cells, train.actions, split, chmm.SPLIT_VITERBI_ITERS, history, "split",
            None, p,
        )  # fmt: skip
        counts = chmm._path_counts(p, train.actions, T.shape)
        active = np.zeros(K * split, dtype=bool)
        active[p] = True
        T = chmm._normalise(counts, chmm.PSEUDOCOUNT, active)
        model = chmm.CloneHMM(T, split, active, counts, history, plain.T_em)
    bits = -chmm.log_likelihood(model.T, val.cells, val.actions, model.n_clones)[1:].mean()
    loc, _, _ = localisation(model, train, val, world)
    b = loc["balanced_room_accuracy"]
    rows[n] = {"bits": bits / math.log(2), "map": b["map"], "cells": b["cells"]}
    rows[n]["gain"] = rows[n]["map"] - rows[n]["cells"]
    print(f"N={n}: val bits/step {rows[n]['bits']:.4f}, balanced room accuracy map "
          f"{b['map']:.4f} cells {b['cells']:.4f} gain {rows[n]['gain']:+.4f} "
          f"({time.time() - t:.0f} s)", flush=True)  # fmt: skip

ok = [n for n in CANDIDATES if rows[n]["bits"] <= rows[1]["bits"] + TOLERANCE]
best = max(rows[n]["gain"] for n in ok)
chosen = min(n for n in ok if rows[n]["gain"] >= best - TIE)
print(json.dumps({"chosen": chosen, "rows": rows, "seconds": round(time.time() - t0)}))
