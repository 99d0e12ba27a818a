"""``sensorimotor map``: from cells to a map, and what the map knows that the cells do not.

The representation (``raw`` or a run folder's z_s, ``analyze.representation_of``) of the
training split becomes cells (k-means, ``clusters.fit_kmeans``; with ``fit_data`` the k-means is
fitted on that database's training split: transfer) and the motor commands become actions
(``cells.action_bins``). On the training split: the cell graph (``cells.cell_graph``) and the
cloned HMM (``chmm.fit_chmm``), each clone split by the slow context (``context.slow_context``,
``contexts`` of them; 1: the plain cloned HMM). On the test split:

- **bits per step** of next-cell prediction: unigram, first-order (cell, action) Markov, the
  cell graph, the map (after Viterbi training, the split and pruning) and the map after EM
  alone (before the split);
- **localisation** from the filtered (causal) map state: the posterior over the map's states
  at step t, each state labelled on the training split by the posterior-weighted frequency of
  each room (or 10 x 10 grid square) and its mean position, gives the most probable room and
  the expected position; against the cell alone (the same labels per cell) and chance (the
  most frequent room, the mean position). Room accuracy is given plain and balanced (the mean
  over rooms of each room's recall: chance is 1 / rooms, so a read-out that always names the
  biggest room scores no better than chance). Room numbers need a world whose file names its
  rooms; otherwise they are null ("n/a");
- **rooms from the graph**: Louvain communities (networkx) of the map's transition graph
  (Viterbi counts, both directions, all actions) and of the cell graph; adjusted Rand index of
  the community of each test step (its most probable state) against its room;
- **planning** in the simulator (``planning.planning``): success rate of the map's planner
  and of the paper's random behaviour over ``pairs`` start/goal pairs (null with 0 pairs).

One representation (one run) per call: the mean and sd over seeds are left to the caller.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from sensorimotor.analysis.analyze import RAW, load_inputs, representation_of
from sensorimotor.analysis.clusters import N_CLUSTERS, assign_clusters, fit_kmeans
from sensorimotor.analysis.map.baselines import baselines
from sensorimotor.analysis.map.ceilings import NO_CEILING, ceilings
from sensorimotor.analysis.map.cells import (
    ACTION_NAMES,
    N_ACTIONS,
    SMOOTHING,
    CellGraph,
    action_bins,
    baseline_bits,
    cell_graph,
)
from sensorimotor.analysis.map.chmm import (
    EM_ITERS,
    PSEUDOCOUNT,
    TOL,
    CloneHMM,
    filtered,
    fit_chmm,
    log_likelihood,
)
from sensorimotor.analysis.map.context import CONTEXT_TAU, MAX_CONTEXTS, N_CONTEXTS, slow_context
from sensorimotor.analysis.map.planning import (
    GOAL_RADIUS,
    MAX_PAIRS,
    N_PAIRS,
    Moves,
    encoder_of,
    planning,
)
from sensorimotor.errors import InputError
from sensorimotor.files import atomic_path, write_text_atomic
from sensorimotor.sim.database import Database
from sensorimotor.sim.world import World
from sensorimotor.stats import balanced_accuracy
from sensorimotor.version import __version__

N_CLONES = 20  # clones per cell (the issue's 20-cell, 20-clone map)
MAX_CLUSTERS = 200
MAX_CLONES = 100
MAX_STATES = 20_000  # K C N: the random start draws A S^2 numbers (2e9, about 10 s, here)
GRID = 10  # the position ground truth: a GRID x GRID partition of the world
PRIOR = 1e-3  # weight of a state's cell's labels added to the state's own (unvisited states)
OUTPUTS = (
    *("map.json", "map.graphml", "cell_graph.graphml"),
    *("place_fields.png", "map_graph.png", "plans.png"),
)


@dataclass(frozen=True)
class Steps:
    """One split as the map sees it."""

    cells: np.ndarray  # (n,) int64 cell of each step
    actions: np.ndarray  # (n,) int64 action taken at each step (leads to the next)
    motors: np.ndarray  # (n, 2) float64 (d, r)
    poses: np.ndarray  # (n, 3) float64 (x, y, heading)


def _bounding_box(db, train: Steps, test: Steps) -> tuple[World, Steps, Steps]:
    """Where the walls are unknown (a robot's recording), a world of no walls over the box the
    poses cover, and the poses moved into it: the grid and the position error are then over
    the region the robot went through; rooms are unknown and nothing can be planned."""
    xy = np.concatenate([train.poses[:, :2], test.poses[:, :2]])
    low = xy.min(axis=0)
    size = np.maximum(xy.max(axis=0) - low, 1e-6)
    moved = [replace(s, poses=s.poses - np.array([low[0], low[1], 0.0])) for s in (train, test)]
    box = World(db.meta["world"]["name"], float(size[0]), float(size[1]), np.zeros((0, 4)))
    return box, moved[0], moved[1]


def check_settings(k: int, clones: int, contexts: int = N_CONTEXTS) -> None:
    """InputError unless 2 <= K <= MAX_CLUSTERS, 1 <= C <= MAX_CLONES, 1 <= N <= MAX_CONTEXTS
    and K C N <= MAX_STATES."""
    if not 2 <= k <= MAX_CLUSTERS:
        raise InputError(f"--clusters must lie in [2, {MAX_CLUSTERS}], got {k}")
    if not 1 <= clones <= MAX_CLONES:
        raise InputError(f"--clones must lie in [1, {MAX_CLONES}], got {clones}")
    if not 1 <= contexts <= MAX_CONTEXTS:
        raise InputError(f"--contexts must lie in [1, {MAX_CONTEXTS}], got {contexts}")
    if k * clones * contexts > MAX_STATES:
        raise InputError(
            f"--clusters {k} x --clones {clones} x --contexts {contexts} = "
            f"{k * clones * contexts:,} states; at most {MAX_STATES:,}"
        )


def _check_length(db: Database, split: str, k: int) -> None:
    n = len(db.take(split))
    if n < max(k, N_CLUSTERS, 2):
        raise InputError(
            f"{db.source}: the {split} split has {n} steps; the map needs at least "
            f"{max(k, N_CLUSTERS, 2)} (k = {k})"
        )


def cell_steps(run, db: Database, k: int, seed: int, fit_db: Database | None = None):
    """(train Steps, test Steps, the k-means) of ``db``: k-means (k = ``k``) fitted on the
    training split of ``fit_db`` (or of ``db``), applied to both splits of ``db``."""
    for d, split in ((db, "train"), (db, "test"), (fit_db, "train")):
        if d is not None:
            _check_length(d, split, k)
    z_train = representation_of(run, db, "train")
    z_fit = z_train if fit_db is None else representation_of(run, fit_db, "train")
    kmeans = fit_kmeans(z_fit, k, seed)
    z_test = representation_of(run, db, "test")
    return split_steps(db, kmeans, z_train, "train"), split_steps(db, kmeans, z_test), kmeans


def split_steps(db: Database, kmeans, z: np.ndarray, split: str = "test") -> Steps:
    """One split of ``db`` as Steps, the cells of its representation ``z`` by ``kmeans``."""
    part = db.take(split)
    motors = np.asarray(part.motors, dtype=np.float64)
    poses = np.asarray(part.poses, dtype=np.float64)
    return Steps(assign_clusters(kmeans, z), action_bins(motors), motors, poses)


# --------------------------------------------------------------------------------------------
# Localisation


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


# --------------------------------------------------------------------------------------------
# Rooms from the graph


def _networkx():
    """networkx (the ``graph`` extra), or an InputError saying how to install it."""
    try:
        import networkx
    except ImportError:
        raise InputError(
            "sensorimotor map needs networkx: pip install 'sensorimotor[graph]'"
        ) from None
    return networkx


def communities(weights: np.ndarray, nodes: np.ndarray, seed: int) -> np.ndarray:
    """(N,) Louvain community of each node (-1 for those not in ``nodes``) of the undirected
    graph whose edge i-j weighs ``weights[i, j] + weights[j, i]`` (``weights`` (N, N), dense or
    scipy sparse); numbered by smallest node."""
    from scipy.sparse import coo_matrix, triu

    nx = _networkx()
    w = coo_matrix(weights)
    w = triu(w + w.T).tocoo()  # duplicates summed
    graph = nx.Graph()
    graph.add_nodes_from(int(i) for i in nodes)
    keep = np.zeros(w.shape[0], dtype=bool)
    keep[nodes] = True
    for i, j, v in zip(w.row, w.col, w.data, strict=True):
        if v and keep[i] and keep[j]:
            graph.add_edge(int(i), int(j), weight=float(v))
    found = nx.community.louvain_communities(graph, weight="weight", seed=seed)
    label = np.full(w.shape[0], -1, dtype=np.int64)
    for c, members in enumerate(sorted(found, key=min)):
        label[list(members)] = c
    return label


def rooms_from_graph(
    model: CloneHMM, graph: CellGraph, test: Steps, world: World, seed: int
) -> tuple[dict, np.ndarray]:
    """Communities of the map's and of the cell graph's transitions; adjusted Rand index of each
    test step's community against its room (null without named rooms)."""
    from sklearn.metrics import adjusted_rand_score

    state_comm = communities(model.edge_counts(), np.flatnonzero(model.active), seed)
    cell_comm = communities(graph.counts.sum(axis=0), np.arange(graph.k), seed)
    w = filtered(model, test.cells, test.actions)
    best = test.cells * model.n_clones + w.argmax(axis=1)
    out = {
        "communities": {
            "map": int(state_comm.max()) + 1,
            "cells": int(cell_comm.max()) + 1,
        },
        "adjusted_rand": None,
        "adjusted_rand_cells": None,
        "names": [r.name for r in world.rooms],
    }
    if world.rooms:
        room = world.room_index(test.poses[:, 0], test.poses[:, 1])
        ok = room >= 0
        out["adjusted_rand"] = float(adjusted_rand_score(room[ok], state_comm[best][ok]))
        out["adjusted_rand_cells"] = float(adjusted_rand_score(room[ok], cell_comm[test.cells][ok]))
    return out, state_comm


# --------------------------------------------------------------------------------------------
# The whole map, its files


@dataclass(frozen=True)
class MapResult:
    """What ``map_files`` computed and wrote."""

    metrics: dict  # the content of map.json
    files: list[Path]


def _strict(value):
    """``value`` with every non-finite float replaced by None (strict JSON)."""
    if isinstance(value, dict):
        return {k: _strict(v) for k, v in value.items()}
    if isinstance(value, list | tuple):
        return [_strict(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _versions() -> dict:
    import numba
    import sklearn

    versions = {"sensorimotor": __version__, "numpy": np.__version__}
    versions |= {"numba": numba.__version__, "scikit-learn": sklearn.__version__}
    try:
        import networkx

        versions["networkx"] = networkx.__version__
    except ImportError:
        versions["networkx"] = None
    return versions


def map_graphs(model: CloneHMM, graph: CellGraph, state_mean, occupancy, comm, world: World):
    """(the map, the cell graph) as networkx directed graphs: the map's active states with their
    cell, clone (after the split: clone x contexts + context), mean position, room and
    community, edges with their Viterbi counts per action; the cell graph as a multigraph, one
    edge per (cell, action, next cell) with its motor stats."""
    nx = _networkx()
    m = nx.DiGraph(name="map")
    rooms = world.room_index(state_mean[:, 0], state_mean[:, 1]) if world.rooms else None
    for s in np.flatnonzero(model.active):
        m.add_node(
            int(s),
            cell=int(s // model.n_clones),
            clone=int(s % model.n_clones),
            x=float(state_mean[s, 0]),
            y=float(state_mean[s, 1]),
            occupancy=float(occupancy[s]),
            community=int(comm[s]),
            room=world.rooms[rooms[s]].name if rooms is not None and rooms[s] >= 0 else "",
        )
    edges: dict[tuple[int, int], dict] = {}
    for i, j, a, count in zip(*model.transitions(), strict=True):
        edge = edges.setdefault((int(i), int(j)), {f"count_{n}": 0 for n in ACTION_NAMES})
        edge[f"count_{ACTION_NAMES[a]}"] = int(count)
    for (i, j), per_action in sorted(edges.items()):
        m.add_edge(i, j, weight=float(sum(per_action.values())), **per_action)
    g = nx.MultiDiGraph(name="cell graph")
    g.add_nodes_from(range(graph.k))
    for e in graph.edges():
        g.add_edge(e.pop("source"), e.pop("target"), key=e["action"], **e)
    return m, g


def map_files(
    run: str | Path,
    data: str | Path,
    out: str | Path,
    clusters: int = N_CLUSTERS,
    clones: int = N_CLONES,
    fit_data: str | Path | None = None,
    seed: int = 0,
    em_iters: int = EM_ITERS,
    pairs: int = N_PAIRS,
    progress=None,
    contexts: int = N_CONTEXTS,
    tol: float = TOL,
) -> MapResult:
    """Build the map of ``run``'s representation (``"raw"`` or a run folder) of ``data`` and
    write ``map.json``, the GraphML files and the figures into ``out`` (module docstring).
    ``progress(stage, i, number)``: after each EM or Viterbi iteration (its log-likelihood per
    step) and each planning pair (the map's success so far)."""
    from sensorimotor.analysis.map.plots import plot_map_graph, plot_place_fields, plot_plans
    from sensorimotor.sim.plots import save_figure

    check_settings(clusters, clones, contexts)
    nx = _networkx()
    if not 0 <= pairs <= MAX_PAIRS:  # before the inputs are read
        raise InputError(f"--pairs must be from 0 to {MAX_PAIRS:,}, got {pairs}")
    run, db, fit_db, out = load_inputs(run, data, fit_data, out, OUTPUTS)
    train, test, kmeans = cell_steps(run, db, clusters, seed, fit_db)
    if db.has_walls:
        world = db.world
    else:  # a recording: positions within the path's bounding box, no rooms, no planning
        world, train, test = _bounding_box(db, train, test)
        pairs = 0
    graph = cell_graph(train.cells, train.actions, train.motors, clusters)
    context = slow_context(train.cells, clusters, contexts, CONTEXT_TAU, seed)
    model = fit_chmm(
        *(train.cells, train.actions, clusters, clones, N_ACTIONS, seed, em_iters),
        tol=tol,
        context=context,
        n_contexts=contexts,
        progress=progress,
    )
    val = split_steps(db, kmeans, representation_of(run, db, "val"), "val")
    bits = baseline_bits(train.cells, train.actions, test.cells, test.actions, clusters)
    for name, T in (("map", model.T), ("map_em", model.T_em)):
        bits[name] = float(-log_likelihood(T, test.cells, test.actions)[1:].mean()) / math.log(2)
    loc, state_mean, occupancy = localisation(model, train, test, world)
    rooms, comm = rooms_from_graph(model, graph, test, world, seed)
    plans, traces = {"success": {"map": None, "random": None}, "pairs": 0}, []
    if pairs:
        encoder = encoder_of(run, db.max_range)
        on_pair = None if progress is None else lambda i, rate: progress("planning pair", i, rate)
        plans, traces = planning(
            world, db.layout, encoder, kmeans, model, state_mean, occupancy, seed, pairs,
            progress=on_pair, moves=Moves(db.behaviour),
        )  # fmt: skip
    metrics = {
        "run": RAW if run == RAW else str(run.path),
        "model": RAW if run == RAW else run.kind,
        "data": str(data),
        "fit_data": None if fit_data is None else str(fit_data),
        "world": world.name,
        "split": "test (the model fitted on the train split)",
        "steps": {"train": len(train.cells), "test": len(test.cells)},
        "settings": {
            "clusters": clusters,
            "clones": clones,
            "contexts": contexts,
            "context_tau": CONTEXT_TAU,
            "actions": list(ACTION_NAMES),
            "seed": seed,
            "em_iters": em_iters,
            "em_tol": tol,
            "pseudocount": PSEUDOCOUNT,
            "markov_smoothing": SMOOTHING,
            "grid": GRID,
        },
        "versions": _versions(),
        "bits_per_step": bits,
        "baselines": baselines(train, val, test, world, clusters, int(model.active.sum()), seed),
        "ceiling": ceilings(db, world, seed, pairs) if db.has_walls else NO_CEILING,
        "states": {
            "total": model.n_states,
            "active": int(model.active.sum()),
            "em_iterations": len(model.history["em"]),
            "viterbi_iterations": len(model.history["viterbi"]),
            "split_viterbi_iterations": len(model.history.get("split", [])),
            "train_nats_per_step": {
                "em": model.history["em"][-1],
                "viterbi": model.history["viterbi"][-1] if model.history["viterbi"] else None,
            },
        },
        "localisation": loc,
        "rooms": rooms,
        "planning": plans,
    }
    metrics = _strict(metrics)
    the_map, the_cells = map_graphs(model, graph, state_mean, occupancy, comm, world)
    best = test.cells * model.n_clones + filtered(model, test.cells, test.actions).argmax(axis=1)
    seen = np.bincount(best, minlength=model.n_states).astype(np.float64)  # test occupancy
    box = not db.has_walls  # the frame is the path's bounding box, not walls
    place = plot_place_fields(
        world, test.poses, best, seen, f"{metrics['model']} on {world.name}", bounding_box=box
    )
    drawn = plot_map_graph(
        world,
        state_mean,
        model.edge_counts(),
        model.active,
        comm,
        occupancy,
        f"{metrics['model']} on {world.name}: {int(model.active.sum())} states",
        bounding_box=box,
    )
    figures = {"place_fields.png": place, "map_graph.png": drawn.figure}
    if traces:
        figures["plans.png"] = plot_plans(
            world, traces, GOAL_RADIUS, f"{metrics['model']} on {world.name}: the map plans"
        )
    out.mkdir(parents=True, exist_ok=True)
    files = []
    for name, g in (("map.graphml", the_map), ("cell_graph.graphml", the_cells)):
        with atomic_path(out / name, ".graphml") as tmp:
            nx.write_graphml(g, tmp)
        files.append(out / name)
    for name, fig in figures.items():
        files += save_figure(fig, out / name)
    for stale in set(OUTPUTS) - {f.name for f in files} - {"map.json"}:
        (out / stale).unlink(missing_ok=True)  # an earlier map's, in this folder
    path = out / "map.json"
    write_text_atomic(path, json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    files.append(path)
    return MapResult(metrics, files)


def _fmt(v, spec: str = ".3f") -> str:
    return "n/a" if v is None else format(v, spec)


def summary_lines(m: dict) -> list[str]:
    """The main numbers of a ``map.json`` as printable lines."""
    b, loc, r = m["bits_per_step"], m["localisation"], m["rooms"]
    ra, pe = loc["room_accuracy"], loc["position_error"]
    return [
        f"{m['model']} on {m['world']}: {m['settings']['clusters']} cells x "
        f"{m['settings']['clones']} clones x {m['settings'].get('contexts', 1)} contexts, "
        f"{m['states']['active']} active states",
        "  bits/step: " + ", ".join(f"{k} {_fmt(v)}" for k, v in b.items()),
        *_baseline_lines(m),
        f"  room accuracy: map {_fmt(ra['map'])}, cells {_fmt(ra['cells'])}, "
        f"chance {_fmt(ra['chance'])}",
        f"  position error: map {_fmt(pe['map'], '.2f')}, cells {_fmt(pe['cells'], '.2f')}, "
        f"chance {_fmt(pe['chance'], '.2f')}",
        f"  rooms from the graph: adjusted Rand {_fmt(r['adjusted_rand'])} (map), "
        f"{_fmt(r['adjusted_rand_cells'])} (cells)",
        f"  planning success: map {_fmt(m['planning']['success']['map'], '.2f')}, random "
        f"{_fmt(m['planning']['success']['random'], '.2f')} ({m['planning']['pairs']} pairs)",
        *_planning_warning(m["planning"]),
    ]


def _baseline_lines(m: dict) -> list[str]:
    """The baselines' and ceilings' numbers (none in a map.json made before them)."""
    base, top = m.get("baselines", {}), m.get("ceiling", {})
    out = []
    if base:
        higher = ", ".join(f"{k} {_fmt(v)}" for k, v in base["bits_per_step"].items())
        readout = base["localisation"]["history_readout"]
        out.append(
            f"  baselines: bits/step {higher}; balanced room accuracy of the history read-out "
            f"{_fmt(readout)}"
        )
    if top:
        loc = top["localisation"]
        blind = (loc.get("no_odometry") or {}).get("balanced_room_accuracy")
        out.append(
            f"  ceilings: balanced room accuracy of MCL {_fmt(loc['balanced_room_accuracy'])} "
            f"(no odometry {_fmt(blind)}); true-pose planning "
            f"{_fmt(top['planning']['success'], '.2f')}"
        )
    return out


def _planning_warning(planning: dict) -> list[str]:
    """A warning where the map's planner reaches no more goals than the random behaviour: its
    plans then say nothing about the map (too little data or too few clones to tell places
    apart, or a representation whose cells do not)."""
    ours, chance = planning["success"]["map"], planning["success"]["random"]
    if ours is None or chance is None or ours > chance:
        return []
    return [
        f"  warning: the planner reached no more goals than the random behaviour ({ours:.2f} vs "
        f"{chance:.2f}): the map does not tell the places apart well enough to plan; try more "
        "data (a larger database or --scale paper) or more --clones"
    ]
