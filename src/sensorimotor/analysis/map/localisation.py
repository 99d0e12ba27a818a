"""Where the map thinks the robot is: room, grid square and position from the filtered state.

The posterior over the map's states at step t (``chmm.filtered``, causal), each state labelled on
the training split by the posterior-weighted frequency of each room (or ``GRID`` x ``GRID``
square) and its mean position, gives the most probable room and the expected position; against
the cell alone (the same labels per cell) and chance (the most frequent room, the mean
position). Room accuracy is given plain and balanced (the mean over rooms of each room's recall).
"""

from __future__ import annotations

import numpy as np

from sensorimotor.analysis.map.cells import Steps
from sensorimotor.analysis.map.chmm import CloneHMM, filtered
from sensorimotor.sim.world import World
from sensorimotor.stats import balanced_accuracy

GRID = 10  # the position ground truth: a GRID x GRID partition of the world
PRIOR = 1e-3  # weight of a state's cell's labels added to the state's own (unvisited states)


def _label_table(weights: np.ndarray, cells: np.ndarray, labels: np.ndarray, n_labels: int, k: int):
    """(K C, L) posterior-weighted label counts of the states (``weights`` (n, C) over the
    clones of each step's cell; steps labelled -1 count for nothing)."""
    C = weights.shape[1]
    S = k * C
    ok = labels >= 0
    table = np.zeros(S * n_labels)
    for i in range(C):
        flat = (cells[ok] * C + i) * n_labels + labels[ok]
        table += np.bincount(flat, weights=weights[ok, i], minlength=S * n_labels)[: S * n_labels]
    return table.reshape(S, n_labels)


def _with_prior(state_table: np.ndarray, cell_table: np.ndarray, C: int) -> np.ndarray:
    """State label distributions, backed by their cell's (``PRIOR`` pseudo-steps of it)."""
    cell = cell_table / np.maximum(cell_table.sum(axis=1, keepdims=True), 1e-300)
    mixed = state_table + PRIOR * np.repeat(cell, C, axis=0)
    return mixed / np.maximum(mixed.sum(axis=1, keepdims=True), 1e-300)


def _predict(weights: np.ndarray, cells: np.ndarray, table: np.ndarray) -> np.ndarray:
    """(n, L) sum over clones of weight x the state's row of ``table`` (S, L)."""
    C = weights.shape[1]
    out = np.zeros((len(cells), table.shape[1]))
    for i in range(C):
        out += weights[:, i, None] * table[cells * C + i]
    return out


def grid_index(world: World, xy: np.ndarray, grid: int = GRID) -> np.ndarray:
    """(n,) index of each point's square in a ``grid x grid`` partition of the world."""
    gx = np.clip((xy[:, 0] / world.width * grid).astype(np.int64), 0, grid - 1)
    gy = np.clip((xy[:, 1] / world.height * grid).astype(np.int64), 0, grid - 1)
    return gy * grid + gx


def _accuracy(model, train: Steps, test: Steps, w_train, w_test, train_labels, test_labels, n):
    """Label accuracy on test steps with a label: map, cells alone, chance."""
    ones_tr = np.ones((len(train.cells), 1))
    cell_table = _label_table(ones_tr, train.cells, train_labels, n, model.n_cells)
    state_table = _label_table(w_train, train.cells, train_labels, n, model.n_cells)
    state_p = _with_prior(state_table, cell_table, model.n_clones)
    ok = test_labels >= 0
    truth = test_labels[ok]
    by_map = _predict(w_test, test.cells, state_p).argmax(axis=1)[ok]
    by_cell = cell_table.argmax(axis=1)[test.cells][ok]
    chance = int(np.argmax(np.bincount(train_labels[train_labels >= 0], minlength=n)))
    guesses = {"map": by_map, "cells": by_cell, "chance": np.full(len(truth), chance)}
    plain = {name: float((g == truth).mean()) for name, g in guesses.items()}
    return plain, {name: balanced_accuracy(truth, g) for name, g in guesses.items()}


def _mean_positions(weights: np.ndarray, cells: np.ndarray, xy: np.ndarray, S: int) -> tuple:
    """(S, 2) posterior-weighted mean position of each state and (S,) its total weight."""
    C = weights.shape[1]
    total = np.zeros(S)
    sums = np.zeros((S, 2))
    for i in range(C):
        states = cells * C + i
        total += np.bincount(states, weights=weights[:, i], minlength=S)[:S]
        for c in range(2):
            sums[:, c] += np.bincount(states, weights=weights[:, i] * xy[:, c], minlength=S)[:S]
    return sums, total


def localisation(model: CloneHMM, train: Steps, test: Steps, world: World) -> tuple:
    """Room and grid accuracy and mean position error (world units) on the test split, from the
    filtered map state, from the cell alone and by chance (see the module docstring); also each
    state's mean position (S, 2) and its posterior weight on the training split (S,)."""
    w_train = filtered(model, train.cells, train.actions)  # (n, C)
    w_test = filtered(model, test.cells, test.actions)
    xy_tr, xy_te = train.poses[:, :2], test.poses[:, :2]
    K, C, S = model.n_cells, model.n_clones, model.n_states
    out = {}
    if world.rooms:
        rooms_tr = world.room_index(xy_tr[:, 0], xy_tr[:, 1])
        rooms_te = world.room_index(xy_te[:, 0], xy_te[:, 1])
        out["room_accuracy"], out["balanced_room_accuracy"] = _accuracy(
            model, train, test, w_train, w_test, rooms_tr, rooms_te, len(world.rooms)
        )
    else:
        out["room_accuracy"] = {"map": None, "cells": None, "chance": None}
        out["balanced_room_accuracy"] = dict(out["room_accuracy"])
    out["grid_accuracy"], _ = _accuracy(
        model,
        train,
        test,
        w_train,
        w_test,
        grid_index(world, xy_tr),
        grid_index(world, xy_te),
        GRID * GRID,
    )
    cell_sums, cell_n = _mean_positions(np.ones((len(train.cells), 1)), train.cells, xy_tr, K)
    cell_mean = np.divide(
        cell_sums, cell_n[:, None], out=np.zeros((K, 2)), where=cell_n[:, None] > 0
    )
    cell_mean[cell_n == 0] = xy_tr.mean(axis=0)
    sums, n = _mean_positions(w_train, train.cells, xy_tr, S)
    state_mean = (sums + PRIOR * np.repeat(cell_mean, C, axis=0)) / (n + PRIOR)[:, None]
    guess = _predict(w_test, test.cells, state_mean)  # (n, 2) expected position
    out["position_error"] = {
        "map": float(np.hypot(*(guess - xy_te).T).mean()),
        "cells": float(np.hypot(*(cell_mean[test.cells] - xy_te).T).mean()),
        "chance": float(np.hypot(*(xy_tr.mean(axis=0) - xy_te).T).mean()),
    }
    return out, state_mean, n
