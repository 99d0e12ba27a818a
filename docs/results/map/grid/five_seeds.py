"""The grid maps over seeds, on fresh test databases, beside the issue's goals (issue 37).

    python docs/results/map/grid/five_seeds.py WORLD=MAP_DIR[,MAP_DIR...] ...

Each MAP_DIR holds the ``map.json`` of ``sensorimotor map raw --data TRAIN --test-data FRESH
...`` (one map seed, one training database, one fresh test database), as ``reproduce
--experiment gridmap`` makes them; the numbers are aggregated as that experiment aggregates
them (``experiments.gridmap.aggregate``): mean and Student-t 95 % interval, the goals.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from sensorimotor.experiments.gridmap import _cell, aggregate


def main(args: list[str]) -> None:
    per_map = []
    for arg in args:
        world, dirs = arg.split("=", 1)
        for k, d in enumerate(dirs.split(",")):
            per_map.append((world, k, json.loads((Path(d) / "map.json").read_text())))
    found = aggregate(per_map)
    names = list(found)
    print("| mean [Student-t 95 %] | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 1) + "|")
    print("| maps (seeds) | " + " | ".join(str(len(found[w]["seeds"])) for w in names) + " |")
    for label in found[names[0]]["rows"]:
        print(f"| {label} | " + " | ".join(_cell(found[w]["rows"][label]) for w in names) + " |")
    for world, res in found.items():
        print(f"\n{world}:")
        for v in res["goals"].values():
            n = v["numbers"]
            said = "reached" if v["holds"] else f"missed by {n['goal'] - n['mean']:.3f}"
            print(f"- {v['claim']}: {_cell(n)} against {v['threshold']} ({v['provenance']}): "
                  f"{said}")  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
