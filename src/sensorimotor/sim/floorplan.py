"""Generated floor plans: a rectangle split recursively into named rooms joined by doorways.

``random_plan(rooms, seed)`` cuts the world's rectangle in two with a wall across it, leaving
one doorway of width ``door`` in that wall, then cuts the largest room that can still be cut,
and so on until there are ``rooms`` rooms. A cut runs across the longer side of its room, at a
random position that leaves both halves at least ``min_side`` wide and does not end inside an
earlier doorway (which would narrow it). Every room is reachable from every other through the
doorways (each cut joins its two halves, so the rooms form a tree); ``reachable`` proves it on
the drawn walls by a flood fill (one free region), and ``random_plan`` refuses a plan that fails
it (``check_reachable`` names the rooms cut off). ``experiments.walls`` refuses a wall layout by
the same test.

``world_toml`` writes any world as a TOML world file (walls, rooms), which ``load_world`` reads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.sim.world import START_CLEARANCE, World, world_from_dict

DOOR = 1.5  # units; default doorway width (the agent is a point; 1.5 > the turn threshold)
MIN_SIDE = 4.0  # units; default smallest room side (a free start needs a 2 x 2 clear square)
ROOM_AREA = 100.0  # units^2; the default world is about this much per room
FLOOD_RESOLUTION = 0.25  # units; the flood fill's cell
# what a plan costs grows as rooms^2 x flood-fill cells (measured: 40 rooms of the default
# side, 64, take 5 s; 40 rooms at side 200, 41 s; 80 rooms, 40 s): both bounded, and their
# product, to about 5 s
MAX_ROOMS = 40
MAX_SIZE = 200.0  # units; a side
MAX_PLAN_WORK = 110_000_000  # rooms^2 x cells: 40 rooms of the default side, 104,857,600


def check_plan_work(rooms: int, size: float | tuple[float, float] | None) -> None:
    """InputError, before any work, for a plan that would take more than about 5 s."""
    if isinstance(rooms, bool) or not isinstance(rooms, int) or not 1 <= rooms <= MAX_ROOMS:
        raise InputError(f"--rooms must be an integer from 1 to {MAX_ROOMS}, got {rooms!r}")
    if size is None:
        side = float(math.ceil(math.sqrt(rooms * ROOM_AREA)))
        size = (side, side)
    elif not isinstance(size, tuple):
        size = (size, size)
    width, height = (float(v) for v in size)
    if not all(math.isfinite(v) and 0 < v <= MAX_SIZE for v in (width, height)):
        raise InputError(f"--size must be positive and at most {MAX_SIZE:g}, got {size!r}")
    work = rooms**2 * (width / FLOOD_RESOLUTION) * (height / FLOOD_RESOLUTION)
    if work > MAX_PLAN_WORK:
        raise InputError(
            f"--rooms {rooms} in a {width:g} x {height:g} world is too much work (rooms^2 x "
            f"cells of {FLOOD_RESOLUTION:g} = {work:,.0f}, at most {MAX_PLAN_WORK:,}: about "
            "5 s); give fewer rooms or a smaller --size"
        )


@dataclass(frozen=True)
class _Door:
    vertical: bool  # the wall it pierces runs along y (x = at)
    at: float  # that wall's x (vertical) or y
    lo: float  # the opening, along the wall
    hi: float


def random_plan(
    rooms: int,
    seed: int = 0,
    door: float = DOOR,
    size: tuple[float, float] | None = None,
    min_side: float = MIN_SIDE,
    name: str | None = None,
) -> World:
    """A floor plan of ``rooms`` rectangular rooms named ``room0``, ``room1``, ... (see the
    module docstring); ``size`` (width, height) defaults to a square of about ``ROOM_AREA``
    per room. InputError when ``rooms`` rooms do not fit, or a setting is out of range."""
    check_plan_work(rooms, size)
    if not (math.isfinite(min_side) and min_side > 2 * START_CLEARANCE):
        raise InputError(f"the smallest room side must exceed {2 * START_CLEARANCE:g}")
    if not (math.isfinite(door) and 0 < door <= min_side - 2 * START_CLEARANCE):
        raise InputError(
            f"--door must be positive and at most {min_side - 2 * START_CLEARANCE:g} (a room's "
            f"smallest side, {min_side:g}, less a clearance at each end), got {door!r}"
        )
    if size is None:
        side = float(math.ceil(math.sqrt(rooms * ROOM_AREA)))
        size = (side, side)
    width, height = (float(v) for v in size)
    rng = np.random.default_rng(seed)
    boxes = [(0.0, 0.0, width, height)]
    walls: list[list[float]] = []
    doors: list[_Door] = []
    while len(boxes) < rooms:
        order = sorted(range(len(boxes)), key=lambda i: -_area(boxes[i]))
        for i in order:
            cut = _cut(boxes[i], door, min_side, doors, rng)
            if cut is not None:
                break
        else:
            raise InputError(
                f"{rooms} rooms do not fit a {width:g} x {height:g} world with rooms at least "
                f"{min_side:g} wide: {len(boxes)} do"
            )
        halves, new_walls, new_door = cut
        boxes[i : i + 1] = halves
        walls += new_walls
        doors.append(new_door)
    world = world_from_dict(
        {
            "name": name or f"plan{rooms}-s{seed}",
            "size": [width, height],
            "walls": walls,
            "rooms": [{"name": f"room{k}", "rect": list(b)} for k, b in enumerate(boxes)],
        },
        "generated plan",
    )
    resolution = max(min(FLOOD_RESOLUTION, door / 4), max(width, height) / 2000)
    if not reachable(world, resolution):  # a bug: the cuts form a tree
        unreached = check_reachable(world, resolution) or ["?"]
        raise InputError(f"generated plan: room {unreached[0]!r} cannot be reached")
    return world


def _area(box: tuple[float, float, float, float]) -> float:
    return (box[2] - box[0]) * (box[3] - box[1])


def _cut(box, door: float, min_side: float, doors: list[_Door], rng: np.random.Generator):
    """Split ``box`` across its longer side: (two boxes, its wall pieces, the doorway), or None
    if it cannot be split (too small, or every position would end in a doorway)."""
    x0, y0, x1, y1 = box
    vertical = (x1 - x0) >= (y1 - y0)  # a vertical wall cuts a wide room
    lo, hi = (x0, x1) if vertical else (y0, y1)  # where the wall may stand
    a, b = (y0, y1) if vertical else (x0, x1)  # the span the wall crosses
    if hi - lo < 2 * min_side:
        return None
    ends = [d for d in doors if d.vertical != vertical and d.at in (a, b)]  # walls it ends on
    for _ in range(50):
        at = round(float(rng.uniform(lo + min_side, hi - min_side)), 3)
        if all(at < d.lo - START_CLEARANCE or at > d.hi + START_CLEARANCE for d in ends):
            break
    else:
        return None
    start = round(float(rng.uniform(a + START_CLEARANCE, b - START_CLEARANCE - door)), 3)
    opening = (start, start + door)
    pieces = [(a, opening[0]), (opening[1], b)]
    walls = [[at, p, at, q] if vertical else [p, at, q, at] for p, q in pieces if q - p > 1e-9]
    halves = (
        [(x0, y0, at, y1), (at, y0, x1, y1)] if vertical else [(x0, y0, x1, at), (x0, at, x1, y1)]
    )
    return halves, walls, _Door(vertical, at, *opening)


def _flood(world: World, resolution: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(labels, blocked, xs, ys): the free cells of a grid of ``resolution`` labelled by their
    4-neighbour component (0: blocked); a cell is blocked when a wall passes through it."""
    from scipy import ndimage

    xs = np.arange(resolution / 2, world.width, resolution)
    ys = np.arange(resolution / 2, world.height, resolution)
    blocked = np.zeros((len(ys), len(xs)), dtype=bool)
    for x0, y0, x1, y1 in world.segments:  # sample each wall densely, mark the cells it crosses
        n = math.ceil(math.hypot(x1 - x0, y1 - y0) / (resolution / 4)) + 1
        t = np.linspace(0.0, 1.0, n)
        ix = np.clip(((x0 + t * (x1 - x0)) / resolution).astype(int), 0, len(xs) - 1)
        iy = np.clip(((y0 + t * (y1 - y0)) / resolution).astype(int), 0, len(ys) - 1)
        blocked[iy, ix] = True
    labels, _ = ndimage.label(~blocked)
    return labels, blocked, xs, ys


def check_reachable(world: World, resolution: float = FLOOD_RESOLUTION) -> list[str]:
    """The names of the rooms that no path from the first room reaches (empty: all reachable).

    Flood fill on a grid of ``resolution``: a cell is blocked when a wall passes within half a
    cell of its centre; the rooms are connected when the free cells inside each room belong
    to the component of the first room's free cells (4-neighbour connectivity).
    """
    if not world.rooms:
        return []
    labels, blocked, xs, ys = _flood(world, resolution)
    gx, gy = np.meshgrid(xs, ys)
    inside = [
        world.room_index(gx.ravel(), gy.ravel()).reshape(gx.shape) == k
        for k in range(len(world.rooms))
    ]
    first = set(np.unique(labels[inside[0] & ~blocked])) - {0}
    return [
        room.name
        for room, cells in zip(world.rooms, inside, strict=True)
        if not first & set(np.unique(labels[cells & ~blocked]))
    ]


MIN_REGION = 1.0  # square units: a free region smaller is a sliver of the flood fill's grid


def free_regions(world: World, resolution: float = FLOOD_RESOLUTION) -> int:
    """How many separate free regions the walls leave (a room sealed by walls is one more);
    1: every free place is reachable from every other. Regions under ``MIN_REGION`` are not
    counted: where two walls meet, the grid may leave a few cells between them."""
    _, sizes = _regions(world, resolution)
    return int((sizes >= MIN_REGION).sum())


def _regions(world: World, resolution: float) -> tuple[np.ndarray, np.ndarray]:
    """(labels, areas): ``_flood``'s labels and each free region's area (label k + 1 at k)."""
    labels, _, _, _ = _flood(world, resolution)
    return labels, np.bincount(labels.ravel())[1:] * resolution**2


@dataclass(frozen=True)
class StartRegion:
    """The largest free region of a world with several (``start_region``), as a grid mask."""

    mask: np.ndarray  # (Y, X) bool: cells of the region
    resolution: float

    def contains(self, x: float, y: float) -> bool:
        """Whether the grid cell of (x, y) belongs to the region."""
        j = min(max(int(y / self.resolution), 0), self.mask.shape[0] - 1)
        i = min(max(int(x / self.resolution), 0), self.mask.shape[1] - 1)
        return bool(self.mask[j, i])


def start_region(world: World, resolution: float = FLOOD_RESOLUTION) -> StartRegion | None:
    """Where a start pose may be: the largest free region (by area) when the walls leave more
    than one (``free_regions``), else None (anywhere free). An imported map's building
    interiors and sealed pockets are regions of their own, which a walk started inside never
    leaves; the paper's worlds, floor plans and wall layouts have one region."""
    resolution = max(resolution, world.width / 1000, world.height / 1000)
    labels, sizes = _regions(world, resolution)
    if int((sizes >= MIN_REGION).sum()) <= 1:
        return None
    return StartRegion(labels == 1 + int(np.argmax(sizes)), resolution)


def reachable(world: World, resolution: float = FLOOD_RESOLUTION) -> bool:
    """Every free place reachable from every other (one free region, ``free_regions``): the
    one test of a generated world, floor plan or wall layout, that no wall seals a room."""
    return free_regions(world, resolution) == 1


def world_toml(world: World, comment: str = "") -> str:
    """A TOML world file for ``world`` (what ``load_world`` reads back to an equal World)."""
    lines = [f"# {line}" for line in comment.splitlines()]
    lines += [f'name = "{world.name}"', f"size = [{world.width!r}, {world.height!r}]", "walls = ["]
    lines += [f"  [{', '.join(repr(float(v)) for v in w)}]," for w in world.walls]
    lines.append("]")
    if world.rooms:
        lines.append("rooms = [")
        for room in world.rooms:
            points = ", ".join(f"[{x!r}, {y!r}]" for x, y in room.polygon.tolist())
            lines.append(f'  {{ name = "{room.name}", polygon = [{points}] }},')
        lines.append("]")
    return "\n".join(lines) + "\n"
