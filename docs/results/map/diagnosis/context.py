"""Item 5: a slow-context start. Each cell's clones start as the k-means clusters (C of them) of
the decayed history of cells (time constant TAU steps); the transitions are counted along that
path, then EM (ITERS iterations, 0 = none) and Viterbi training as ``chmm.fit_chmm``. Fits on
the first N training steps; numbers on the whole test split. Arguments: WORLD RUN N TAU:C:ITERS...
With PLAN=P in the environment, also the planner of ``planning.planning`` over P pairs, seeded as
``sensorimotor map`` seeds a run's (k-means and pairs by the run's seed, as the shipped maps)."""

import os
import sys
import time

import numpy as np

from sensorimotor.analysis.analyze import representation_of
from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans
from sensorimotor.analysis.map import chmm
from sensorimotor.analysis.map.cells import Steps, action_bins
from sensorimotor.analysis.map.localisation import localisation
from sensorimotor.analysis.map.planning import encoder_of, planning
from sensorimotor.learn.evaluate import load_run
from sensorimotor.sim.database import load_database

# DATA: the folder of {world}.npz (sensorimotor generate WORLD --steps 1000000 --seed 0);
# Z: the z_s cache of zprep.py. Both from the environment; run from the project root.
DATA = os.environ.get("DATA", "data")
Z = os.environ.get("Z", "z")
PLAN = int(os.environ.get("PLAN", "0"))
K = 20

world, name, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
SEED = int(name.rsplit("__s", 1)[1]) if "__s" in name else 0
db = load_database(f"{DATA}/{world}.npz")


def z(split):
    if name == "raw":
        return representation_of("raw", db, split)
    return np.load(f"{Z}/{name}__{split}.npy")


km = fit_kmeans(z("train"), K, SEED)


def steps(split, m=None):
    part = db.take(split)
    P = np.asarray(part.poses, dtype=np.float64)
    M = np.asarray(part.motors, dtype=np.float64)
    c = assign_clusters(km, z(split))
    return Steps(c[:m], action_bins(M)[:m], M[:m], P[:m])


def decayed(cells, tau):
    """(n, K) causal exponentially decayed histogram of the cells."""
    lam = 1 - 1 / tau
    h, cur = np.zeros((len(cells), K)), np.full(K, 1 / K)
    for t, c in enumerate(cells):
        cur *= lam
        cur[c] += 1 - lam
        h[t] = cur
    return h


def fit_from(T, cells, actions, C, iters, pc=chmm.PSEUDOCOUNT):
    """EM (``iters``) then Viterbi training and pruning from a given T (as ``fit_chmm``)."""
    n, alpha = len(cells), np.empty((len(cells), C))
    for _ in range(iters):
        counts = np.zeros_like(T)
        chmm._forward(T, cells, actions, C, alpha)
        chmm._backward_counts(T, cells, actions, C, alpha, counts)
        T = chmm._normalise(counts, pc)
    T_em, previous, path = T, -np.inf, None
    for _ in range(chmm.VITERBI_ITERS):
        with np.errstate(divide="ignore"):
            new, logp = chmm._viterbi(np.log(T), cells, actions, C)
        if logp / (n - 1) <= previous + 1e-12:
            break
        path, previous = new, logp / (n - 1)
        T = chmm._normalise(chmm._path_counts(path, actions, T.shape), 0.0)
    counts = chmm._path_counts(path, actions, T.shape)
    active = np.zeros(T.shape[1], bool)
    active[path] = True
    T = chmm._normalise(counts, pc, active)
    return chmm.CloneHMM(T, C, active, counts, {"em": [], "viterbi": []}, T_em)


tr, te = steps("train", n), steps("test")
for spec in sys.argv[4:]:
    tau, C, iters = float(spec.split(":")[0]), *map(int, spec.split(":")[1:])
    t0 = time.time()
    h = decayed(tr.cells, tau)
    context = assign_clusters(fit_kmeans(h, C, 0), h)
    T0 = chmm._path_counts(tr.cells * C + context, tr.actions, (4, K * C, K * C))
    m = fit_from(chmm._normalise(T0, chmm.PSEUDOCOUNT), tr.cells, tr.actions, C, iters)
    bits = -chmm.log_likelihood(m.T, te.cells, te.actions, C)[1:].mean() / np.log(2)
    loc, state_mean, occupancy = localisation(m, tr, te, db.world)
    plan = ""
    if PLAN:
        run = load_run(f"docs/results/runs/{name}") if name != "raw" else "raw"
        encoder = encoder_of(run, db.max_range)
        plans, _ = planning(db.world, db.layout, encoder, km, m, state_mean, occupancy, SEED, PLAN)
        plan = (
            f"; planning map {plans['success']['map']:.2f} random {plans['success']['random']:.2f}"
        )
    r, b = loc["room_accuracy"], loc["balanced_room_accuracy"]
    print(
        f"{world} {name} tau={tau} C={C} em={iters}: bits {bits:.3f}, active {m.active.sum()}; "
        f"room acc map {r['map']:.3f} cells {r['cells']:.3f} chance {r['chance']:.3f}; "
        f"balanced map {b['map']:.3f} cells {b['cells']:.3f}; "
        f"grid map {loc['grid_accuracy']['map']:.3f} cells {loc['grid_accuracy']['cells']:.3f}; "
        f"pos err map {loc['position_error']['map']:.2f} cells {loc['position_error']['cells']:.2f}"
        f"{plan} ({time.time() - t0:.0f} s)",
        flush=True,
    )
