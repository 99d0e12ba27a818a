"""The figure of ``sensorimotor rl``: learning curves and final scores per feature set."""

from __future__ import annotations

from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from sensorimotor.sim.plots import save_figure

COLORS = {
    "pose": "black",
    "raw": "tab:gray",
    "s": "tab:blue",
    "sm": "tab:orange",
    "rec-s": "tab:green",
    "rec-sm": "tab:red",
    "random": "tab:purple",
}


def rl_figure(rl: dict) -> Figure:
    """Left: success rate against environment steps, mean over seeds with its 95 % bootstrap
    band, one line per feature set. Right: final success per feature set (bars: mean, whiskers:
    CI) in the task's world and in each transfer world."""
    fig = Figure(figsize=(10, 4), layout="constrained")
    curves, bars = fig.subplots(1, 2, width_ratios=[3, 2])
    for name, r in rl["results"].items():
        c = r["curve"]
        steps = np.asarray(c["steps"])
        color = COLORS.get(name)
        curves.plot(steps, c["success"]["mean"], color=color, label=name)
        curves.fill_between(
            steps, c["success"]["ci_low"], c["success"]["ci_high"], color=color, alpha=0.2
        )
    curves.set(
        xlabel="environment steps",
        ylabel=f"success rate ({rl['eval_episodes']} episodes)",
        ylim=(-0.02, 1.02),
        title=f"{rl['task']} in {rl['world']}, {rl['seeds']} seeds (95 % bootstrap CI)",
    )
    curves.legend(loc="upper left", fontsize="small")
    worlds = [rl["world"], *rl["transfer"]]
    names = list(rl["results"])
    width = 0.8 / len(worlds)
    for k, world in enumerate(worlds):
        stats = [
            r["success"] if world == rl["world"] else r["transfer"][world]["success"]
            for r in rl["results"].values()
        ]
        mean = np.array([s["mean"] for s in stats])
        err = np.array(
            [[m - s["ci_low"], s["ci_high"] - m] for m, s in zip(mean, stats, strict=True)]
        ).T
        x = np.arange(len(names)) + (k - (len(worlds) - 1) / 2) * width
        bars.bar(x, mean, width, yerr=err, capsize=2, label=world, alpha=1.0 - 0.25 * k)
    bars.set_xticks(np.arange(len(names)), names, rotation=30)
    bars.set(ylabel="final success rate", ylim=(0, 1.05), title="final policy, by world")
    bars.legend(fontsize="small")
    return fig


def plot_rl(rl: dict, path: str | Path) -> list[Path]:
    """Write ``rl_figure(rl)`` as a PNG at ``path`` (atomically)."""
    return save_figure(rl_figure(rl), path)
