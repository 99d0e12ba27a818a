"""The context split, before it was in ``chmm.fit_chmm``: the plain map's clones (C1, EM then
Viterbi) times K2 slow contexts (k-means of the decayed history of cells, time constant TAU),
counted along the split path, then VIT Viterbi passes (0: the counts alone). Fits on the first
N training steps; numbers on the whole test split. Arguments: WORLD RUN N C1 K2 TAU [EM] [VIT].
With PLAN=P in the environment, also the planner over P pairs. DATA and Z as in context.py."""

import os
import sys
import time

import numpy as np

from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans
from sensorimotor.analysis.map import chmm, mapping
from sensorimotor.analysis.map.cells import Steps, baseline_bits
from sensorimotor.analysis.map.context import decayed_history
from sensorimotor.analysis.map.localisation import localisation
from sensorimotor.analysis.map.planning import encoder_of, planning
from sensorimotor.learn.evaluate import load_run
from sensorimotor.sim.database import load_database

DATA = os.environ.get("DATA", "data")
Z = os.environ.get("Z", "z")
PLAN = int(os.environ.get("PLAN", "0"))
K = 20
world, name, n, C1, K2, tau = (
    sys.argv[1],
    sys.argv[2],
    int(sys.argv[3]),
    int(sys.argv[4]),
    int(sys.argv[5]),
    float(sys.argv[6]),
)
EM = int(sys.argv[7]) if len(sys.argv) > 7 else 100
VIT = int(sys.argv[8]) if len(sys.argv) > 8 else 20
SEED = int(name.rsplit("__s", 1)[1])
db = load_database(f"{DATA}/{world}.npz")


# the map's own cells and context (``mapping.cell_steps``, ``context.decayed_history``), with
# z_s read from the cache instead of recomputed
mapping.representation_of = lambda run, db, split="test": np.load(f"{Z}/{name}__{split}.npy")
train, te, km = mapping.cell_steps(load_run(f"docs/results/runs/{name}"), db, K, SEED)
tr = Steps(*(np.asarray(a)[:n] for a in (train.cells, train.actions, train.motors, train.poses)))


t0 = time.time()
m1 = chmm.fit_chmm(tr.cells, tr.actions, K, C1, 4, SEED, em_iters=EM)
with np.errstate(divide="ignore"):
    p1, _ = chmm._viterbi(np.log(m1.T), tr.cells, tr.actions, C1)
t1 = time.time()
b = baseline_bits(tr.cells, tr.actions, te.cells, te.actions, K)
bits1 = -chmm.log_likelihood(m1.T, te.cells, te.actions, C1)[1:].mean() / np.log(2)
h = decayed_history(tr.cells, K, tau)
ctx = assign_clusters(fit_kmeans(h, K2, 0), h)
C = C1 * K2
prod = tr.cells * C + (p1 % C1) * K2 + ctx
shape = (4, K * C, K * C)
T0 = chmm._normalise(chmm._path_counts(prod, tr.actions, shape), chmm.PSEUDOCOUNT)
path = chmm._viterbi_training(T0, tr.cells, tr.actions, C, VIT, {}, "split", None, prod)[1]
counts = chmm._path_counts(path, tr.actions, shape)
active = np.zeros(K * C, bool)
active[path] = True
T = chmm._normalise(counts, chmm.PSEUDOCOUNT, active)
m = chmm.CloneHMM(T, C, active, counts, {"em": [], "viterbi": []}, T)
bits = -chmm.log_likelihood(m.T, te.cells, te.actions, C)[1:].mean() / np.log(2)
loc, state_mean, occupancy = localisation(m, tr, te, db.world)
loc1, sm1, oc1 = localisation(m1, tr, te, db.world)
plan = ""
if PLAN:
    enc = encoder_of(load_run(f"docs/results/runs/{name}"), db.max_range)
    plans, _ = planning(db.world, db.layout, enc, km, m, state_mean, occupancy, SEED, PLAN)
    plan = f"; plan map {plans['success']['map']:.2f} random {plans['success']['random']:.2f}"
r = loc["balanced_room_accuracy"]
r1 = loc1["balanced_room_accuracy"]
print(
    f"{world} {name} C1={C1} K2={K2} tau={tau} em={EM} vit={VIT}: bits markov {b['markov']:.3f} em-map {bits1:.3f} product {bits:.3f} active {active.sum()}; "
    f"balanced product {r['map']:.3f} em-map {r1['map']:.3f} cells {r['cells']:.3f}; pos err {loc['position_error']['map']:.2f} vs {loc1['position_error']['map']:.2f}; grid {loc['grid_accuracy']['map']:.3f} {loc1['grid_accuracy']['map']:.3f}{plan} (em {t1 - t0:.0f} s, all {time.time() - t0:.0f} s)",
    flush=True,
)
