"""The probes of paper-scale seeds of Rec-SMA, its ablations and Rec-SM side by side (issue 32).

    python docs/results/memory/five_seeds.py [LABEL=]PROBES [LABEL=]PROBES ...

Each PROBES is a folder of ``s0`` .. ``s4`` folders written by ``sensorimotor analyze RUN
--data FRESH.npz --out PROBES/sN`` (LABEL: the column's name, default the folder's). Prints
the mean and Student-t 95 % interval of each probe beside the issue's goals (set before any
Rec-SMA was trained); a probe a world does not have (the room of Square) is left out. The
seeds of two columns are independent models, so no difference is paired.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

from sensorimotor.experiments.memory import THRESHOLDS
from sensorimotor.stats import t_interval

PROBES = {
    "room (balanced accuracy)": ("room", "balanced_accuracy"),
    "R^2 x": ("position", "r2", "x"),
    "R^2 y": ("position", "r2", "y"),
    "median position error": ("position", "median_error"),
    "KNN-MSE": ("knn_mse", "value"),
}


def probe_values(folder: Path, path: tuple) -> list[float] | None:
    """The probe at ``path`` of every seed in ``folder``; None where the world has none."""
    out = []
    seeds = sorted(folder.glob("s[0-9]*"))
    if len(seeds) < 2:
        raise SystemExit(f"{folder}: fewer than 2 seed folders s0, s1, ...")
    for seed in seeds:
        value = json.loads((seed / "metrics.json").read_text())["probes"]
        for key in path:
            value = None if value is None else value[key]
        if value is None:
            return None
        out.append(float(value))
    return out


def main(columns: dict[str, Path]) -> None:
    print(f"goals (THRESHOLDS, set before the data): {THRESHOLDS}")
    print("| probe | " + " | ".join(f"{label} mean [t 95 %]" for label in columns) + " |")
    print("|---|" + "---|" * len(columns))
    for name, path in PROBES.items():
        cells = []
        for folder in columns.values():
            values = probe_values(folder, path)
            if values is None:
                break
            low, high = t_interval(values)
            mean = sum(values) / len(values)
            cells.append(f"{mean:.3f} [{low:.3f}, {high:.3f}] (n = {len(values)})")
        else:
            print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    args = [a.rpartition("=") for a in sys.argv[1:]]
    main({(label if sep else Path(d).name): Path(d) for label, sep, d in args})
