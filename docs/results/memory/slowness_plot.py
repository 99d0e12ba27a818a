"""The slowness and contrastive pilots' room accuracy by epoch, from their logs in ``slowness/``.

    python docs/results/memory/slowness_plot.py [--out docs/results/memory/slowness/room.png]

Each log is ``heading_pilot.py``'s output: a JSON line of probes every 20 epochs and one at the
end. One line per run, one colour per form; the true pose (0.993), the goal (0.90) and Rec-SM
(0.367, the paper kinds' strongest) as reference lines.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

HERE = Path(__file__).parent / "slowness"
RUNS = {  # log name: (label, colour)
    "floor_w0": ("no prior (W = 0)", "0.4"),
    "floor_w0_s1": ("no prior (W = 0)", "0.4"),
    "floor_w0_s2": ("no prior (W = 0)", "0.4"),
    "floor_w0.1": ("floor, W = 0.1", "tab:orange"),
    "floor_w1": ("floor, W = 1", "tab:red"),
    "hinge_w1": ("hinge, W = 1", "tab:blue"),
    "hinge_w1_s1": ("hinge, W = 1", "tab:blue"),
    "hinge_w1_s2": ("hinge, W = 1", "tab:blue"),
    "hinge_w10": ("hinge, W = 10", "tab:purple"),
    "sfa_w1": ("sfa, W = 1", "tab:green"),
    "contrastive_w1_s0": ("contrastive, W = 1", "tab:brown"),
    "contrastive_w1_s1": ("contrastive, W = 1", "tab:brown"),
    "contrastive_w1_s2": ("contrastive, W = 1", "tab:brown"),
    "k64_hinge_w1_s0": ("hinge, W = 1, K = 64", "tab:cyan"),
    "k64_hinge_w1_s1": ("hinge, W = 1, K = 64", "tab:cyan"),
    "k64_hinge_w1_s2": ("hinge, W = 1, K = 64", "tab:cyan"),
}


def curve(log: Path) -> tuple[list[int], list[float]]:
    """(epochs, room balanced accuracy) of one pilot's log."""
    epochs, rooms = [], []
    for line in log.read_text().splitlines():
        if line.startswith("{"):
            d = json.loads(line)
            epochs.append(d["epoch"] if "epoch" in d else d["epochs"])
            rooms.append(d["probes"]["room"]["balanced_accuracy"])
    return epochs, rooms


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, default=HERE / "room.png")
    args = ap.parse_args()
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    seen = set()
    for name, (label, colour) in RUNS.items():
        epochs, rooms = curve(HERE / f"{name}.log")
        ax.plot(epochs, rooms, "o-", color=colour, label=None if label in seen else label, lw=1.2)
        seen.add(label)
    for y, text in ((0.993, "true pose"), (0.90, "goal"), (0.367, "Rec-SM"), (1 / 3, "chance")):
        ax.axhline(y, color="k", lw=0.6, ls=":")
        ax.text(61, y, text, va="center", fontsize=8)
    ax.set_xlim(15, 70)
    ax.set_ylim(0.3, 1.02)
    ax.set_xlabel("epochs (Rooms1, 1,000,000 steps)")
    ax.set_ylabel("room, balanced accuracy (fresh database)")
    ax.set_title("Rec-SMA with a prior on 4 of z_s's 10 dimensions (Rooms1)")
    ax.legend(fontsize=8, loc="center right")
    fig.tight_layout()
    tmp = args.out.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=120)
    tmp.replace(args.out)


if __name__ == "__main__":
    main()
