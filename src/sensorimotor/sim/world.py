"""Worlds: a walled rectangle plus straight inner walls, read from TOML world files.

A world's geometry is one ``(S, 4)`` float64 array of segments ``x0, y0, x1, y1``: the four
outer walls first, then the inner walls in file order. Everything downstream (ray casting,
events, plots) reads that array and nothing else.

A world may also name its rooms (rectangles or polygons): ground truth for the numbers that
ask "which room is the robot in?" (the map, room-to-room tasks); the simulation never reads
them. The built-in worlds name theirs.
"""

from __future__ import annotations

import functools
import math
import re
import tomllib
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.files import MAX_TEXT_BYTES, check_input, check_nesting
from sensorimotor.sim.grid import WallGrid, build_grid

BUILTIN_WORLDS = ("square", "rooms1", "rooms2")
START_CLEARANCE = 1.0  # a start position keeps at least this distance to every wall (units)
MAX_SIZE = 10_000.0  # units a side: beyond it a world is a typo (the paper's are 50)
MAX_WALLS = 100_000  # a ray tests the walls of the grid cells it crosses (sim.grid)
# a name names run folders: no / or .., and short enough for any file system
NAME_PATTERN = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.+-]{0,99}")


@dataclass(frozen=True, eq=False)
class Room:
    """A named region of a world: a simple polygon, (P, 2) float64 vertices in order."""

    name: str
    polygon: np.ndarray = field(repr=False)


@dataclass(frozen=True, eq=False)
class World:
    """A ``width x height`` rectangle whose edges are walls, plus inner wall segments."""

    name: str
    width: float
    height: float
    walls: np.ndarray = field(repr=False)
    """(N, 4) float64 inner walls ``x0, y0, x1, y1``; the outer walls are implied."""
    rooms: tuple[Room, ...] = ()
    """Named rooms, if the world file names any (ground truth only)."""

    @property
    def segments(self) -> np.ndarray:
        """(4 + N, 4) float64: the outer walls (bottom, right, top, left), then the inner walls."""
        w, h = self.width, self.height
        outer = np.array([[0, 0, w, 0], [w, 0, w, h], [w, h, 0, h], [0, h, 0, 0]], dtype=np.float64)
        return np.concatenate([outer, self.walls]).astype(np.float64)

    @functools.cached_property
    def grid(self) -> WallGrid:
        """The walls' grid index (``sim.grid``), built on first use and kept."""
        return build_grid(self.segments, self.width, self.height)

    def to_dict(self) -> dict:
        """JSON-ready description: what a database's ``meta`` records of its world. A built-in
        world's rooms are not recorded (its name gives them back), so its databases are the
        bytes they were before worlds had rooms."""
        out = {"name": self.name, "size": [self.width, self.height], "walls": self.walls.tolist()}
        if self.rooms and self.name not in BUILTIN_WORLDS:
            out["rooms"] = [{"name": r.name, "polygon": r.polygon.tolist()} for r in self.rooms]
        return out

    def room_index(self, x: np.ndarray, y: np.ndarray) -> np.ndarray:
        """(N,) int64: the index in ``rooms`` of the room holding each point (the first one
        listed where rooms overlap or share an edge), -1 where none does."""
        x = np.asarray(x, dtype=np.float64)
        y = np.asarray(y, dtype=np.float64)
        out = np.full(x.shape, -1, dtype=np.int64)
        for i, room in reversed(list(enumerate(self.rooms))):
            out[point_in_polygon(room.polygon, x, y)] = i
        return out

    def __eq__(self, other: object) -> bool:
        return isinstance(other, World) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(repr(self.to_dict()))


def _finite(value: int | float) -> bool:
    try:
        return math.isfinite(value)
    except OverflowError:  # an int too big for a float
        return False


def world_from_dict(data: dict, source: str = "<dict>") -> World:
    """Validate a world description (the TOML keys) and build the World; InputError if bad."""

    def fail(problem: str) -> InputError:
        return InputError(f"{source}: {problem}")

    if not isinstance(data, dict):
        raise fail("a world must be a table with keys 'size' and 'walls'")
    unknown = sorted(set(data) - {"name", "size", "walls", "rooms"})
    if unknown:
        raise fail(f"unknown key {unknown[0]!r} (allowed: name, size, walls, rooms)")
    for key in ("size", "walls"):
        if key not in data:
            raise fail(f"missing key {key!r}")

    size = data["size"]
    if isinstance(size, list):
        if len(size) != 2:
            raise fail(f"'size' must be a number or [width, height], got {size!r}")
        width, height = size
    else:
        width = height = size
    for value in (width, height):
        if isinstance(value, bool) or not isinstance(value, int | float):
            raise fail(f"'size' must be numbers, got {size!r}")
        if not _finite(value):
            raise fail(f"'size' is not a finite number: {size!r}")
        if not 0 < value <= MAX_SIZE:
            raise fail(f"'size' must be positive and at most {MAX_SIZE:g}, got {size!r}")
    width, height = float(width), float(height)

    walls = data["walls"]
    if not isinstance(walls, list):
        raise fail(f"'walls' must be a list of [x0, y0, x1, y1], got {walls!r}")
    if len(walls) > MAX_WALLS:
        raise fail(f"{len(walls):,} walls; at most {MAX_WALLS:,} are supported")
    rows = []
    for i, wall in enumerate(walls):
        if not isinstance(wall, list) or len(wall) != 4:
            raise fail(f"wall {i} must be 4 numbers [x0, y0, x1, y1], got {wall!r}")
        for v in wall:
            if isinstance(v, bool) or not isinstance(v, int | float):
                raise fail(f"wall {i} must be 4 numbers [x0, y0, x1, y1], got {wall!r}")
            if not _finite(v):
                raise fail(f"wall {i} has a coordinate that is not a finite number: {wall!r}")
        x0, y0, x1, y1 = (float(v) for v in wall)
        if not (0 <= x0 <= width and 0 <= x1 <= width and 0 <= y0 <= height and 0 <= y1 <= height):
            raise fail(f"wall {i} {wall!r} lies outside the {width:g} x {height:g} world")
        if x0 == x1 and y0 == y1:
            raise fail(f"wall {i} {wall!r} has zero length")
        rows.append((x0, y0, x1, y1))

    # without one, the file's name, made safe ("my world.toml" -> "my-world")
    stem = re.sub(r"[^A-Za-z0-9_.+-]+", "-", Path(source).stem).strip("_.+-")[:100]
    name = data.get("name", stem or "world")
    if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
        raise fail(
            f"'name' must be 1 to 100 letters, digits and _ . + - (starting with a letter or "
            f"digit), got {name if not isinstance(name, str) or len(name) <= 40 else name[:40] + '...'!r}"
        )
    rooms = _rooms(data.get("rooms", []), width, height, fail)
    world = World(name, width, height, np.array(rows, dtype=np.float64).reshape(-1, 4), rooms)
    if not rooms and name in BUILTIN_WORLDS and source != f"{name}.toml":
        builtin = _builtin(name)  # a database's meta: the built-in's rooms, if its walls
        if world == builtin:
            world = builtin
    if free_start_cells(world).size == 0:
        raise fail(f"no free start position (every point is within {START_CLEARANCE:g} of a wall)")
    return world


def _rooms(rooms, width: float, height: float, fail) -> tuple[Room, ...]:
    """Validate the ``rooms`` key: a list of tables ``{name = "hall", rect = [x0, y0, x1, y1]}``
    or ``{name = "hall", polygon = [[x, y], ...]}`` (3 or more vertices), inside the world,
    names distinct."""
    if not isinstance(rooms, list):
        raise fail(f"'rooms' must be a list of tables, got {rooms!r}")
    out: list[Room] = []
    for i, room in enumerate(rooms):
        if not isinstance(room, dict) or set(room) not in ({"name", "rect"}, {"name", "polygon"}):
            raise fail(f"room {i} must be {{name, rect = [x0, y0, x1, y1]}} or {{name, polygon}}")
        name = room["name"]
        if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
            raise fail(f"room {i}: 'name' must be letters, digits and _ . + -, got {name!r}")
        if name in [r.name for r in out]:
            raise fail(f"room {i}: the name {name!r} is taken by another room")
        shape = room.get("rect", room.get("polygon"))
        if "rect" in room:
            ok = isinstance(shape, list) and len(shape) == 4
            points = (
                [
                    [shape[0], shape[1]],
                    [shape[2], shape[1]],
                    [shape[2], shape[3]],
                    [shape[0], shape[3]],
                ]
                if ok
                else []
            )
        else:
            ok = isinstance(shape, list) and len(shape) >= 3
            points = shape if ok else []
        ok = ok and all(
            isinstance(pt, list)
            and len(pt) == 2
            and all(
                not isinstance(v, bool) and isinstance(v, int | float) and _finite(v) for v in pt
            )
            for pt in points
        )
        if not ok:
            raise fail(f"room {name!r}: rect must be 4 numbers, polygon 3 or more [x, y] points")
        poly = np.array(points, dtype=np.float64)
        if (
            poly[:, 0].min() < 0
            or poly[:, 0].max() > width
            or poly[:, 1].min() < 0
            or poly[:, 1].max() > height
        ):
            raise fail(f"room {name!r} lies outside the {width:g} x {height:g} world")
        area = 0.5 * abs(
            np.dot(poly[:, 0], np.roll(poly[:, 1], -1))
            - np.dot(poly[:, 1], np.roll(poly[:, 0], -1))
        )
        if area == 0:
            raise fail(f"room {name!r} has zero area")
        out.append(Room(name, poly))
    return tuple(out)


def point_in_polygon(polygon: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Whether each point lies inside ``polygon`` (P, 2), by the even-odd rule: a ray from the
    point towards +x crosses the boundary an odd number of times. Points on the boundary
    count as inside (rooms of a plan share their walls). An axis-aligned rectangle (every
    built-in room) is the same closed box, tested by its bounds alone."""
    box = _axis_aligned_box(polygon)
    if box is not None:
        x0, y0, x1, y1 = box
        return (x0 <= x) & (x <= x1) & (y0 <= y) & (y <= y1)
    inside = np.zeros(np.shape(x), dtype=bool)
    on_edge = np.zeros(np.shape(x), dtype=bool)
    for (x0, y0), (x1, y1) in zip(polygon, np.roll(polygon, -1, axis=0), strict=True):
        crosses = (y0 > y) != (y1 > y)
        with np.errstate(divide="ignore", invalid="ignore"):
            at = x0 + (y - y0) * (x1 - x0) / (y1 - y0)  # x where the edge meets the point's row
        inside ^= crosses & (x < at)
        cross = (x1 - x0) * (y - y0) - (y1 - y0) * (x - x0)
        within = (np.minimum(x0, x1) <= x) & (x <= np.maximum(x0, x1))
        within &= (np.minimum(y0, y1) <= y) & (y <= np.maximum(y0, y1))
        on_edge |= within & (np.abs(cross) <= 1e-9 * max(1.0, abs(x1 - x0) + abs(y1 - y0)))
    return inside | on_edge


def _axis_aligned_box(polygon: np.ndarray) -> tuple[float, float, float, float] | None:
    """(x0, y0, x1, y1) of ``polygon`` if it is a rectangle with axis-parallel edges, else None.
    On such a box the even-odd rule and the on-edge test above give the closed box exactly: a
    point off a vertical edge by any amount fails that edge's x-range, and likewise in y."""
    if len(polygon) != 4:
        return None
    nxt = np.roll(polygon, -1, axis=0)
    if not np.all((polygon[:, 0] == nxt[:, 0]) != (polygon[:, 1] == nxt[:, 1])):
        return None  # an edge neither vertical nor horizontal, or of zero length
    (x0, y0), (x1, y1) = polygon.min(axis=0), polygon.max(axis=0)
    return float(x0), float(y0), float(x1), float(y1)


def load_world(spec: str | Path) -> World:
    """A built-in world by name (``square``, ``rooms1``, ``rooms2``) or a TOML world file's path."""
    spec_str = str(spec)
    if spec_str in BUILTIN_WORLDS:
        text = resources.files("sensorimotor.sim.worlds").joinpath(f"{spec_str}.toml").read_text()
        return world_from_dict(tomllib.loads(text), f"{spec_str}.toml")
    path = Path(spec)
    if not path.exists():
        if path.suffix.lower() != ".toml" and "/" not in spec_str:
            raise InputError(
                f"unknown world {spec_str!r}: use one of {', '.join(BUILTIN_WORLDS)} "
                "or the path of a .toml world file"
            )
        raise InputError(f"{path}: world file not found")
    check_input(path, "world file", MAX_TEXT_BYTES)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read world file ({err.__class__.__name__})") from None
    if not text.strip():
        raise InputError(f"{path}: empty world file")
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise InputError(f"{path}: not valid TOML ({err})") from None
    except RecursionError:
        raise InputError(f"{path}: nested too deeply to be a world file") from None
    check_nesting(data, str(path))
    world = world_from_dict(data, str(path))
    check_builtin_name(world, str(path))
    return world


@functools.cache
def _builtin(name: str) -> World:
    """A built-in world read once, for comparisons only (callers of load_world get their own)."""
    return load_world(name)


def check_builtin_name(world: World, source: str) -> None:
    """Refuse a world that takes a built-in world's name but not its walls: runs are named, and
    set beside the paper's numbers, by the world's name."""
    if world.name in BUILTIN_WORLDS and world != _builtin(world.name):
        raise InputError(
            f"{source}: {world.name!r} is the name of a built-in world with other walls; give "
            "this world a name of its own"
        )


def point_segment_distance(segments: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Distance from points ``(x, y)`` (shape P) to each segment (S, 4): an (P, S) array.

    The closest point of segment ``a + u (b - a)`` is at ``u = clip(((p - a).(b - a)) / |b - a|^2,
    0, 1)``.
    """
    x = np.asarray(x, dtype=np.float64)[:, None]
    y = np.asarray(y, dtype=np.float64)[:, None]
    ax, ay, bx, by = (segments[:, i][None, :] for i in range(4))
    ex, ey = bx - ax, by - ay
    u = np.clip(((x - ax) * ex + (y - ay) * ey) / (ex * ex + ey * ey), 0.0, 1.0)
    return np.hypot(x - (ax + u * ex), y - (ay + u * ey))


def free_start_cells(world: World, resolution: float = 0.25) -> np.ndarray:
    """(P, 2) grid points at least START_CLEARANCE from every wall: proof that a start exists.

    The grid is coarsened for big worlds so that it never holds more than 400 x 400 points.
    Each wall rules out the points within the clearance of it, found among the points of its
    bounding box grown by the clearance (the distance is ``point_segment_distance``'s), so the
    cost grows with the walls' lengths, not with walls x points.
    """
    resolution = max(resolution, world.width / 400, world.height / 400)
    xs = np.arange(resolution / 2, world.width, resolution)
    ys = np.arange(resolution / 2, world.height, resolution)
    free = np.ones((len(ys), len(xs)), dtype=bool)  # (Y, X), the meshgrid's order
    c = START_CLEARANCE
    for seg in world.segments:
        i0, i1 = np.searchsorted(xs, [min(seg[0], seg[2]) - c, max(seg[0], seg[2]) + c], "left")
        j0, j1 = np.searchsorted(ys, [min(seg[1], seg[3]) - c, max(seg[1], seg[3]) + c], "left")
        i1 += int(i1 < len(xs) and xs[i1] == max(seg[0], seg[2]) + c)  # the bound itself counts
        j1 += int(j1 < len(ys) and ys[j1] == max(seg[1], seg[3]) + c)
        if i0 >= i1 or j0 >= j1:
            continue
        gx, gy = np.meshgrid(xs[i0:i1], ys[j0:j1])
        d = point_segment_distance(seg[None, :], gx.ravel(), gy.ravel())[:, 0]
        free[j0:j1, i0:i1] &= (d >= c).reshape(gx.shape)
    gx, gy = np.meshgrid(xs, ys)
    return np.stack([gx[free], gy[free]], axis=1)
