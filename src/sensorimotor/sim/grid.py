"""A uniform grid over the walls: ray casting whose cost grows with the walls near a ray.

The all-walls loop (``core._cast_many``) tests every ray against every wall; in a world of
thousands of walls almost all of those tests are misses far away. Here the world's rectangle
is cut into square cells, each listing the walls that pass through it (compressed: ``start``
(C + 1,) int64 offsets into ``items`` (M,) int32 wall rows, cell ``c = iy * nx + ix``), and a
ray walks the cells it crosses in order (Amanatides & Woo's traversal), testing only their
walls, and stops at the first cell whose far side lies beyond the nearest hit so far.

**Same bits as the all-walls loop.** A ray-wall test is the same arithmetic in the same order
as ``core._cast_many`` (shared ``_hit``), so every candidate distance is the same float; the
reading is their minimum, which does not depend on the order in which they are met. What can
differ is only which walls are tested, and every wall that could give the minimum is: a wall
is listed in every cell whose square, grown by ``PAD`` of a cell on each side, it touches, so
a hit point lying within rounding of a cell's edge is listed on both sides; and the walk stops
only once the best distance is at most where the ray leaves the current cell, beyond which
every untested hit lies farther (by more than rounding, thanks to the padding). A wall met in
several cells is tested once per ray (a stamp per wall).

Small worlds (fewer than ``GRID_MIN_WALLS`` walls, the paper's have 4 to 8) get no grid: the
all-walls loop is faster there, and their readings are the same bits either way.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numba
import numpy as np

GRID_MIN_WALLS = 16  # walls; below this the all-walls loop is faster (benchmarks/bench_sim.py)
WALLS_PER_CELL = 1.0  # cells ~ walls / this: the cell side that the benchmark found fastest
MAX_CELLS = 1 << 22  # a bound on the index's memory (4 M cells, 32 MiB of offsets)
PAD = 1e-6  # of a cell side: a wall this close to a cell is listed in it too
EPS = 1e-12  # |cross(u, e)| below this: the ray is parallel to the wall (as in core)


@dataclass(frozen=True, eq=False)
class WallGrid:
    """The cell lists of a world's walls; ``nx == 0`` means no grid (the all-walls loop)."""

    cell: float  # side of a square cell (units)
    nx: int  # cells along x
    ny: int  # cells along y
    start: np.ndarray = field(repr=False)  # (nx * ny + 1,) int64 offsets into items
    items: np.ndarray = field(repr=False)  # (M,) int32 rows of the segment array

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """What the kernels take: ``dims`` (3,) float64 ``cell, nx, ny``, ``start``, ``items``."""
        return np.array([self.cell, self.nx, self.ny], dtype=np.float64), self.start, self.items


NO_GRID = WallGrid(1.0, 0, 0, np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int32))


def for_rays(grid: WallGrid, n_walls: int, n_rays: int) -> WallGrid:
    """``grid``, or ``NO_GRID`` where the all-walls loop is faster: it tests the rays of one
    step against a wall in one vectorised pass, so the more rays, the more walls it takes
    before the grid wins (about as many walls as rays, measured by benchmarks/bench_sim.py)."""
    return grid if n_walls >= max(GRID_MIN_WALLS, n_rays) else NO_GRID


def build_grid(
    segments: np.ndarray, width: float, height: float, force: bool = False, cell: float = 0.0
) -> WallGrid:
    """The grid of ``segments`` (S, 4) in the ``width x height`` world, or ``NO_GRID`` for a world
    of fewer than ``GRID_MIN_WALLS`` walls (unless ``force``). ``cell`` (units) overrides the
    side, which by default gives about ``WALLS_PER_CELL`` walls per cell."""
    segments = np.ascontiguousarray(segments, dtype=np.float64)
    n = len(segments)
    if n < GRID_MIN_WALLS and not force:
        return NO_GRID
    if cell <= 0:
        cell = math.sqrt(width * height * WALLS_PER_CELL / max(n, 1))
    cell = max(cell, math.sqrt(width * height / MAX_CELLS))
    nx = max(1, math.ceil(width / cell))
    ny = max(1, math.ceil(height / cell))
    counts = np.zeros(nx * ny + 1, dtype=np.int64)
    _register(segments, cell, nx, ny, counts, np.zeros(0, dtype=np.int32), False)
    start = np.zeros(nx * ny + 1, dtype=np.int64)
    np.cumsum(counts[:-1], out=start[1:])
    items = np.empty(int(start[-1]), dtype=np.int32)
    fill = start.copy()
    _register(segments, cell, nx, ny, fill, items, True)
    return WallGrid(float(cell), nx, ny, start, items)


@numba.njit(cache=True)
def _touches(x0, y0, x1, y1, bx0, by0, bx1, by1):
    """Whether segment (x0, y0)-(x1, y1) meets the box [bx0, bx1] x [by0, by1] (slab clipping)."""
    lo, hi = 0.0, 1.0
    ex, ey = x1 - x0, y1 - y0
    for p, e, a, b in ((x0, ex, bx0, bx1), (y0, ey, by0, by1)):
        if e == 0.0:
            if p < a or p > b:
                return False
        else:
            ta, tb = (a - p) / e, (b - p) / e
            if ta > tb:
                ta, tb = tb, ta
            lo, hi = max(lo, ta), min(hi, tb)
            if lo > hi:
                return False
    return True


@numba.njit(cache=True)
def _register(segments, cell, nx, ny, counts, items, fill):
    """Count (``fill`` False: ``counts[c] += 1``) or list (``items[counts[c]++] = k``) each wall
    k in every cell whose square, grown by PAD cells, it touches."""
    pad = PAD * cell
    for k in range(segments.shape[0]):
        x0, y0, x1, y1 = segments[k, 0], segments[k, 1], segments[k, 2], segments[k, 3]
        ix0 = max(0, min(nx - 1, math.floor((min(x0, x1) - pad) / cell)))
        ix1 = max(0, min(nx - 1, math.floor((max(x0, x1) + pad) / cell)))
        iy0 = max(0, min(ny - 1, math.floor((min(y0, y1) - pad) / cell)))
        iy1 = max(0, min(ny - 1, math.floor((max(y0, y1) + pad) / cell)))
        for iy in range(iy0, iy1 + 1):
            for ix in range(ix0, ix1 + 1):
                bx0, by0 = ix * cell - pad, iy * cell - pad
                if _touches(x0, y0, x1, y1, bx0, by0, bx0 + cell + 2 * pad, by0 + cell + 2 * pad):
                    c = iy * nx + ix
                    if fill:
                        items[counts[c]] = k
                    counts[c] += 1


@numba.njit(cache=True, error_model="numpy")
def _hit(segments, k, x, y, dx, dy, best):
    """The distance along ray (x, y) + t (dx, dy) to wall k if it is hit nearer than ``best``,
    else ``best``: the arithmetic of ``core._cast_many``, operation for operation."""
    ax = segments[k, 0]
    ay = segments[k, 1]
    ex = segments[k, 2] - ax
    ey = segments[k, 3] - ay
    qx = ax - x
    qy = ay - y
    t_num = qx * ey - qy * ex
    den = dx * ey - dy * ex
    s_num = qx * dy - qy * dx
    neg = den < 0.0
    den = -den if neg else den
    tn = -t_num if neg else t_num
    sn = -s_num if neg else s_num
    t = tn / den
    hit = (den >= EPS) & (tn >= 0.0) & (sn >= 0.0) & (sn <= den) & (t < best)
    return t if hit else best


@numba.njit(cache=True, error_model="numpy")
def cast_grid(segments, dims, start, items, stamp, ray_id, x, y, dx, dy, max_range, out):
    """Write into ``out`` (R,) the distance from (x, y) along each unit direction (dx[i], dy[i])
    to the first wall, capped at ``max_range``, walking the grid ``dims, start, items``.

    ``stamp`` (S,) int64 and ``ray_id`` (a counter above every value in ``stamp``) mark the
    walls already tested by a ray; returns the next free ``ray_id``.
    """
    cell = dims[0]
    nx = int(dims[1])
    ny = int(dims[2])
    ix0 = max(0, min(nx - 1, math.floor(x / cell)))  # the origin's cell, shared by every ray
    iy0 = max(0, min(ny - 1, math.floor(y / cell)))
    for i in range(out.shape[0]):
        ux = dx[i]
        uy = dy[i]
        ix = ix0
        iy = iy0
        sx = 1 if ux > 0.0 else -1
        sy = 1 if uy > 0.0 else -1
        inv_x = 1.0 / ux if ux != 0.0 else np.inf  # a ray along an axis never leaves across it
        inv_y = 1.0 / uy if uy != 0.0 else np.inf
        best = max_range
        while True:
            c = iy * nx + ix
            for j in range(start[c], start[c + 1]):
                k = items[j]
                if stamp[k] != ray_id:
                    stamp[k] = ray_id
                    best = _hit(segments, k, x, y, ux, uy, best)
            # where the ray leaves this cell: through its x side or its y side
            tx = ((ix + (sx > 0)) * cell - x) * inv_x if ux != 0.0 else np.inf
            ty = ((iy + (sy > 0)) * cell - y) * inv_y if uy != 0.0 else np.inf
            if tx <= ty:
                if best <= tx:
                    break
                ix += sx
                if ix < 0 or ix >= nx:
                    break
            else:
                if best <= ty:
                    break
                iy += sy
                if iy < 0 or iy >= ny:
                    break
        out[i] = best
        ray_id += 1
    return ray_id
