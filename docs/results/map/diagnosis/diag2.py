"""How many bits per step knowing the room could add to next-cell prediction (the EM's incentive)."""

import os
import sys

import numpy as np

from sensorimotor.analysis.analyze import representation_of
from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans
from sensorimotor.analysis.map.cells import action_bins
from sensorimotor.sim.database import load_database

# DATA: the folder of {world}.npz (sensorimotor generate WORLD --steps 1000000 --seed 0);
# Z: the z_s cache of zprep.py. Both from the environment; run from the project root.
DATA = os.environ.get("DATA", "data")
Z = os.environ.get("Z", "z")

world, name = sys.argv[1], sys.argv[2]
db = load_database(f"{DATA}/{world}.npz")


def z(split):
    return (
        representation_of("raw", db, split)
        if name == "raw"
        else np.load(f"{Z}/{name}__{split}.npy")
    )


km = fit_kmeans(z("train"), 20, 0)


def seq(split):
    part = db.take(split)
    P = np.asarray(part.poses)
    return (
        assign_clusters(km, z(split)),
        action_bins(np.asarray(part.motors)),
        db.world.room_index(P[:, 0], P[:, 1]),
    )


def bits(ctx_tr, nxt_tr, ctx_te, nxt_te, n_ctx, beta=1.0):
    cnt = np.zeros((n_ctx, 20))
    np.add.at(cnt, (ctx_tr, nxt_tr), 1)
    uni = np.bincount(nxt_tr, minlength=20) / len(nxt_tr)
    p = (cnt + beta * uni) / (cnt.sum(1, keepdims=True) + beta)
    return float(-np.log2(p[ctx_te, nxt_te]).mean())


c, a, r = seq("train")
ct, at, rt = seq("test")
R = max(r.max(), rt.max()) + 2  # -1 -> R-1
r, rt = np.where(r < 0, R - 1, r), np.where(rt < 0, R - 1, rt)
base = bits(c[:-1] * 4 + a[:-1], c[1:], ct[:-1] * 4 + at[:-1], ct[1:], 80)
room = bits(
    (c[:-1] * 4 + a[:-1]) * R + r[:-1], c[1:], (ct[:-1] * 4 + at[:-1]) * R + rt[:-1], ct[1:], 80 * R
)
# an oracle of position: 10 x 10 grid square
part = db.take("train")
P = np.asarray(part.poses)
Pt = np.asarray(db.take("test").poses)
g = (np.clip(P[:, 1] // 5, 0, 9) * 10 + np.clip(P[:, 0] // 5, 0, 9)).astype(int)
gt = (np.clip(Pt[:, 1] // 5, 0, 9) * 10 + np.clip(Pt[:, 0] // 5, 0, 9)).astype(int)
grid = bits(
    (c[:-1] * 4 + a[:-1]) * 100 + g[:-1],
    c[1:],
    (ct[:-1] * 4 + at[:-1]) * 100 + gt[:-1],
    ct[1:],
    8000,
)
print(
    f"{world} {name}: test bits/step Markov (cell, action) {base:.3f}; + true room {room:.3f} (gain {base - room:.3f}); + true 10x10 square {grid:.3f} (gain {base - grid:.3f})"
)
