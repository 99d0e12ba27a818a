"""Figures of the map: the place fields of its states and its graph laid over the walls."""

from __future__ import annotations

import matplotlib as mpl
import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from scipy.sparse import coo_matrix, triu

from sensorimotor.sim.plots import PANEL_SIZE, plot_world, world_aspect
from sensorimotor.sim.world import World

N_FIELDS = 24  # place fields drawn: the most occupied states
MAX_DOTS = 4_000  # positions drawn per field (evenly thinned)
BOX_NOTE = "walls unknown: dashed = the bounding box of the robot's path"


def _box(world: World, ax: Axes) -> None:
    """The dashed frame of a world of unknown walls: the bounding box of the path, not a wall
    (``plot_world``'s outer walls of it are taken away)."""
    for line in [line for line in ax.lines if line.get_gid() == "wall"]:
        line.remove()
    frame = mpl.patches.Rectangle(
        (0, 0), world.width, world.height, fill=False, ls="--", lw=0.8, ec="0.4", zorder=0
    )
    ax.add_patch(frame)


def plot_place_fields(
    world: World,
    poses: np.ndarray,
    states: np.ndarray,
    occupancy: np.ndarray,
    title: str,
    n: int = N_FIELDS,
    bounding_box: bool = False,
) -> Figure:
    """The positions (``poses`` (N, 3)) of the steps whose most probable state (``states``
    (N,)) is each of the ``n`` states with the largest ``occupancy`` (S,): one panel each.
    ``bounding_box``: the walls are unknown (a recording): the frame drawn is the box of the
    path, dashed, and the title says so."""
    top = [int(s) for s in np.argsort(-occupancy, kind="stable")[:n] if occupancy[s] > 0]
    cols = 6
    rows = max(1, -(-len(top) // cols))
    aspect = world_aspect([world])
    fig = Figure(figsize=(cols * PANEL_SIZE * 0.6, rows * PANEL_SIZE * 0.6 * aspect + 0.6))
    fig.set_layout_engine("constrained")
    axes = fig.subplots(rows, cols, squeeze=False)
    for ax in axes.ravel():
        ax.set_axis_off()
    for ax, s in zip(axes.ravel(), top, strict=False):
        plot_world(world, ax)
        if bounding_box:
            _box(world, ax)
        ax.set_axis_on()
        ax.set_xticks([])
        ax.set_yticks([])
        where = np.flatnonzero(states == s)
        where = where[:: max(1, len(where) // MAX_DOTS)]
        dot = 1 if len(where) > 1_000 else 4  # sparse fields in bigger dots, to be seen
        ax.scatter(poses[where, 0], poses[where, 1], s=dot, color="tab:red", alpha=0.4, lw=0)
        ax.set_title(f"state {s}: {len(np.flatnonzero(states == s)):,} steps", fontsize="small")
    note = f"\n({BOX_NOTE})" if bounding_box else ""
    fig.suptitle(f"{title}: place fields of the {len(top)} most occupied states (test split){note}")
    return fig


def plot_map_graph(
    world: World,
    positions: np.ndarray,
    weights: np.ndarray,
    active: np.ndarray,
    community: np.ndarray,
    occupancy: np.ndarray,
    title: str,
    ax: Axes | None = None,
    bounding_box: bool = False,
) -> Axes:
    """The map's states at their mean positions (S, 2) over the walls, coloured by community,
    sized by occupancy; an edge for each pair of states with transitions (``weights`` (S, S),
    dense or scipy sparse, both directions summed), darker the more often it is taken.
    ``bounding_box``: as for ``plot_place_fields``."""
    if ax is None:
        ax = Figure(figsize=(6.5, 6.5 * world_aspect([world])), layout="constrained").add_subplot()
    plot_world(world, ax)
    if bounding_box:
        _box(world, ax)
    w = coo_matrix(weights)
    w = triu(w + w.T, k=1).tocoo()  # both directions summed, no self-loops
    i, j, v = w.row[w.data > 0], w.col[w.data > 0], w.data[w.data > 0]
    if len(i):
        strength = np.log1p(v) / np.log1p(v.max())
        segments = np.stack([positions[i], positions[j]], axis=1)  # (E, 2, 2)
        lines = mpl.collections.LineCollection(
            segments, colors=[(0.2, 0.2, 0.2, 0.05 + 0.6 * a) for a in strength], lw=0.6, zorder=1
        )
        ax.add_collection(lines)
    s = np.flatnonzero(active)
    colours = mpl.colormaps["tab20"](community[s] % 20)
    size = 8 + 60 * occupancy[s] / max(occupancy[s].max(), 1e-12)
    ax.scatter(
        positions[s, 0], positions[s, 1], s=size, c=colours, edgecolors="k", lw=0.3, zorder=2
    )
    note = f"\n({BOX_NOTE})" if bounding_box else ""
    ax.set_title(f"{title}, {int(community.max()) + 1} communities{note}")
    return ax


def plot_plans(
    world: World, traces: list, radius: float, title: str, true_pose: list | None = None
) -> Figure:
    """One panel per planned episode: its trajectory, start (circle) and goal (its disc); with
    ``true_pose`` (the true-pose planner's episodes on the same pairs, as ``traces``), its
    trajectory in grey beneath and its steps in the title."""
    n = max(1, len(traces))
    aspect = world_aspect([world])
    fig = Figure(figsize=(n * PANEL_SIZE, PANEL_SIZE * aspect + 0.5), layout="constrained")
    axes = fig.subplots(1, n, squeeze=False)[0]
    others = true_pose if true_pose is not None else [None] * len(traces)
    for ax, (path, goal, steps), other in zip(axes, traces, others, strict=False):
        plot_world(world, ax)
        ax.add_patch(mpl.patches.Circle(goal, radius, color="tab:green", alpha=0.3, lw=0))
        if other is not None:
            ax.plot(other[0][:, 0], other[0][:, 1], color="0.5", lw=1.2, ls="--")
        ax.plot(path[:, 0], path[:, 1], color="tab:blue", lw=0.8)
        ax.plot(*path[0], "o", color="tab:blue", ms=5)
        done = f"goal in {steps} steps" if steps is not None else "goal not reached"
        if other is not None:
            done += f" (true pose: {'not reached' if other[2] is None else other[2]})"
        ax.set_title(done, fontsize="small")
    fig.suptitle(title)
    return fig
