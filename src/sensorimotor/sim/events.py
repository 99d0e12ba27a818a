"""Ground-truth events computed from the true pose and the walls: what the agent has in view.

These back the paper's claims about the learned clusters (section V.D-V.F) with numbers: a
*corner* in view, a *free wall end* in view, *nothing* in view (every reading at the range), and
the *distance to the wall behind* (what a memory of the last wall seen could know). They use the
pose only, never the model; all take poses ``(N, 3)`` = ``x, y, heading`` (float32 or float64).

Definitions (the geometry of one world is its ``(S, 4)`` segment array):

- **Corner point**: where two walls meet: the 4 outer corners, every inner-wall end point lying
  on another wall (L- and T-junctions), and every crossing of two walls' interiors.
- **Free wall end**: an inner-wall end point that touches no other wall.
- **In view**: the point lies inside the sensor fan ``[heading - 0.6, heading + 0.6]``, no
  farther than the range (10), and the straight line from the agent to it is not blocked: the
  first wall hit along the ray toward it is at distance ``>= |p - point| - 1e-6`` (the point lies
  on its own walls, so that hit is the point itself).
- **Corner in view** also asks that the agent sees the corner *as a corner*: the agent must lie
  inside an angular sector narrower than pi between two of the walls meeting there (a concave
  corner, like the four of the square). This only matters for a T-junction seen from its flat
  side, which the lasers cannot tell from a plain wall, and for a convex corner seen from outside.
"""

from __future__ import annotations

import math

import numpy as np

from sensorimotor.sim.core import (
    DEFAULT_LAYOUT,
    MAX_RANGE,
    SENSOR_ANGLES,
    SensorLayout,
    read_sensors,
)
from sensorimotor.sim.world import World, point_segment_distance

TOUCH_TOL = 1e-6  # units; an end point this close to another wall touches it
SIGHT_TOL = 1e-6  # units; a first hit this much short of the point still counts as the point
FLAT_TOL = 1e-9  # rad; a sector this close to pi is a flat wall, not a corner
CHUNK = 131_072  # poses per block in points_in_view (bounds memory, not a result)


def _as_poses(poses: np.ndarray) -> np.ndarray:
    poses = np.asarray(poses, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise ValueError(f"poses must have shape (N, 3), got {poses.shape}")
    return poses


def _unique_points(points: list[tuple[float, float]]) -> np.ndarray:
    """(P, 2) float64 points in first-seen order, duplicates (within TOUCH_TOL) dropped."""
    kept: list[tuple[float, float]] = []
    for p in points:
        if all(math.hypot(p[0] - q[0], p[1] - q[1]) > TOUCH_TOL for q in kept):
            kept.append(p)
    return np.array(kept, dtype=np.float64).reshape(-1, 2)


def _inner_ends(world: World) -> tuple[np.ndarray, np.ndarray]:
    """Inner-wall end points (2 W, 2) and, for each, whether it touches another wall (2 W,)."""
    segments = world.segments
    n_outer = 4
    ends, touches = [], []
    for i in range(n_outer, len(segments)):
        others = np.delete(segments, i, axis=0)
        for x, y in (segments[i, :2], segments[i, 2:]):
            d = point_segment_distance(others, np.array([x]), np.array([y]))[0]
            ends.append((x, y))
            touches.append(bool((d <= TOUCH_TOL).any()))
    return np.array(ends, dtype=np.float64).reshape(-1, 2), np.array(touches, dtype=bool)


def _crossings(segments: np.ndarray, chunk: int = 256) -> list[tuple[float, float]]:
    """Points where the interiors of two segments cross (end points excluded), pair (i, j),
    i < j, in order; worked on ``chunk`` rows i at a time against every j (numpy)."""
    out = []
    ax, ay, bx, by = (segments[:, k] for k in range(4))
    ex, ey = bx - ax, by - ay
    n = len(segments)
    eps = 1e-9
    for lo in range(0, n, chunk):
        i = np.arange(lo, min(lo + chunk, n))[:, None]  # (C, 1)
        j = np.arange(n)[None, :]  # (1, S)
        denom = ex[i] * ey[j] - ey[i] * ex[j]  # (C, S)
        with np.errstate(divide="ignore", invalid="ignore"):
            s = ((ax[j] - ax[i]) * ey[j] - (ay[j] - ay[i]) * ex[j]) / denom  # along segment i
            u = ((ax[j] - ax[i]) * ey[i] - (ay[j] - ay[i]) * ex[i]) / denom  # along segment j
        ok = (
            (j > i)
            & (np.abs(denom) >= 1e-12)
            & (eps < s)
            & (s < 1 - eps)
            & (eps < u)
            & (u < 1 - eps)
        )
        for r, c in zip(*np.nonzero(ok), strict=True):
            out.append((ax[lo + r] + s[r, c] * ex[lo + r], ay[lo + r] + s[r, c] * ey[lo + r]))
    return out


def corner_points(world: World) -> np.ndarray:
    """(C, 2) points where two walls meet: outer corners, touching inner ends, crossings."""
    w, h = world.width, world.height
    points = [(0.0, 0.0), (w, 0.0), (w, h), (0.0, h)]
    ends, touches = _inner_ends(world)
    points += [tuple(p) for p in ends[touches]]
    points += _crossings(world.segments)
    return _unique_points([(float(x), float(y)) for x, y in points])


def free_wall_ends(world: World) -> np.ndarray:
    """(E, 2) inner-wall end points that touch no other wall."""
    ends, touches = _inner_ends(world)
    return _unique_points([(float(x), float(y)) for x, y in ends[~touches]])


def points_in_view(
    world: World,
    poses: np.ndarray,
    points: np.ndarray,
    angles: np.ndarray = SENSOR_ANGLES,
    max_range: float = MAX_RANGE,
) -> np.ndarray:
    """(N, P) bool: point p is inside pose n's sensor fan, within range, with a clear line of sight.

    The fan is ``[heading + min(angles), heading + max(angles)]``, or every direction for a
    layout spread over a full turn (its gap behind no wider than the gap between its rays). Candidates (in the fan, at
    distance ``0 < r <= max_range``) get one ray each, cast by ``sim.read_sensors`` toward the
    point; the point is visible when that ray's first hit is at ``>= r - SIGHT_TOL``.
    Cost: O(N P) numpy (in chunks of CHUNK poses) plus one numba ray per candidate; 100k poses
    take a few tens of ms.
    """
    poses = _as_poses(poses)
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    angles = np.asarray(angles, dtype=np.float64)
    visible = np.zeros((len(poses), len(points)), dtype=bool)
    if len(points) == 0:
        return visible
    layout = SensorLayout(angles=(0.0,), max_range=max_range + 1.0)  # one ray, past the point
    spread = angles.max() - angles.min()
    full_turn = len(angles) > 1 and 2 * np.pi - spread <= spread / (len(angles) - 1) + 1e-9
    for start in range(0, len(poses), CHUNK):
        p = poses[start : start + CHUNK]  # (C, 3)
        dx = points[None, :, 0] - p[:, 0, None]  # (C, P)
        dy = points[None, :, 1] - p[:, 1, None]  # (C, P)
        dist = np.hypot(dx, dy)  # (C, P)
        bearing = np.arctan2(dy, dx)  # (C, P) absolute direction of the point
        rel = np.remainder(bearing - p[:, 2, None] + np.pi, 2 * np.pi) - np.pi  # (C, P)
        cand = (rel >= angles.min() - 1e-12) & (rel <= angles.max() + 1e-12)
        cand |= full_turn  # the fan closes: the gap behind is no wider than between its rays
        cand &= (dist > 0) & (dist <= max_range)
        rows, cols = np.nonzero(cand)  # (K,) each
        if rows.size:
            rays = np.stack([p[rows, 0], p[rows, 1], bearing[rows, cols]], axis=1)  # (K, 3)
            hit = read_sensors(world, rays, layout)[:, 0]  # (K,)
            visible[start + rows, cols] = hit >= dist[rows, cols] - SIGHT_TOL
    return visible


def _wall_directions(world: World, point: np.ndarray) -> np.ndarray:
    """Sorted angles (K,) in [-pi, pi) of the walls leaving ``point``, one per wall side."""
    ax, ay, bx, by = (world.segments[:, k] for k in range(4))
    ex, ey = bx - ax, by - ay
    length2 = ex * ex + ey * ey
    u = ((point[0] - ax) * ex + (point[1] - ay) * ey) / length2
    u_c = np.minimum(np.maximum(u, 0.0), 1.0)
    near = np.hypot(ax + u_c * ex - point[0], ay + u_c * ey - point[1]) <= TOUCH_TOL
    length = np.sqrt(length2)
    back = near & (u * length > TOUCH_TOL)  # the wall runs back toward a
    on = near & ((1.0 - u) * length > TOUCH_TOL)  # the wall runs on toward b
    dirs = np.concatenate([np.arctan2(-ey[back], -ex[back]), np.arctan2(ey[on], ex[on])])
    return np.sort(np.remainder(dirs + np.pi, 2 * np.pi) - np.pi)


def _concave_side(world: World, poses: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(N, C) bool: pose n lies in a sector narrower than pi between walls meeting at corner c.

    Around a corner the walls leave in K sorted directions; the agent, seen from the corner, lies
    in one gap between two consecutive directions. The corner looks like a corner (two walls
    folding toward the agent) exactly when that gap is below pi.
    """
    out = np.zeros((len(poses), len(corners)), dtype=bool)
    for c, point in enumerate(corners):
        dirs = _wall_directions(world, point)
        if len(dirs) < 2:
            continue
        gaps = np.diff(np.append(dirs, dirs[0] + 2 * np.pi))  # gap k runs from dirs[k]
        phi = np.arctan2(poses[:, 1] - point[1], poses[:, 0] - point[0])  # (N,)
        k = np.searchsorted(dirs, phi, side="right") - 1  # -1 -> last gap (wraps around)
        out[:, c] = gaps[k] < np.pi - FLAT_TOL
    return out


def corner_in_view(
    world: World, poses: np.ndarray, layout: SensorLayout = DEFAULT_LAYOUT
) -> np.ndarray:
    """(N,) bool: some corner is in view of ``layout``'s lasers and seen as a concave corner
    (see the module docstring)."""
    poses = _as_poses(poses)
    corners = corner_points(world)
    seen = points_in_view(world, poses, corners, np.asarray(layout.angles), layout.max_range)
    return (seen & _concave_side(world, poses, corners)).any(axis=1)


def wall_end_in_view(
    world: World, poses: np.ndarray, layout: SensorLayout = DEFAULT_LAYOUT
) -> np.ndarray:
    """(N,) bool: some free wall end is in view of ``layout``'s lasers (always False in a world
    without inner walls)."""
    ends = free_wall_ends(world)
    seen = points_in_view(
        world, _as_poses(poses), ends, np.asarray(layout.angles), layout.max_range
    )
    return seen.any(axis=1)


def nothing_in_view(sensors: np.ndarray, max_range: float = MAX_RANGE) -> np.ndarray:
    """(N,) bool: every reading is at the range (the agent perceives nothing).

    ``sensors`` are the raw readings (N, R) in units, not scaled; a relative tolerance of 1e-6
    absorbs float32 storage.
    """
    sensors = np.asarray(sensors, dtype=np.float64)
    return np.all(sensors >= max_range * (1.0 - 1e-6), axis=1)


def distance_behind(world: World, poses: np.ndarray, max_range: float = math.inf) -> np.ndarray:
    """(N,) distance from each pose straight backwards (heading + pi) to the first wall.

    ``max_range`` caps it (infinite by default: in a closed world a wall is always behind).
    """
    poses = _as_poses(poses)
    layout = SensorLayout(angles=(math.pi,), max_range=float(max_range))
    return read_sensors(world, poses, layout)[:, 0]
