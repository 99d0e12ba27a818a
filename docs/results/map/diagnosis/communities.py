"""A pilot: Louvain's resolution against the rooms, on a map's ``map.graphml``.

``python communities.py MAP.graphml``: the map's transitions as an undirected graph (Viterbi
counts, both directions, all actions summed), Louvain (networkx, seed 0) at six resolutions,
and the adjusted Rand index of each active state's community against its room (as a node, and
weighted by its training occupancy). ``graphs.rooms_from_graph`` runs resolution 1.
"""

import sys

import networkx as nx
import numpy as np
from sklearn.metrics import adjusted_rand_score

graph = nx.read_graphml(sys.argv[1])
undirected = nx.Graph()
for a, b, data in graph.edges(data=True):
    w = data.get("weight", 1.0)
    if undirected.has_edge(a, b):
        undirected[a][b]["weight"] += w
    else:
        undirected.add_edge(a, b, weight=w)
nodes = list(undirected.nodes)
room = np.array([graph.nodes[n]["room"] for n in nodes])
visits = np.array([max(round(graph.nodes[n]["occupancy"]), 1) for n in nodes])
known = room != "None"
for resolution in (1.0, 0.3, 0.1, 0.03, 0.01, 0.003):
    found = nx.community.louvain_communities(undirected, resolution=resolution, seed=0)
    label = {n: i for i, members in enumerate(found) for n in members}
    comm = np.array([label[n] for n in nodes])
    plain = adjusted_rand_score(room[known], comm[known])
    weighted = adjusted_rand_score(
        np.repeat(room[known], visits[known]), np.repeat(comm[known], visits[known])
    )
    print(f"resolution {resolution}: {len(found)} communities, adjusted Rand {plain:.3f} "
          f"(states), {weighted:.3f} (weighted by occupancy)")  # fmt: skip
