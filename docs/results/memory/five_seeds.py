"""The probes of paper-scale seeds of Rec-SMA, its ablations and Rec-SM side by side (issue 32).

    python docs/results/memory/five_seeds.py [LABEL=]PROBES ... [--paired] [--png FILE [--ceiling X] [--world W]]

Each PROBES is a folder of ``s0`` .. ``s4`` folders written by ``sensorimotor analyze RUN
--data FRESH.npz --out PROBES/sN`` (LABEL: the column's name, default the folder's). Prints
the mean and Student-t 95 % interval of each probe beside the issue's goals (set before any
Rec-SMA was trained); a probe a world does not have (the room of Square) is left out. The
seeds of two columns are independent models, so no difference is paired, unless ``--paired``:
then the first column minus the second, seed by seed (a setting beside its control: the same
seeds' initial weights and data order), with its Student-t interval. ``--png``: the room
probe of each column drawn, each seed a dot, the mean with its interval, the goal a line.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sensorimotor.experiments.memory import THRESHOLDS
from sensorimotor.sim.world import load_world
from sensorimotor.stats import t_interval

PROBES = {
    "room (balanced accuracy)": ("room", "balanced_accuracy"),
    "R^2 x": ("position", "r2", "x"),
    "R^2 y": ("position", "r2", "y"),
    "median position error": ("position", "median_error"),
    "KNN-MSE": ("knn_mse", "value"),
}
ROOM = "room (balanced accuracy)"


def probe_table(folder: Path) -> dict[str, list[float]]:
    """``{probe: [value of each seed]}`` of the seed folders in ``folder``, each metrics.json
    read once; a probe the world has not (null) is left out."""
    seeds = sorted(folder.glob("s[0-9]*"))
    if len(seeds) < 2:
        raise SystemExit(f"{folder}: fewer than 2 seed folders s0, s1, ...")
    probes = [json.loads((seed / "metrics.json").read_text())["probes"] for seed in seeds]
    table = {}
    for name, path in PROBES.items():
        values = []
        for value in probes:
            for key in path:
                value = None if value is None else value[key]
            values.append(value)
        if None not in values:
            table[name] = [float(v) for v in values]
    return table


def print_table(columns: dict[str, dict[str, list[float]]]) -> None:
    print(f"goals (THRESHOLDS, set before the data): {THRESHOLDS}")
    print("| probe | " + " | ".join(f"{label} mean [t 95 %]" for label in columns) + " |")
    print("|---|" + "---|" * len(columns))
    for name in PROBES:
        if not all(name in table for table in columns.values()):
            continue
        cells = []
        for table in columns.values():
            values = table[name]
            low, high = t_interval(values)
            mean = sum(values) / len(values)
            cells.append(f"{mean:.3f} [{low:.3f}, {high:.3f}] (n = {len(values)})")
        print(f"| {name} | " + " | ".join(cells) + " |")


def print_paired(columns: dict[str, dict[str, list[float]]]) -> None:
    """The first column minus the second, seed by seed (the caller checks that their seeds
    are the same), for every probe both hold."""
    (a, first), (b, second) = list(columns.items())[:2]
    print(f"\n| probe | {a} minus {b}, by seed: mean [t 95 %] | by seed |")
    print("|---|---|---|")
    for name in PROBES:
        if name in first and name in second:
            diffs = [x - y for x, y in zip(first[name], second[name], strict=True)]
            low, high = t_interval(diffs)
            each = ", ".join(f"{d:+.3f}" for d in diffs)
            print(f"| {name} | {sum(diffs) / len(diffs):+.3f} [{low:+.3f}, {high:+.3f}] | {each} |")


def plot_room(
    columns: dict[str, dict[str, list[float]]],
    png: Path,
    ceiling: float | None = None,
    world: str = "rooms1",
) -> None:
    """Each column's balanced room accuracy: the seeds (dots), the mean and its Student-t
    interval; the goal, chance and the ``ceiling`` as lines."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(1.6 * len(columns) + 1.5, 3.6))
    for i, table in enumerate(columns.values()):
        values = table[ROOM]
        low, high = t_interval(values)
        mean = sum(values) / len(values)
        ax.plot([i - 0.15] * len(values), values, "o", color="0.5", markersize=4)
        ax.errorbar(i, mean, yerr=[[mean - low], [high - mean]], fmt="s", color="k", capsize=5)
    ax.axhline(THRESHOLDS["room"][world], color="tab:green", ls="--", label="goal (set before)")
    ax.axhline(1 / len(load_world(world).rooms), color="tab:red", ls=":", label="chance")
    if ceiling is not None:
        ax.axhline(ceiling, color="tab:blue", ls="-.", label="true pose (ceiling)")
    ax.set_xticks(range(len(columns)), list(columns), rotation=15, ha="right", fontsize=8)
    ax.set_ylabel("balanced room accuracy (fresh test split)")
    ax.set_ylim(min(0.3, 1 / len(load_world(world).rooms) - 0.05), 1.02)
    ax.legend(fontsize=8, loc="center right")
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("columns", nargs="+", metavar="[LABEL=]PROBES")
    parser.add_argument("--paired", action="store_true", help="the first two columns by seed")
    parser.add_argument("--png", type=Path, help="draw the room probe of each column here")
    parser.add_argument("--ceiling", type=float, help="the true pose's room accuracy, a line")
    parser.add_argument("--world", default="rooms1", choices=list(THRESHOLDS["room"]))
    args = parser.parse_args()
    columns, folders = {}, []
    for column in args.columns:
        label, _, folder = column.rpartition("=")  # a label may hold "=", a folder not
        columns[label or Path(folder).name] = probe_table(Path(folder))
        folders.append(Path(folder))
    print_table(columns)
    if args.paired:
        names = [sorted(p.name for p in folder.glob("s[0-9]*")) for folder in folders[:2]]
        if len(columns) < 2 or names[0] != names[1]:
            raise SystemExit(
                f"--paired: the first two columns must hold the same seeds, got {names}"
            )
        print_paired(columns)
    if args.png is not None:
        plot_room(columns, args.png, args.ceiling, args.world)


if __name__ == "__main__":
    main()
