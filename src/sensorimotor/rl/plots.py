"""The figure of ``sensorimotor rl``: learning curves and final scores per feature set."""

from __future__ import annotations

import itertools
from pathlib import Path

import numpy as np
from matplotlib.figure import Figure

from sensorimotor.learn.models import REC_S, REC_SM, REC_SMA, SM, S
from sensorimotor.learn.runs import count
from sensorimotor.sim.plots import save_figure

COLORS = {
    "pose": "black",
    "raw": "tab:gray",
    S: "tab:blue",
    SM: "tab:orange",
    REC_S: "tab:green",
    REC_SM: "tab:red",
    REC_SMA: "tab:brown",
    "random": "tab:purple",
    "pose+raw": "darkgoldenrod",
}
SPARE = ("tab:pink", "tab:olive", "tab:cyan", "gold")  # a feature set without a colour


def colors(names) -> dict[str, str]:
    """A colour per feature set: ``COLORS``'s, else the next of ``SPARE``, in turn."""
    spare = itertools.cycle(SPARE)
    return {n: COLORS[n] if n in COLORS else next(spare) for n in names}


def rl_figure(rl: dict) -> Figure:
    """Left: success rate against environment steps, mean over seeds with its 95 % interval
    (``stats.interval``; none with one seed) as a band, one colour per feature set; solid: the
    deterministic policy, dashed: the stochastic one. Middle and right: final success per
    feature set (bars: mean, whiskers: CI) in the task's world and in each transfer world,
    deterministic then stochastic policy."""
    fig = Figure(figsize=(15, 4.2), layout="constrained")
    curves, *bars = fig.subplots(1, 3, width_ratios=[3, 2, 2])
    palette = colors(rl["results"])
    for name, r in rl["results"].items():
        c = r["curve"]
        steps = np.asarray(c["steps"])
        color = palette[name]
        for score, style in (("success", "-"), ("success_stochastic", "--")):
            curves.plot(steps, c[score]["mean"], style, color=color,
                        label=name if style == "-" else None)  # fmt: skip
            low, high = (_or_mean(c[score][k], c[score]["mean"]) for k in ("ci_low", "ci_high"))
            curves.fill_between(steps, low, high, color=color, alpha=0.12)
    curves.set(
        xlabel="environment steps",
        ylabel=f"success rate ({rl['eval_episodes']} episodes)",
        ylim=(-0.02, 1.02),
        title=f"{rl['task']} in {rl['world']}, {count(rl['seeds'], 'seed')}: deterministic "
        "(solid), stochastic (dashed)",
    )
    curves.title.set_fontsize("medium")
    curves.legend(loc="upper left", fontsize="small")
    for ax, score, how in zip(
        bars, ("success", "success_stochastic"), ("deterministic", "stochastic"), strict=True
    ):
        _final_bars(ax, rl, score)
        what = "95 % CI" if rl["seeds"] > 1 else "one seed, no interval"
        ax.set_title(f"final {how} policy, {what}", fontsize="medium")
    return fig


def _or_mean(bounds: list, mean) -> np.ndarray:
    """Interval bounds with the mean where there is none (one seed: no interval, no band)."""
    return np.array([m if b is None else b for b, m in zip(bounds, mean, strict=True)], float)


def _final_bars(ax, rl: dict, score: str) -> None:
    worlds = [rl["world"], *rl["transfer"]]
    names = list(rl["results"])
    width = 0.8 / len(worlds)
    for k, world in enumerate(worlds):
        stats = [
            r[score] if world == rl["world"] else r["transfer"][world][score]
            for r in rl["results"].values()
        ]
        mean = np.array([s["mean"] for s in stats])
        low = _or_mean([s["ci_low"] for s in stats], mean)
        high = _or_mean([s["ci_high"] for s in stats], mean)
        err = np.clip([mean - low, high - mean], 0.0, None)  # no rounding below 0
        x = np.arange(len(names)) + (k - (len(worlds) - 1) / 2) * width
        shown = {"yerr": err, "capsize": 2} if rl["seeds"] > 1 else {}  # one seed: no whiskers
        ax.bar(x, mean, width, label=world, **shown)
    ax.set_xticks(np.arange(len(names)), names, rotation=30)
    ax.set(ylabel="final success rate", ylim=(0, 1.05))
    ax.legend(fontsize="small")


def plot_rl(rl: dict, path: str | Path) -> list[Path]:
    """Write ``rl_figure(rl)`` as a PNG at ``path`` (atomically)."""
    return save_figure(rl_figure(rl), path)
