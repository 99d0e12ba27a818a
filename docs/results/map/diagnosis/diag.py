"""Why the map does not localise: how much the cell sequence says about the room at all."""

import os
import sys
import time

import numpy as np
from sklearn.linear_model import LogisticRegression

from sensorimotor.analysis.analyze import representation_of
from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans
from sensorimotor.analysis.map.cells import action_bins
from sensorimotor.sim.database import load_database
from sensorimotor.stats import balanced_accuracy

# DATA: the folder of {world}.npz (sensorimotor generate WORLD --steps 1000000 --seed 0);
# Z: the z_s cache of zprep.py. Both from the environment; run from the project root.
DATA = os.environ.get("DATA", "data")
Z = os.environ.get("Z", "z")

world, name = sys.argv[1], sys.argv[2]
db = load_database(f"{DATA}/{world}.npz")


def z(split):
    if name == "raw":
        return representation_of("raw", db, split)
    return np.load(f"{Z}/{name}__{split}.npy")


ztr, zte = z("train"), z("test")
km = fit_kmeans(ztr, 20, 0)
out = {}
for split, zz in (("train", ztr), ("test", zte)):
    part = db.take(split)
    poses = np.asarray(part.poses)
    out[split] = (
        assign_clusters(km, zz),
        action_bins(np.asarray(part.motors)),
        db.world.room_index(poses[:, 0], poses[:, 1]),
        poses,
    )
c, a, r, P = out["train"]
ok = r >= 0
# dwell: mean run length in a room
ch = np.flatnonzero(np.diff(r) != 0)
print(
    f"{world} {name}: rooms freq",
    np.round(np.bincount(r[ok]) / ok.sum(), 3),
    "mean dwell",
    round(len(r) / (len(ch) + 1)),
    "steps",
)


def mi(x, y):
    j = np.zeros((x.max() + 1, y.max() + 1))
    np.add.at(j, (x, y), 1)
    j /= j.sum()
    px, py = j.sum(1, keepdims=True), j.sum(0, keepdims=True)
    nz = j > 0
    return float((j[nz] * np.log2(j[nz] / (px @ py)[nz])).sum())


Hr = -sum(p * np.log2(p) for p in np.bincount(r[ok]) / ok.sum() if p > 0)
print(f"H(room) {Hr:.3f} bits, I(room; cell) {mi(c[ok], r[ok]):.3f} bits")


# causal window histograms of cells (exponential decay, time constant W) -> room
def feats(cells, W):
    onehot = np.eye(20)[cells]
    if W == 1:
        return onehot
    lam = 1 - 1 / W
    f = np.empty_like(onehot)
    acc = np.zeros(20)
    for t in range(len(cells)):
        acc = lam * acc + onehot[t]
        f[t] = acc
    return f / f.sum(1, keepdims=True)


ct, at, rt, Pt = out["test"]
okt = rt >= 0
sub = np.arange(0, len(c), 8)
for W in (1, 10, 50, 200, 1000):
    t0 = time.time()
    Ftr, Fte = feats(c, W), feats(ct, W)
    clf = LogisticRegression(max_iter=300).fit(Ftr[sub][ok[sub]], r[sub][ok[sub]])
    g = clf.predict(Fte[okt])
    print(
        f"window {W:5d}: room acc {np.mean(g == rt[okt]):.3f} balanced {balanced_accuracy(rt[okt], g):.3f} ({time.time() - t0:.0f} s)",
        flush=True,
    )
