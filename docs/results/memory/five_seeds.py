"""The probes of five paper-scale seeds of Rec-SMA and of Rec-SM beside them (issue 32).

    python docs/results/memory/five_seeds.py SMA_PROBES REC_SM_PROBES

Each argument is a folder of ``s0`` .. ``s4`` folders written by ``sensorimotor analyze RUN
--data r1_fresh1.npz --out DIR/sN``. Prints the mean and Student-t 95 % interval of each probe
beside the issue's goals (set before any Rec-SMA was trained). The seeds of the two kinds are
independent models, so no difference is paired.
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


def probe_values(folder: Path, path: tuple) -> list[float]:
    out = []
    for seed in sorted(folder.glob("s[0-9]*")):
        value = json.loads((seed / "metrics.json").read_text())["probes"]
        for key in path:
            value = value[key]
        out.append(float(value))
    return out


def main(sma: Path, rec_sm: Path) -> None:
    print(f"goals (THRESHOLDS, set before the data): {THRESHOLDS}")
    print("| probe | Rec-SMA mean [t 95 %] | Rec-SM (strongest baseline) mean [t 95 %] |")
    print("|---|---|---|")
    for name, path in PROBES.items():
        a, b = probe_values(sma, path), probe_values(rec_sm, path)
        cells = []
        for values in (a, b):
            low, high = t_interval(values)
            cells.append(f"{sum(values) / len(values):.3f} [{low:.3f}, {high:.3f}] (n = {len(values)})")
        print(f"| {name} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main(Path(sys.argv[1]), Path(sys.argv[2]))
