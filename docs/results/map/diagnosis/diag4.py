"""Is it the read-out? A causal window (decay time 200 steps) of the filtered map-state posterior
(or of the cells) -> room, by logistic regression fitted on the training split."""

import os
import sys
import time

import numba
import numpy as np
from sklearn.linear_model import LogisticRegression

from sensorimotor.analysis.analyze import representation_of
from sensorimotor.analysis.clusters import assign_clusters, fit_kmeans
from sensorimotor.analysis.map.cells import action_bins
from sensorimotor.analysis.map.chmm import filtered, fit_chmm
from sensorimotor.sim.database import load_database
from sensorimotor.stats import balanced_accuracy

# DATA: the folder of {world}.npz (sensorimotor generate WORLD --steps 1000000 --seed 0);
# Z: the z_s cache of zprep.py. Both from the environment; run from the project root.
DATA = os.environ.get("DATA", "data")
Z = os.environ.get("Z", "z")

world, name, n, W = sys.argv[1], sys.argv[2], int(sys.argv[3]), int(sys.argv[4])
db = load_database(f"{DATA}/{world}.npz")


def z(split):
    return (
        representation_of("raw", db, split)
        if name == "raw"
        else np.load(f"{Z}/{name}__{split}.npy")
    )


km = fit_kmeans(z("train"), 20, 0)


def seq(split, m=None):
    part = db.take(split)
    P = np.asarray(part.poses)
    return (
        assign_clusters(km, z(split))[:m],
        action_bins(np.asarray(part.motors))[:m],
        db.world.room_index(P[:m, 0], P[:m, 1]),
    )


c, a, r = seq("train", n)
ct, at, rt = seq("test")
C = 20
m = fit_chmm(c, a, 20, C, 4, 0, 100)


@numba.njit(cache=True)
def decay(cells, post, C, S, lam, every):
    out = np.zeros((len(cells) // every + 1, S))
    acc = np.zeros(S)
    k = 0
    for t in range(len(cells)):
        acc *= lam
        for i in range(C):
            acc[cells[t] * C + i] += post[t, i]
        if t % every == 0:
            out[k] = acc / acc.sum()
            k += 1
    return out


lam = 1 - 1 / W
every = 4
for label, (tr_post, te_post, CC) in {
    "cells": (np.ones((len(c), 1)), np.ones((len(ct), 1)), 1),
    "map states": (filtered(m, c, a), filtered(m, ct, at), C),
}.items():
    t0 = time.time()
    Ftr = decay(c, tr_post, CC, 20 * CC, lam, every)
    Fte = decay(ct, te_post, CC, 20 * CC, 1 - 1 / W, 1)
    y = r[::every]
    Ftr = Ftr[: len(y)]
    ok = y >= 0
    clf = LogisticRegression(max_iter=300).fit(Ftr[ok], y[ok])
    okt = rt >= 0
    g = clf.predict(Fte[: len(rt)][okt])
    print(
        f"{world} {name} fit {n}: window {W} of {label}: room acc {np.mean(g == rt[okt]):.3f} balanced {balanced_accuracy(rt[okt], g):.3f} ({time.time() - t0:.0f} s)",
        flush=True,
    )
    # single step (no window) for comparison
    Ftr1 = decay(c, tr_post, CC, 20 * CC, 0.0, every)
    Fte1 = decay(ct, te_post, CC, 20 * CC, 0.0, 1)
    clf = LogisticRegression(max_iter=300).fit(Ftr1[: len(y)][ok], y[ok])
    g = clf.predict(Fte1[: len(rt)][okt])
    print(
        f"{world} {name} fit {n}: one step of {label}: room acc {np.mean(g == rt[okt]):.3f} balanced {balanced_accuracy(rt[okt], g):.3f}",
        flush=True,
    )
