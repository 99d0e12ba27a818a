"""The probes of paper-scale seeds of Rec-SMA, its ablations and Rec-SM side by side (issue 32).

    python docs/results/memory/five_seeds.py [LABEL=]PROBES ... [--png FILE [--ceiling X]]

Each PROBES is a folder of ``s0`` .. ``s4`` folders written by ``sensorimotor analyze RUN
--data FRESH.npz --out PROBES/sN`` (LABEL: the column's name, default the folder's). Prints
the mean and Student-t 95 % interval of each probe beside the issue's goals (set before any
Rec-SMA was trained); a probe a world does not have (the room of Square) is left out. The
seeds of two columns are independent models, so no difference is paired. ``--png``: the room
probe of each column drawn, each seed a dot, the mean with its interval, the goal a line.
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


def plot_room(
    columns: dict[str, Path], png: Path, ceiling: float | None = None, world: str = "rooms1"
) -> None:
    """Each column's balanced room accuracy: the seeds (dots), the mean and its Student-t
    interval; the goal, chance and the ``ceiling`` as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1.6 * len(columns) + 1.5, 3.6))
    for i, folder in enumerate(columns.values()):
        values = probe_values(folder, PROBES["room (balanced accuracy)"])
        low, high = t_interval(values)
        mean = sum(values) / len(values)
        ax.plot([i - 0.15] * len(values), values, "o", color="0.5", markersize=4)
        ax.errorbar(i, mean, yerr=[[mean - low], [high - mean]], fmt="s", color="k", capsize=5)
    ax.axhline(THRESHOLDS["room"][world], color="tab:green", ls="--", label="goal (set before)")
    ax.axhline(1 / 3, color="tab:red", ls=":", label="chance")
    if ceiling is not None:
        ax.axhline(ceiling, color="tab:blue", ls="-.", label="true pose (ceiling)")
    ax.set_xticks(range(len(columns)), list(columns), rotation=15, ha="right", fontsize=8)
    ax.set_ylabel("balanced room accuracy (fresh test split)")
    ax.set_ylim(0.3, 1.02)
    ax.legend(fontsize=8, loc="center right")
    fig.tight_layout()
    fig.savefig(png, dpi=120)


if __name__ == "__main__":
    argv = sys.argv[1:]
    options = {}
    for flag in ("--png", "--ceiling"):
        if flag in argv:
            options[flag] = argv.pop(argv.index(flag) + 1)
            argv.remove(flag)
    png = Path(options["--png"]) if "--png" in options else None
    args = [a.rpartition("=") for a in argv]
    columns = {(label if sep else Path(d).name): Path(d) for label, sep, d in args}
    main(columns)
    if png is not None:
        ceiling = float(options["--ceiling"]) if "--ceiling" in options else None
        plot_room(columns, png, ceiling)
