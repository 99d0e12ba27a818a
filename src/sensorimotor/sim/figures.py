"""The paper's figures of the simulator (section IV), assembled from ``sim.plots``: Fig. 1, the
worlds; Fig. 2, 10,000 steps of trajectory in each; Fig. 3, what the agent perceives in five
situations, which ``pick_situations`` finds in a database by pose and readings.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from matplotlib.axes import Axes
from matplotlib.figure import Figure

from sensorimotor.sim import events
from sensorimotor.sim.core import TURN_THRESHOLD, SensorLayout, hit_walls, read_sensors
from sensorimotor.sim.database import Database
from sensorimotor.sim.plots import (
    panel_size,
    plot_perception,
    plot_trajectory,
    plot_world,
    world_aspect,
)
from sensorimotor.sim.world import World, point_segment_distance

CRAMPED_PENALTY = 100.0  # added to a situation's score when the agent is about to turn around

# The paper's five situations of Fig. 3, in its order, with its captions.
SITUATIONS = {
    "nothing": "Agent perceiving nothing",
    "line": "Agent in front of a line",
    "corner": "Agent in front of a corner",
    "wall at its left": "Agent with a wall at its left",
    "wall end": "Agent in front of a wall's end",
}


def _symmetric_score(sensors: np.ndarray, max_range: float, middle: int = 2) -> np.ndarray:
    """(N,) lower for a wall straight ahead at mid range: outer rays alike, the ray ``middle``
    (the one nearest straight ahead) at range/2."""
    return np.abs(sensors[:, 0] - sensors[:, -1]) + np.abs(sensors[:, middle] - max_range / 2)


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
    - ``line``: every ray hits the same wall segment (``sim.hit_walls``).
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
    true = read_sensors(world, poses, layout)  # (N, R) noiseless
    clearance = point_segment_distance(world.segments, poses[:, 0], poses[:, 1]).min(axis=1)
    nothing = events.nothing_in_view(true, max_range)
    all_hit = np.all(true < max_range * (1.0 - 1e-6), axis=1)  # (N,)
    angles = np.asarray(layout.angles)  # (R,) counter-clockwise: positive to the left
    middle, leftmost = int(np.argmin(np.abs(angles))), int(np.argmax(angles))
    left_hit = np.all(true[:, angles > 0] < max_range, axis=1)  # (N,) every ray to the left
    right_free = np.all(true[:, angles <= 0] >= max_range, axis=1)  # straight ahead too

    ends = events.free_wall_ends(world)  # (E, 2)
    found: dict[str, int] = {}

    def best(name: str, rows: np.ndarray, score: np.ndarray) -> None:
        score = score + CRAMPED_PENALTY * (clearance[rows] < TURN_THRESHOLD)
        if len(rows) and np.isfinite(score).any():
            found[name] = int(rows[np.argmin(score)])

    rows = np.flatnonzero(nothing)
    best("nothing", rows, -clearance[rows])

    rows = np.flatnonzero(all_hit)
    walls = hit_walls(world, poses[rows], layout)  # (M, R)
    same = np.all(walls == walls[:, :1], axis=1)
    best("line", rows[same], _symmetric_score(true[rows[same]], max_range, middle))

    corner = events.corner_in_view(world, poses[rows], layout) & ~same
    corners = events.corner_points(world)  # (C, 2)
    best("corner", rows[corner], _bearing_score(world, poses[rows[corner]], corners, layout))

    rows = np.flatnonzero(left_hit & right_free)
    clean = ~events.corner_in_view(world, poses[rows], layout) & ~_near(
        poses[rows], ends, max_range
    )
    best("wall at its left", rows[clean], np.abs(true[rows[clean], leftmost] - max_range / 2))

    if len(ends):
        rows = np.flatnonzero(events.wall_end_in_view(world, poses, layout))
        end_walls = point_segment_distance(world.segments, ends[:, 0], ends[:, 1]).argmin(axis=1)
        hit = hit_walls(world, poses[rows], layout)  # (M, R) the wall each ray hits
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


# ---------------------------------------------------------------- real data (reproduce real)


def real_path_figure(log, db: Database, every: int = 5, within: float = 20.0) -> Figure:
    """A real robot's recording (an MRPT rawlog and its imported database): left, the end
    points of the valid beams under ``within`` m of every ``every``-th scan, drawn from the
    odometry pose, over the laser's path; right, the layout's readings along the rows."""
    from sensorimotor.sim.mrpt import Odometry, Scan, compose, inverse_compose, read_rawlog

    entries, _ = read_rawlog(log)
    odo, first, points, scans = (0.0, 0.0, 0.0), None, [], 0
    for entry in entries:
        for item in entry if isinstance(entry, list) else [entry]:
            if isinstance(item, Scan):
                scans += 1
                x, y, yaw = compose(odo, item.sensor)
                n = len(item.ranges)
                a = -item.aperture / 2 + np.arange(n) * item.aperture / max(n - 1, 1)
                if not item.right_to_left:
                    a = -a
                ok = item.valid & (item.ranges < within) & (item.ranges > 0)
                r = item.ranges[ok]
                points.append(
                    np.stack([x + r * np.cos(yaw + a[ok]), y + r * np.sin(yaw + a[ok])], 1)
                )
            elif isinstance(item, Odometry) and item.absolute:  # import_rawlog's rule
                first = item.pose if first is None else first
                odo = inverse_compose(item.pose, first)
            elif isinstance(item, Odometry):
                odo = compose(odo, item.pose)
    pts = np.concatenate(points[::every]) if points else np.zeros((0, 2))
    fig = Figure(figsize=(13, 5.5), layout="constrained")
    ax, bx = fig.subplots(1, 2, gridspec_kw={"width_ratios": [1, 1.3]})
    ax.scatter(pts[:, 0], pts[:, 1], s=0.3, c="0.55", lw=0,
               label=f"laser end points (every {every}th scan)")  # fmt: skip
    ax.plot(db.poses[:, 0], db.poses[:, 1], "C0-", lw=1.5, label="odometry path (laser)")
    ax.plot(*db.poses[0, :2], "go", label="start")
    ax.plot(*db.poses[-1, :2], "rs", label="end")
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, odometry frame)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{db.meta['world']['name']}: {scans:,} scans")
    ax.legend(loc="upper left", fontsize=7)
    im = bx.imshow(db.sensors.T, aspect="auto", cmap="viridis", interpolation="nearest")
    angles = db.layout.angles
    bx.set_yticks(range(len(angles)), [f"{a:g}" for a in angles])
    bx.set_ylabel("ray (rad)")
    rate = db.meta.get("source", {}).get("rate_hz")
    bx.set_xlabel(f"row ({rate:.2g} Hz)" if rate else "row")
    bx.set_title(f"the {len(angles)} kept rays' readings (capped at {db.max_range:g})")
    fig.colorbar(im, ax=bx, fraction=0.04)
    return fig


def campus_figure(
    world: World, db: Database, steps: int = 100_000, trapped: int | None = None
) -> Figure:
    """A large world's walls (thin lines) with the first ``steps`` poses of ``db`` in it; where
    the agent was found trapped from row ``trapped`` on, a red ring there, labelled (the trap
    may lie past the rows drawn)."""
    from matplotlib.collections import LineCollection

    steps = min(steps, len(db))
    aspect = world.height / world.width
    fig = Figure(figsize=(7, max(3.0, 7 * aspect)), layout="constrained")
    ax = fig.subplots()
    w = np.asarray(world.walls)
    ax.add_collection(LineCollection(w.reshape(-1, 2, 2), colors="k", linewidths=0.4))
    ax.plot(db.poses[:steps, 0], db.poses[:steps, 1], "C0-", lw=0.15, alpha=0.7)
    if trapped is not None:
        x, y = (float(v) for v in db.poses[trapped, :2])
        ax.plot(x, y, "o", ms=12, mfc="none", mec="red", mew=2)
        right = x < world.width / 2  # the label towards the middle, inside the axes
        ax.annotate(
            f"trapped from step {trapped:,}\n({x:.1f}, {y:.1f})",
            (x, y),
            xytext=(18 if right else -18, 18 if y < world.height / 2 else -18),
            textcoords="offset points",
            ha="left" if right else "right",
            va="bottom" if y < world.height / 2 else "top",
            color="red",
            fontsize=9,
            bbox={"boxstyle": "round", "fc": "white", "ec": "red", "alpha": 0.9},
            arrowprops={"arrowstyle": "-", "color": "red", "lw": 1},
        )
    ax.set_xlim(0, world.width)
    ax.set_ylim(0, world.height)
    ax.set_aspect("equal")
    seed = db.meta.get("seed")
    ax.set_title(f"{world.name}: {len(w):,} walls, {steps:,} simulated steps (seed {seed})")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    return fig
