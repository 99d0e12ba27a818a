"""Two pilot settings' probes at one epoch, over seeds, and their paired difference.

    python docs/results/memory/pilot_seeds.py --epoch 60 \\
        --setting slowness/contrastive_w1_s{0,1,2}.log --control slowness/hinge_w1{,_s1,_s2}.log

Each log is ``heading_pilot.py``'s output (a JSON line of probes every ``--probe-every``
epochs and one at the end); the two lists pair by position (seed by seed). Prints each probe's
mean and Student-t 95 % interval for both settings and for the paired difference.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sensorimotor.stats import paired_differences, t_interval

PROBES = {  # the printed name: the path in a probes dict
    "room (balanced accuracy)": ("room", "balanced_accuracy"),
    "R^2 x": ("position", "r2", "x"),
    "R^2 y": ("position", "r2", "y"),
    "median position error": ("position", "median_error"),
    "KNN-MSE": ("knn_mse", "value"),
}


def probes_at(log: Path, epoch: int) -> dict:
    """The probes a pilot's log gives at ``epoch`` (its last line holds the final epoch's)."""
    for line in log.read_text().splitlines():
        if line.startswith("{"):
            d = json.loads(line)
            if d.get("epoch", d.get("epochs")) == epoch:
                return d["probes"]
    raise SystemExit(f"{log}: no probes at epoch {epoch}")


def value(probes: dict, path: tuple[str, ...]) -> float:
    for key in path:
        probes = probes[key]
    return float(probes)


def summary(values: list[float]) -> str:
    low, high = t_interval(values)
    mean = sum(values) / len(values)
    return f"{mean:.3f} [{low:.3f}, {high:.3f}] ({', '.join(f'{v:.3f}' for v in values)})"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epoch", type=int, required=True)
    ap.add_argument("--setting", type=Path, nargs="+", required=True)
    ap.add_argument("--control", type=Path, nargs="+", required=True)
    args = ap.parse_args()
    if len(args.setting) != len(args.control):
        raise SystemExit("--setting and --control pair by seed: give as many logs to each")
    setting = [probes_at(p, args.epoch) for p in args.setting]
    control = [probes_at(p, args.epoch) for p in args.control]
    print(f"| at {args.epoch} epochs | setting | control | paired difference |")
    print("|---|---|---|---|")
    for name, path in PROBES.items():
        a = [value(p, path) for p in setting]
        b = [value(p, path) for p in control]
        low, high = t_interval(paired_differences(a, b))
        mean = sum(paired_differences(a, b)) / len(a)
        print(f"| {name} | {summary(a)} | {summary(b)} | {mean:+.3f} [{low:+.3f}, {high:+.3f}] |")


if __name__ == "__main__":
    main()
