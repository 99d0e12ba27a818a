"""Item 2: does the CSCG recipe (more clones, longer EM, pseudocount) make the map localise?
Fits on the first N training steps of one representation; numbers on the whole test split."""

import os
import sys
import time

import numpy as np

from sensorimotor.analysis.analyze import representation_of
from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans
from sensorimotor.analysis.map.cells import Steps, action_bins
from sensorimotor.analysis.map.chmm import filtered, fit_chmm, log_likelihood
from sensorimotor.analysis.map.localisation import grid_index, localisation
from sensorimotor.sim.database import load_database

# DATA: the folder of {world}.npz (sensorimotor generate WORLD --steps 1000000 --seed 0);
# Z: the z_s cache of zprep.py. Both from the environment; run from the project root.
DATA = os.environ.get("DATA", "data")
Z = os.environ.get("Z", "z")

world, name, n = sys.argv[1], sys.argv[2], int(sys.argv[3])
variants = [v.split(":") for v in sys.argv[4:]]  # clones:em_iters:pseudocount
db = load_database(f"{DATA}/{world}.npz")


def z(split):
    return (
        representation_of("raw", db, split)
        if name == "raw"
        else np.load(f"{Z}/{name}__{split}.npy")
    )


km = fit_kmeans(z("train"), 20, 0)


def steps(split, m=None):
    part = db.take(split)
    P = np.asarray(part.poses, dtype=np.float64)
    M = np.asarray(part.motors, dtype=np.float64)
    c = assign_clusters(km, z(split))
    return Steps(c[:m], action_bins(M)[:m], M[:m], P[:m])


tr, te = steps("train", n), steps("test")


def mi(x, y):
    j = np.zeros((x.max() + 1, y.max() + 1))
    np.add.at(j, (x, y), 1)
    j /= j.sum()
    px, py = j.sum(1, keepdims=True), j.sum(0, keepdims=True)
    nz = j > 0
    return float((j[nz] * np.log2(j[nz] / (px @ py)[nz])).sum())


room = db.world.room_index(te.poses[:, 0], te.poses[:, 1])
ok = room >= 0
head = ((te.poses[:, 2] % (2 * np.pi)) / (2 * np.pi) * 8).astype(int) % 8
sq = grid_index(db.world, te.poses[:, :2])
print(
    f"{world} {name}, fit on {n} steps. cells: I(room) {mi(te.cells[ok], room[ok]):.3f}, I(square) {mi(te.cells, sq):.3f}, I(heading/8) {mi(te.cells, head):.3f} bits",
    flush=True,
)
for C, iters, pc in variants:
    C, iters, pc = int(C), int(iters), float(pc)
    t0 = time.time()
    m = fit_chmm(tr.cells, tr.actions, 20, C, 4, 0, iters, pseudocount=pc)
    bits = {
        k: -log_likelihood(T, te.cells, te.actions, C)[1:].mean() / np.log(2)
        for k, T in (("em", m.T_em), ("viterbi", m.T))
    }
    loc, _, _ = localisation(m, tr, te, db.world)
    s = te.cells * C + filtered(m, te.cells, te.actions).argmax(1)
    print(
        f"C={C} em<={iters} ({len(m.history['em'])} done) pc={pc}: active {m.active.sum()}, bits em {bits['em']:.3f} viterbi {bits['viterbi']:.3f}; "
        f"room acc map {loc['room_accuracy']['map']:.3f} cells {loc['room_accuracy']['cells']:.3f} chance {loc['room_accuracy']['chance']:.3f}; "
        f"balanced map {loc['balanced_room_accuracy']['map']:.3f} cells {loc['balanced_room_accuracy']['cells']:.3f}; "
        f"pos err map {loc['position_error']['map']:.2f} cells {loc['position_error']['cells']:.2f}; "
        f"state: I(room) {mi(s[ok], room[ok]):.3f} I(square) {mi(s, sq):.3f} I(heading/8) {mi(s, head):.3f} bits ({time.time() - t0:.0f} s)",
        flush=True,
    )
