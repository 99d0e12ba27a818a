"""Figures: plain functions that draw data on a matplotlib Axes and return it.

Every ``plot_*`` function takes the data and an optional ``ax``; it makes a Figure (a bare
``matplotlib.figure.Figure``, no pyplot, no backend) only when no Axes is given, and never
saves. ``*_figure`` functions assemble the paper's multi-panel figures from them, and
``save_figure`` writes a Figure to disk atomically.

Simulator figures (paper section IV):

- ``plot_world``: Fig. 1, the walls of a world.
- ``plot_trajectory``: Fig. 2, the path of the agent over the walls (10,000 steps in the paper).
- ``plot_perception``: Fig. 3, the agent, its heading and the 5 readings projected in top view
  as red dots; ``pick_situations`` finds the paper's five situations in a database.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from pathlib import Path

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from sensorimotor import events
from sensorimotor.data import Database, atomic_path, check_writable
from sensorimotor.sim import (
    MAX_RANGE,
    SENSOR_ANGLES,
    TURN_THRESHOLD,
    SensorLayout,
    hit_walls,
    read_sensors,
)
from sensorimotor.world import World, point_segment_distance

WALL_COLOR = "black"
WALL_WIDTH = 2.0  # points
PERCEPT_COLOR = "red"  # the paper's red dots
PANEL_SIZE = 3.2  # inches, one square panel of a multi-panel figure
CRAMPED_PENALTY = 100.0  # added to a situation's score when the agent is about to turn around

# The paper's five situations of Fig. 3, in its order, with its captions.
SITUATIONS = {
    "nothing": "Agent perceiving nothing",
    "line": "Agent in front of a line",
    "corner": "Agent in front of a corner",
    "wall at its left": "Agent with a wall at its left",
    "wall end": "Agent in front of a wall's end",
}


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


def _symmetric_score(sensors: np.ndarray, max_range: float) -> np.ndarray:
    """(N,) lower for a wall straight ahead at mid range: outer rays alike, middle at range/2."""
    return np.abs(sensors[:, 0] - sensors[:, -1]) + np.abs(sensors[:, 2] - max_range / 2)


def _bearing_score(
    world: World,
    poses: np.ndarray,
    points: np.ndarray,
    layout: SensorLayout,
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """(N,) for each pose, how central and mid-range its best visible point is (lower: better).

    points: (P, 2); ``allowed`` (N, P) bool further restricts which points count; a pose with
    none scores inf.
    """
    max_range = layout.max_range
    visible = events.points_in_view(world, poses, points, np.asarray(layout.angles), max_range)
    if allowed is not None:
        visible &= allowed
    dx = points[None, :, 0] - poses[:, 0, None]  # (N, P)
    dy = points[None, :, 1] - poses[:, 1, None]
    rel = np.remainder(np.arctan2(dy, dx) - poses[:, 2, None] + np.pi, 2 * np.pi) - np.pi
    score = np.abs(rel) + np.abs(np.hypot(dx, dy) - max_range / 2) / max_range  # (N, P)
    return np.where(visible, score, np.inf).min(axis=1)


def _near(poses: np.ndarray, points: np.ndarray, radius: float) -> np.ndarray:
    """(N,) bool: some point lies within ``radius`` of the pose's position."""
    if len(points) == 0:
        return np.zeros(len(poses), dtype=bool)
    d = np.hypot(points[None, :, 0] - poses[:, 0, None], points[None, :, 1] - poses[:, 1, None])
    return (d <= radius).any(axis=1)


def pick_situations(db: Database, max_rows: int = 200_000) -> dict[str, int]:
    """Rows of ``db`` showing the paper's five situations (Fig. 3), found by pose and readings.

    Situations are judged on the noiseless readings recomputed at each row's pose (so a noisy
    database works too), among the first ``max_rows`` rows; ``R`` is the range (10):

    - ``nothing``: every reading is R; the candidate farthest from every wall.
    - ``line``: all 5 rays hit the same wall segment (``sim.hit_walls``).
    - ``corner``: ``events.corner_in_view`` and every ray hits a wall, at least two walls hit.
    - ``wall at its left``: the two left rays hit a wall, the middle and the two right rays read
      R, no corner is in view and no free wall end is within R.
    - ``wall end``: a free wall end in view (``events.wall_end_in_view``) with some rays on its
      wall and some passing it; only worlds with inner walls have one.

    Among the candidates of ``line`` the row whose outer readings are most alike and whose
    middle reading is nearest R/2 wins; for ``corner`` and ``wall end``, the row that sees the
    corner (the end) nearest its middle ray and R/2; for ``wall at its left``, the leftmost
    reading nearest R/2. A row whose agent is within 1 of a wall (about to turn around) is
    taken only when there is no other. A situation that does not occur is left out of the
    result, which keeps the paper's order.
    """
    world, layout = db.world, db.layout
    max_range = layout.max_range
    n = min(len(db), max_rows)
    poses = np.asarray(db.poses[:n], dtype=np.float64)  # (N, 3)
    true = read_sensors(world, poses, layout)  # (N, 5) noiseless
    clearance = point_segment_distance(world.segments, poses[:, 0], poses[:, 1]).min(axis=1)
    nothing = events.nothing_in_view(true, max_range)
    all_hit = np.all(true < max_range * (1.0 - 1e-6), axis=1)  # (N,)
    left_hit = (true[:, 3] < max_range) & (true[:, 4] < max_range)  # (N,) index 4 leftmost
    right_free = np.all(true[:, :3] >= max_range, axis=1)  # the middle ray sees nothing too

    ends = events.free_wall_ends(world)  # (E, 2)
    found: dict[str, int] = {}

    def best(name: str, rows: np.ndarray, score: np.ndarray) -> None:
        score = score + CRAMPED_PENALTY * (clearance[rows] < TURN_THRESHOLD)
        if len(rows) and np.isfinite(score).any():
            found[name] = int(rows[np.argmin(score)])

    rows = np.flatnonzero(nothing)
    best("nothing", rows, -clearance[rows])

    rows = np.flatnonzero(all_hit)
    walls = hit_walls(world, poses[rows], layout)  # (M, 5)
    same = np.all(walls == walls[:, :1], axis=1)
    best("line", rows[same], _symmetric_score(true[rows[same]], max_range))

    corner = events.corner_in_view(world, poses[rows], layout) & ~same
    corners = events.corner_points(world)  # (C, 2)
    best("corner", rows[corner], _bearing_score(world, poses[rows[corner]], corners, layout))

    rows = np.flatnonzero(left_hit & right_free)
    clean = ~events.corner_in_view(world, poses[rows], layout) & ~_near(
        poses[rows], ends, max_range
    )
    best("wall at its left", rows[clean], np.abs(true[rows[clean], 4] - max_range / 2))

    if len(ends):
        rows = np.flatnonzero(events.wall_end_in_view(world, poses, layout))
        end_walls = point_segment_distance(world.segments, ends[:, 0], ends[:, 1]).argmin(axis=1)
        hit = hit_walls(world, poses[rows], layout)  # (M, 5) the wall each ray hits
        on = hit[:, :, None] == end_walls[None, None, :]  # (M, 5, E)
        straddled = on.any(axis=1) & ~on.all(axis=1)  # (M, E) some rays on the wall, some past
        score = _bearing_score(world, poses[rows], ends, layout, straddled)
        best("wall end", rows, score)

    return {name: found[name] for name in SITUATIONS if name in found}


# ------------------------------------------------------------------------ multi-panel figures


def _row_of_axes(n: int, aspect: float = 1.0) -> tuple[Figure, list[Axes]]:
    width, height = panel_size(aspect)
    fig = Figure(figsize=(width * n, height + 0.3), layout="constrained")
    return fig, list(np.atleast_1d(fig.subplots(1, n)))


def worlds_figure(worlds: Sequence[World]) -> Figure:
    """Paper Fig. 1: the worlds side by side."""
    fig, axes = _row_of_axes(len(worlds), world_aspect(worlds))
    for world, ax in zip(worlds, axes, strict=True):
        plot_world(world, ax)
    return fig


def trajectories_figure(dbs: Sequence[Database], steps: int = 10_000) -> Figure:
    """Paper Fig. 2: the first ``steps`` poses of each database over its world's walls."""
    fig, axes = _row_of_axes(len(dbs), world_aspect([db.world for db in dbs]))
    for db, ax in zip(dbs, axes, strict=True):
        plot_trajectory(db.world, db.poses[:steps], ax)
    return fig


def perception_figure(
    db: Database, situations: dict[str, int] | None = None, view: float | None = 7.5
) -> Figure:
    """Paper Fig. 3: each situation's row (``pick_situations`` by default) in a panel.

    ``situations`` maps a name to a row; a name of ``SITUATIONS`` gets the paper's caption. The
    red dots are the database's own readings at that row; ``view`` is the half-width of the
    window around the agent (units), ``None`` for the whole world.
    """
    situations = pick_situations(db) if situations is None else situations
    if not situations:
        raise ValueError("no situation to draw")
    world = db.world
    fig, axes = _row_of_axes(len(situations), 1.0 if view is not None else world_aspect([world]))
    for i, ((name, row), ax) in enumerate(zip(situations.items(), axes, strict=True)):
        plot_perception(
            world, db.poses[row], db.sensors[row], ax, db.layout.angles, db.max_range, view
        )
        caption = f"({chr(ord('a') + i)}) {SITUATIONS[name]}\n" if name in SITUATIONS else ""
        ax.set_title(f"{caption}{world.name}, row {row:,}", fontsize="medium")
    return fig


# --------------------------------------------------------------------------------- saving


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
        with atomic_path(target, f".{fmt}") as tmp, mpl.rc_context({"svg.hashsalt": "sm"}):
            fig.savefig(tmp, format=fmt, dpi=dpi)
        written.append(target)
    return written
