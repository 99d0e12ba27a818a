"""Two pilot settings' probes at one epoch, over seeds, and their paired difference.

    python docs/results/memory/pilot_seeds.py --epoch 60 \\
        --setting slowness/contrastive_w1_s{0,1,2}.log --control slowness/hinge_w1{,_s1,_s2}.log

Each log is ``heading_pilot.py``'s output (a JSON line of probes every ``--probe-every``
epochs and one at the end); the two lists pair by position (seed by seed). Prints
``five_seeds.py``'s tables: each probe's mean and Student-t 95 % interval for both settings,
then the setting minus the control, seed by seed.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from five_seeds import PROBES, print_paired, print_table


def probes_at(log: Path, epoch: int) -> dict:
    """The probes a pilot's log gives at ``epoch`` (its last line holds the final epoch's)."""
    for line in log.read_text().splitlines():
        if line.startswith("{"):
            d = json.loads(line)
            if d.get("epoch", d.get("epochs")) == epoch:
                return d["probes"]
    raise SystemExit(f"{log}: no probes at epoch {epoch}")


def column(logs: list[Path], epoch: int) -> dict[str, list[float]]:
    """``{probe: [value of each seed]}``, as ``five_seeds.probe_table`` gives for folders."""
    probes = [probes_at(log, epoch) for log in logs]
    table = {}
    for name, path in PROBES.items():
        values = []
        for value in probes:
            for key in path:
                value = value[key]
            values.append(float(value))
        table[name] = values
    return table


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--epoch", type=int, required=True)
    ap.add_argument("--setting", type=Path, nargs="+", required=True)
    ap.add_argument("--control", type=Path, nargs="+", required=True)
    args = ap.parse_args()
    if len(args.setting) != len(args.control):
        raise SystemExit("--setting and --control pair by seed: give as many logs to each")
    columns = {
        f"setting, {args.epoch} epochs": column(args.setting, args.epoch),
        "control": column(args.control, args.epoch),
    }
    print_table(columns)
    print_paired(columns)


if __name__ == "__main__":
    main()
