"""Figures: plain functions that draw data on a matplotlib Axes and return it.

Every ``plot_*`` function takes the data and an optional ``ax``; it makes a Figure (a bare
``matplotlib.figure.Figure``, no pyplot, no backend) only when no Axes is given, and never
saves; ``save_figure`` writes a Figure to disk atomically. ``sim.figures`` assembles the
paper's multi-panel figures from these; the Gymnasium environment renders with them.

Simulator figures (paper section IV):

- ``plot_world``: Fig. 1, the walls of a world.
- ``plot_trajectory``: Fig. 2, the path of the agent over the walls (10,000 steps in the paper).
- ``plot_perception``: Fig. 3, the agent, its heading and its readings projected in top view
  as red dots.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from sensorimotor.files import atomic_path, check_writable
from sensorimotor.sim.core import (
    MAX_RANGE,
    SENSOR_ANGLES,
)
from sensorimotor.sim.world import World

WALL_COLOR = "black"
WALL_WIDTH = 2.0  # points
PERCEPT_COLOR = "red"  # the paper's red dots
PANEL_SIZE = 3.2  # inches, one square panel of a multi-panel figure


def panel_size(aspect: float, size: float = PANEL_SIZE, labels: float = 0.6) -> tuple[float, float]:
    """(width, height) in inches of a panel showing a region ``aspect`` = height / width: its
    longer side ``size``, plus up to ``labels`` inches along the shorter one for the tick labels
    that a flat panel would otherwise squeeze, and a tall one at least 0.7 ``size`` wide for its
    title (a square region: ``size`` by ``size``)."""
    if aspect >= 1:
        return max(size / aspect + labels * (1 - 1 / aspect), 0.7 * size), size
    return size, size * aspect + labels * (1 - aspect)


def world_aspect(worlds: Sequence[World]) -> float:
    """The height / width of the tallest of ``worlds``, for panels that show them whole."""
    return max(w.height / w.width for w in worlds)


def _new_axes(ax: Axes | None, aspect: float = 1.0) -> Axes:
    """``ax`` itself, or the Axes of a new single-panel Figure for a region of ``aspect``."""
    if ax is not None:
        return ax
    return Figure(figsize=panel_size(aspect), layout="constrained").add_subplot()


# --------------------------------------------------------------------------- simulator figures


def plot_world(world: World, ax: Axes | None = None) -> Axes:
    """Paper Fig. 1: the walls of ``world``, one line per segment (``gid="wall"``).

    The axis limits are the world, the aspect ratio is equal, and the title is the world's name.
    Walls are drawn unclipped so the outer ones are not cut in half by the axis frame.
    """
    ax = _new_axes(ax, world_aspect([world]))
    for x0, y0, x1, y1 in world.segments:
        ax.plot(
            [x0, x1],
            [y0, y1],
            color=WALL_COLOR,
            lw=WALL_WIDTH,
            solid_capstyle="projecting",
            clip_on=False,
            gid="wall",
            zorder=3,
        )
    ax.set_xlim(0, world.width)
    ax.set_ylim(0, world.height)
    ax.set_aspect("equal")
    ax.set_xticks(np.linspace(0, world.width, 3))
    ax.set_yticks(np.linspace(0, world.height, 3))
    ax.tick_params(labelsize="small", length=2)
    for spine in ax.spines.values():
        spine.set_visible(False)
    ax.set_title(world.name)
    return ax


def plot_trajectory(world: World, poses: np.ndarray, ax: Axes | None = None) -> Axes:
    """Paper Fig. 2: the agent's path through ``poses`` (T, 3) over the walls (``gid="path"``)."""
    poses = np.asarray(poses)
    ax = plot_world(world, ax)
    ax.plot(poses[:, 0], poses[:, 1], color="tab:blue", lw=0.35, alpha=0.8, gid="path", zorder=2)
    ax.set_title(f"{world.name}: {len(poses):,} steps")
    return ax


def plot_perception(
    world: World,
    pose: Sequence[float] | np.ndarray,
    sensors: Sequence[float] | np.ndarray,
    ax: Axes | None = None,
    angles: np.ndarray = SENSOR_ANGLES,
    max_range: float = MAX_RANGE,
    view: float | None = None,
) -> Axes:
    """Paper Fig. 3: the agent at ``pose`` (x, y, heading) and its readings ``sensors`` (5,).

    Each reading is projected in top view: a red dot at distance ``sensors[i]`` along ray
    ``heading + angles[i]`` (one scatter, ``gid="percept"``), filled where a wall was hit and
    hollow where the ray saw nothing (the reading is the range). The rays are faint lines
    (``gid="ray"``); the agent is a black dot with an arrow along its heading. ``view`` (units)
    zooms to a square window of half-width ``view`` around the sensor fan (0.75 of the range
    shows all of it); ``None`` shows the whole world.
    """
    x, y, heading = (float(v) for v in np.asarray(pose, dtype=np.float64)[:3])
    sensors = np.asarray(sensors, dtype=np.float64)
    directions = heading + np.asarray(angles, dtype=np.float64)  # (R,)
    hx = x + sensors * np.cos(directions)  # (R,) perceived points
    hy = y + sensors * np.sin(directions)
    if ax is None and view is not None:
        ax = _new_axes(None)  # a square window, whatever the world's shape
    ax = plot_world(world, ax)
    for px, py in zip(hx, hy, strict=True):
        ax.plot([x, px], [y, py], color="0.6", lw=0.6, alpha=0.8, gid="ray", zorder=2)
    hit = sensors < max_range * (1.0 - 1e-6)
    ax.scatter(
        hx,
        hy,
        s=18,
        facecolors=[PERCEPT_COLOR if h else "none" for h in hit],
        edgecolors=PERCEPT_COLOR,
        linewidths=1.0,
        gid="percept",
        zorder=5,
    )
    arrow = 0.25 * max_range  # heading arrow length (units)
    ax.annotate(
        "",
        xy=(x + arrow * math.cos(heading), y + arrow * math.sin(heading)),
        xytext=(x, y),
        arrowprops={"arrowstyle": "-|>", "color": "black", "lw": 1.2, "shrinkA": 0, "shrinkB": 0},
        zorder=4,
    )
    ax.plot([x], [y], "o", color="black", ms=4, gid="agent", zorder=4)
    if view is not None:
        _zoom(ax, world, x, y, heading, view)
    return ax


def _zoom(ax: Axes, world: World, x: float, y: float, heading: float, half: float) -> None:
    """Limit ``ax`` to a square of half-width ``half`` around the middle of the sensor fan.

    The window's centre is ``half * 2/3`` ahead of the agent, so the agent and every point
    within the range ahead fit when ``half`` is about 0.75 of the range. What lies outside the
    world is shaded.
    """
    cx = x + (2 / 3) * half * math.cos(heading)
    cy = y + (2 / 3) * half * math.sin(heading)
    ax.set_xlim(cx - half, cx + half)
    ax.set_ylim(cy - half, cy + half)
    ax.set_facecolor("0.88")  # outside the world
    ax.add_patch(mpl.patches.Rectangle((0, 0), world.width, world.height, color="white", zorder=0))
    for axis in (ax.xaxis, ax.yaxis):
        axis.set_major_locator(mpl.ticker.MaxNLocator(4, integer=True))
    for line in ax.get_lines():
        line.set_clip_on(True)  # walls run on beyond the window
    for spine in ax.spines.values():
        spine.set_visible(True)
        spine.set_color("0.7")


# ------------------------------------------------------------------------ Fig. 3's situations


def save_figure(fig: Figure, path: str | Path, svg: bool = False, dpi: int = 150) -> list[Path]:
    """Write ``fig`` as PNG at ``path`` (and as SVG beside it when ``svg``); return the paths.

    Each file is written to a temporary file in the same folder and renamed into place, so a
    reader never sees half a figure. A missing or unwritable folder is an InputError.
    """
    path = Path(path)
    written = []
    targets = [(path, "png")] + ([(path.with_suffix(".svg"), "svg")] if svg else [])
    for target, _ in targets:  # before writing any: no PNG without its SVG
        check_writable(target)
    for target, fmt in targets:
        with atomic_path(target, f".{fmt}") as tmp, mpl.rc_context({"svg.hashsalt": "sensorimotor"}):
            fig.savefig(tmp, format=fmt, dpi=dpi)
        written.append(target)
    return written
