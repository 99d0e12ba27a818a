"""The map as a graph: Louvain communities of its transitions (rooms from the graph, scored by
the adjusted Rand index against the rooms) and the networkx graphs written as GraphML."""

from __future__ import annotations

import math

import numpy as np

from sensorimotor.analysis.map.cells import ACTION_NAMES, CellGraph, Steps
from sensorimotor.analysis.map.chmm import CloneHMM, filtered
from sensorimotor.errors import InputError
from sensorimotor.sim.world import World

# Louvain's resolution (a smaller one, bigger communities; networkx's default is 1): chosen on
# validation maps (the grid behaviour's seed-1 databases of Rooms1 and Rooms2, 16 rays, their
# validation split; grid_planner.py rooms in docs/results/map/diagnosis) by the mean adjusted
# Rand index over both worlds among 1, 0.3, 0.1, 0.05, 0.03, 0.02, 0.01, 0.003 (1: 0.16,
# 0.1: 0.49, 0.05: 0.75, 0.03: 0.70, 0.01: 0.69); not validated on the paper behaviour's maps.
RESOLUTION = 0.05
# Louvain's runs (its random order from seeds seed * RUNS ... seed * RUNS + RUNS - 1); the one of
# highest modularity is kept. On the two validation maps above (rule in grid_planner.py
# restarts, written before the run), the highest-modularity run of 10 scored adjusted Rand 0.655
# and 0.911 where the median single run scored 0.652 and 0.899 (the runs 0.40 to 0.71 on Rooms1).
RUNS = 10
MAX_RESOLUTION = 100.0  # past it nearly every node is a community of its own


def networkx_or_refuse():
    """networkx (the ``graph`` extra), or an InputError saying how to install it."""
    try:
        import networkx
    except ImportError:
        raise InputError(
            "sensorimotor map needs networkx: pip install 'sensorimotor[graph]'"
        ) from None
    return networkx


def undirected(weights: np.ndarray, nodes: np.ndarray):
    """The networkx graph on ``nodes`` whose edge i-j weighs ``weights[i, j] + weights[j, i]``
    (``weights`` (N, N), dense or scipy sparse)."""
    from scipy.sparse import coo_matrix, triu

    nx = networkx_or_refuse()
    w = coo_matrix(weights)
    w = triu(w + w.T).tocoo()  # duplicates summed
    graph = nx.Graph()
    graph.add_nodes_from(int(i) for i in nodes)
    keep = np.zeros(w.shape[0], dtype=bool)
    keep[nodes] = True
    for i, j, v in zip(w.row, w.col, w.data, strict=True):
        if v and keep[i] and keep[j]:
            graph.add_edge(int(i), int(j), weight=float(v))
    return graph


def communities(
    weights: np.ndarray,
    nodes: np.ndarray,
    seed: int,
    resolution: float = RESOLUTION,
    runs: int = RUNS,
) -> np.ndarray:
    """(N,) Louvain community (at ``resolution``) of each node (-1 for those not in ``nodes``)
    of the ``undirected`` graph of ``weights``, from the run of highest modularity of ``runs``;
    numbered by smallest node."""
    nx = networkx_or_refuse()
    graph = undirected(weights, nodes)
    if graph.number_of_edges() == 0:  # no modularity to compare: every run finds the nodes
        runs = 1
    found, best = None, -math.inf
    kw = {"weight": "weight", "resolution": resolution}
    for run in range(seed * runs, seed * runs + runs):
        found_run = nx.community.louvain_communities(graph, seed=run, **kw)
        q = nx.community.modularity(graph, found_run, **kw) if runs > 1 else 0.0
        if q > best:
            found, best = found_run, q
    label = np.full(weights.shape[0], -1, dtype=np.int64)
    for c, members in enumerate(sorted(found, key=min)):
        label[list(members)] = c
    return label


def best_states(model: CloneHMM, steps: Steps) -> np.ndarray:
    """(n,) the most probable state of each step under the filter (causal)."""
    return steps.cells * model.n_clones + filtered(model, steps.cells, steps.actions).argmax(axis=1)


def rooms_from_graph(
    model: CloneHMM,
    graph: CellGraph,
    test: Steps,
    best: np.ndarray,
    world: World,
    seed: int,
    resolution: float = RESOLUTION,
) -> tuple[dict, np.ndarray]:
    """Communities of the map's and of the cell graph's transitions; adjusted Rand index of each
    test step's community (that of ``best``, its ``best_states``) against its room (null
    without named rooms)."""
    from sklearn.metrics import adjusted_rand_score

    state_comm = communities(model.edge_counts(), np.flatnonzero(model.active), seed, resolution)
    cell_comm = communities(graph.counts.sum(axis=0), np.arange(graph.k), seed, resolution)
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


def map_graphs(model: CloneHMM, graph: CellGraph, state_mean, occupancy, comm, world: World):
    """(the map, the cell graph) as networkx directed graphs: the map's active states with their
    cell, clone (after the split: clone x contexts + context), mean position, room and
    community, edges with their Viterbi counts per action; the cell graph as a multigraph, one
    edge per (cell, action, next cell) with its motor stats."""
    nx = networkx_or_refuse()
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
