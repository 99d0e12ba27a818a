"""The five-seed grid maps' communities again, after ``graphs.RUNS`` (Louvain's run of highest
modularity of 10, chosen on the validation maps; DESIGN.md, Map): each map refitted as
``reproduce --experiment gridmap`` fits it (``mapping.map_files``, the same seeds and settings)
and its rooms scored on its fresh test database as ``map`` scores them, once with the kept run
of 10 and once with the single run ``map`` made before (its seed, to check the refit reproduces
the shipped number). The ceilings, baselines and plans are left out (``pairs`` 0, the ceilings
and baselines not computed): they do not depend on the communities.

    python rescore_communities.py DATA OUT rooms1:0:2:0 rooms1:3:4:1 ...   # WORLD:TRAIN:TEST:K
    python rescore_communities.py --table OUT ../five_seeds                 # the table
"""

import json
import sys
from pathlib import Path

import numpy as np
from sklearn.metrics import adjusted_rand_score

from sensorimotor.analysis.map import graphs, mapping
from sensorimotor.stats import t_interval

CLONES = {"rooms1": 160, "rooms2": 200}  # as five_seeds was made (README, "Five seeds")


ORIGINAL = mapping.rooms_from_graph


def rooms_both_ways(model, graph, steps, best, world, seed, resolution):
    """``rooms_from_graph`` (the kept run of ``graphs.RUNS``), and beside it the single run of
    ``seed`` scored the same way."""
    rooms, comm = ORIGINAL(model, graph, steps, best, world, seed, resolution)
    one = graphs.communities(
        model.edge_counts(), np.flatnonzero(model.active), seed, resolution, runs=1
    )
    room = world.room_index(steps.poses[:, 0], steps.poses[:, 1])
    ok = room >= 0
    rooms["adjusted_rand_one_run"] = float(adjusted_rand_score(room[ok], one[best][ok]))
    rooms["communities_one_run"] = int(one.max()) + 1
    return rooms, comm


def rescore(data: Path, out: Path, spec: str) -> None:
    """One map (``WORLD:TRAIN:TEST:K``) fitted and its rooms scored both ways."""
    world, train, test, k = spec.split(":")
    mapping.map_files(
        "raw", data / f"{world}_grid_r16_s{train}.npz", out / f"{world}_k{k}", clusters=200,
        clones=CLONES[world], contexts=1, start="fine", pseudocount=2e-5, pairs=0, seed=int(k),
        test_data=data / f"{world}_grid_r16_s{test}.npz",
    )  # fmt: skip
    rooms = json.loads((out / f"{world}_k{k}" / "map.json").read_text())["rooms"]
    print(spec, {key: rooms[key] for key in rooms if key != "names"}, flush=True)


def mean_t(values: list[float]) -> str:
    low, high = t_interval(values)
    return f"{np.mean(values):.3f} [{low:.3f}, {high:.3f}]"


def table(out: Path, shipped: Path) -> None:
    print("| mean [Student-t 95 %] | kept run of 10 | one run, refitted | one run, shipped |")
    print("|---|---|---|---|")
    for world in ("rooms1", "rooms2"):
        cols: list[list[float]] = [[], [], []]
        for k in range(5):
            rooms = json.loads((out / f"{world}_k{k}" / "map.json").read_text())["rooms"]
            old = json.loads((shipped / f"{world}_k{k}" / "map.json").read_text())["rooms"]
            for col, v in zip(cols, (rooms["adjusted_rand"], rooms["adjusted_rand_one_run"],
                                     old["adjusted_rand"]), strict=True):  # fmt: skip
                col.append(v)
        print(f"| {world}: adjusted Rand | " + " | ".join(mean_t(c) for c in cols) + " |")
        print(f"| {world}, per seed | " + " | ".join(", ".join(f"{v:.2f}" for v in c)
                                                     for c in cols) + " |")  # fmt: skip


if __name__ == "__main__":
    if sys.argv[1] == "--table":
        table(Path(sys.argv[2]), Path(sys.argv[3]))
    else:  # map_files as it is, less what the communities do not change
        mapping.rooms_from_graph = rooms_both_ways
        mapping.ceilings = lambda *a, **kw: mapping.NO_CEILING
        mapping.baselines = lambda *a, **kw: {}
        for spec in sys.argv[3:]:
            rescore(Path(sys.argv[1]), Path(sys.argv[2]), spec)
