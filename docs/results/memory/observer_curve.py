"""How fast the ideal observer finds the room: its likeliest room against the true one at each
step since it started knowing nothing, over windows of a database's test split, with and
without the commands (``analysis.observer``; docs/results/memory/README.md, "An ideal
observer").

    python docs/results/memory/observer_curve.py rooms1_fresh1.npz --out observer/curve_rooms1
    python docs/results/memory/observer_curve.py --plot observer/curve_rooms*.npz --png observer/curve.png
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np

from sensorimotor.analysis.observer import PARTICLES, observe
from sensorimotor.analysis.probes import BURN_IN
from sensorimotor.sim.database import load_database

GOALS = {"rooms1": 0.90, "rooms2": 0.85}  # the issue's, set before any Rec-SMA was trained


VARIANTS = {"commands": True, "blind": False}  # name -> does the observer read the commands


def windows(data: str, n: int, length: int, particles: int, names=tuple(VARIANTS)) -> dict:
    """(W, L) bool: is the observer's likeliest room the true one, for each window and step,
    with and without the commands; windows evenly spaced over the test split."""
    db = load_database(data)
    test, world = db.take("test"), db.world
    starts = np.linspace(0, len(test) - length, n).astype(int)
    out = {"starts": starts, "world": world.name, "particles": particles}
    for name in names:
        commands = VARIANTS[name]
        right = np.zeros((n, length), dtype=bool)
        inside = np.zeros((n, length), dtype=bool)
        began = time.time()
        for w, s in enumerate(starts):
            rows = slice(s, s + length)
            belief = observe(world, test.sensors[rows], test.motors[rows], db.layout, commands,
                             particles, seed=w)  # fmt: skip
            room = world.room_index(test.poses[rows, 0], test.poses[rows, 1])
            right[w], inside[w] = belief[:, 4:].argmax(axis=1) == room, room >= 0
            print(f"{name} window {w + 1}/{n}  {time.time() - began:.0f} s", flush=True)
        out[name], out[f"{name}_inside"] = right, inside
    return out


def share_right(right: np.ndarray, inside: np.ndarray) -> np.ndarray:
    """(L,) the share of windows, at each step, whose likeliest room is right (steps outside
    every room left out)."""
    return (right & inside).sum(axis=0) / np.maximum(inside.sum(axis=0), 1)


def plot(files: list[str], png: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = [np.load(f, allow_pickle=False) for f in files]
    worlds = list(dict.fromkeys(str(d["world"]) for d in runs))
    fig, axes = plt.subplots(1, len(worlds), figsize=(5.2 * len(worlds), 3.6), squeeze=False)
    styles = iter(("-", "--", ":", "-."))
    style = {n: next(styles) for n in sorted({int(d["particles"]) for d in runs})}
    for ax, world in zip(axes[0], worlds, strict=True):
        for d in (d for d in runs if str(d["world"]) == world):
            n = int(d["particles"])
            for name, colour, label in (
                ("commands", "tab:blue", "with the commands"),
                ("blind", "tab:orange", "without (draws them from the behaviour)"),
            ):
                if name in d:
                    ax.plot(share_right(d[name], d[f"{name}_inside"]), color=colour,
                            ls=style[n], lw=1.2, label=f"{label}, {n:,} particles")  # fmt: skip
        ax.axvline(BURN_IN, color="grey", ls=":", label=f"the probes' burn-in ({BURN_IN})")
        ax.axhline(GOALS[world], color="k", ls="--", lw=0.8, label=f"the goal ({GOALS[world]})")
        ax.set(title=f"{world}: {len(d['starts'])} windows of the fresh test split",
               xlabel="steps since the observer started", ylabel="likeliest room right (share)",
               ylim=(0, 1.02))  # fmt: skip
        ax.legend(fontsize=7, loc="lower right")
    fig.tight_layout()
    fig.savefig(png, dpi=120)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data", nargs="?")
    p.add_argument("--out", help="the .npz to write (without the suffix)")
    p.add_argument("--windows", type=int, default=24)
    p.add_argument("--length", type=int, default=1000)
    p.add_argument("--particles", type=int, default=PARTICLES)
    p.add_argument("--only", choices=tuple(VARIANTS), help="one observer, not both")
    p.add_argument("--plot", nargs="+", help="draw these .npz files instead")
    p.add_argument("--png", default="curve.png")
    a = p.parse_args()
    if a.plot:
        plot(a.plot, a.png)
        return
    names = (a.only,) if a.only else tuple(VARIANTS)
    out = windows(a.data, a.windows, a.length, a.particles, names)
    np.savez(a.out, **out)
    text = json.dumps(summary(out), indent=1, allow_nan=False)
    with open(f"{a.out}.json", "w") as f:
        f.write(text + "\n")
    print(text)


def summary(d) -> dict:
    """The share of steps whose likeliest room is right, from step k on (k = 0, 100, the
    burn-in, 500), for each observer in ``d`` (``windows``' output or its .npz)."""
    return {
        name: {
            f"after {k}": float(share_right(d[name], d[f"{name}_inside"])[k:].mean())
            for k in (0, 100, BURN_IN, 500)
        }
        for name in VARIANTS
        if name in d
    }


if __name__ == "__main__":
    main()
