"""Real building maps: a ROS ``map_server`` occupancy grid (or MRPT's, ``import_mrpt_map``) turned
into a world's wall segments.

A map is a ``.yaml`` file beside an image (``.pgm`` or ``.png``), the format robotics labs
keep their buildings in (http://wiki.ros.org/map_server#Map_format)::

    image: floor2.pgm          # the image, relative to the .yaml
    resolution: 0.05           # metres per pixel
    origin: [-12.0, -8.5, 0.0] # the lower-left pixel's pose in the map frame (x, y, yaw)
    negate: 0                  # 1: white is occupied
    occupied_thresh: 0.65      # occupancy above this: a wall
    free_thresh: 0.196         # occupancy below this: free

A pixel's occupancy is ``(255 - v) / 255`` (``v / 255`` with ``negate``), for a grey value
``v`` in 0..255 (colour images are averaged). A pixel whose occupancy is not below
``free_thresh`` is blocked: occupied or unknown (the outside of a building is unknown, and
the agent must not wander into it). The walls are the edges between a blocked and a free
pixel, merged into one segment along each run of such edges in a row or a column. The world
is the image's rectangle in metres, its lower-left corner at (0, 0): the map's ``origin`` is
kept in the world file's comment, not in the coordinates (a world starts at 0).

Clearance (``open_free``, both formats): before the walls are drawn, the free space can be
opened by a disk of diameter ``clearance``: free places narrower than it (pockets, slots,
corridors) become blocked, so that the paper's behaviour, which turns around whenever a reading
is under ``TURN_THRESHOLD``, cannot walk into a place it cannot turn out of. An MRPT grid is
opened to ``CLEARANCE`` by default (its SLAM map's narrow free slivers are dead ends: the
shipped campus trapped the behaviour for good); a ROS map is not unless asked (a building's
doorways are narrower than 2 m).

Only the map_server keys above (and ``mode``, ``trinary`` or ``scale``/``raw`` are read as
trinary) are parsed, by a small reader of ``key: value`` lines: numbers, strings and flat
``[a, b, c]`` lists; anything else is an InputError naming the file and line.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.files import MAX_TEXT_BYTES, check_input
from sensorimotor.sim.core import TURN_THRESHOLD
from sensorimotor.sim.world import MAX_SIZE, NAME_PATTERN, World, world_from_dict

KEYS = ("image", "resolution", "origin", "negate", "occupied_thresh", "free_thresh", "mode")
NUMBER = re.compile(r"[-+]?(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?")
MAX_IMAGE_BYTES = 1 << 30  # a map image: a building at 1 cm a pixel is far less
FREE_THRESH = 0.196  # an MRPT grid's cell is free below this occupancy (map_server's default)
SPECK_CELLS = 2  # blocked specks of at most this many cells inside the free region: noise
CLEARANCE = 2.0 * TURN_THRESHOLD
"""Units: an MRPT grid's free space is opened to this width (``open_free``). A free disk of
radius ``TURN_THRESHOLD`` around a point: the behaviour turns there in any heading without its
reflex firing, and from anywhere in the disk the rays aimed at its centre read at least
2 cos(0.6) > 1 (the fan spans +-0.6 rad), so some heading always lets it walk out."""
# pixels of a map image, read from its header before it is decoded: 5,000 x 5,000 (a 250 m
# building at 5 cm a pixel) holds in well under 1 GB as the grids the import makes of it
MAX_IMAGE_PIXELS = 25_000_000


def _check_pixels(cols: int, rows: int, path: Path) -> None:
    if cols * rows > MAX_IMAGE_PIXELS:
        raise InputError(
            f"{path}: {cols:,} x {rows:,} pixels, more than the {MAX_IMAGE_PIXELS:,} a map image "
            "may have (crop it or lower its resolution)"
        )


def _value(text: str, where: str):
    text = text.strip()
    if len(text) >= 2 and text[0] == text[-1] and text[0] in "'\"":
        return text[1:-1]
    if text.startswith("[") and text.endswith("]"):
        items = [v for v in text[1:-1].split(",") if v.strip()]
        if any("[" in v or "]" in v for v in items):  # map_server's lists are flat
            raise InputError(f"{where}: a list within a list (map_server's lists hold numbers)")
        return [_value(v, where) for v in items]
    if NUMBER.fullmatch(text):
        return float(text)
    return text


def read_map_yaml(path: str | Path) -> dict:
    """The map_server keys of ``path``: ``{key: number | str | list}``; InputError if bad."""
    path = check_input(path, "map file", MAX_TEXT_BYTES)
    try:
        text = path.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as err:
        raise InputError(f"{path}: cannot read the map file ({err.__class__.__name__})") from None
    out: dict = {}
    for number, line in enumerate(text.splitlines(), 1):
        line = line.split("#", 1)[0].rstrip()
        if not line.strip():
            continue
        key, sep, value = line.partition(":")
        key = key.strip()
        if not sep or not value.strip() or line[0].isspace():
            raise InputError(f"{path}:{number}: expected 'key: value', got {line.strip()!r}")
        if key in KEYS:
            out[key] = _value(value, f"{path}:{number}")
    for key in ("image", "resolution"):
        if key not in out:
            raise InputError(f"{path}: missing key {key!r}")
    return out


def _number(meta: dict, key: str, default: float, path: Path) -> float:
    value = meta.get(key, default)
    if not isinstance(value, float) or not math.isfinite(value):
        raise InputError(f"{path}: {key!r} must be a number, got {value!r}")
    return value


def read_image(path: Path) -> np.ndarray:
    """(rows, cols) float64 grey levels in 0..255 of a PGM (P2/P5, 8 or 16 bit) or PNG."""
    data = check_input(path, "map image", MAX_IMAGE_BYTES).read_bytes()
    if data[:2] in (b"P2", b"P5"):
        return _read_pgm(data, path)
    if data[:8] == b"\x89PNG\r\n\x1a\n":
        from matplotlib.image import imread

        if len(data) < 24 or data[12:16] != b"IHDR":
            raise InputError(f"{path}: not a readable PNG (no IHDR header)")
        _check_pixels(int.from_bytes(data[16:20], "big"), int.from_bytes(data[20:24], "big"), path)

        try:
            img = np.asarray(imread(path), dtype=np.float64)  # floats in [0, 1]
        except Exception as err:  # a damaged PNG: any of several libraries' errors
            raise InputError(f"{path}: not a readable PNG ({err.__class__.__name__})") from None
        if img.ndim == 3:
            img = img[..., :3].mean(axis=2)
        return img * 255.0
    raise InputError(f"{path}: not a map image (a .pgm or .png occupancy grid)")


def _read_pgm(data: bytes, path: Path) -> np.ndarray:
    """A binary (P5) or plain (P2) PGM: header ``P5 width height maxval``, comments ``#``."""
    tokens: list[bytes] = []
    pos = 2
    while len(tokens) < 3:
        match = re.compile(rb"\s*(#[^\n]*\n\s*)*(\S+)").match(data, pos)
        if match is None:
            raise InputError(f"{path}: truncated PGM header")
        tokens.append(match.group(2))
        pos = match.end()
    try:
        cols, rows, maxval = (int(t) for t in tokens)
    except ValueError:
        raise InputError(f"{path}: bad PGM header {tokens!r}") from None
    if not (cols > 0 and rows > 0 and 0 < maxval < 65536):
        raise InputError(f"{path}: bad PGM header (size {cols} x {rows}, maxval {maxval})")
    _check_pixels(cols, rows, path)
    if data[:2] == b"P5":
        dtype = np.dtype(">u2") if maxval > 255 else np.dtype("u1")
        body = data[pos + 1 : pos + 1 + rows * cols * dtype.itemsize]
        if len(body) != rows * cols * dtype.itemsize:
            raise InputError(f"{path}: truncated PGM ({rows} x {cols} pixels announced)")
        img = np.frombuffer(body, dtype=dtype).reshape(rows, cols)
    else:
        values = data[pos:].split()
        if len(values) < rows * cols:
            raise InputError(f"{path}: truncated PGM ({rows} x {cols} pixels announced)")
        try:
            img = np.array([int(v) for v in values[: rows * cols]]).reshape(rows, cols)
        except ValueError:
            raise InputError(f"{path}: a PGM pixel is not an integer") from None
    return img.astype(np.float64) * (255.0 / maxval)


def import_ros_map(
    path: str | Path, name: str | None = None, clearance: float = 0.0, scale: float = 1.0
) -> tuple[World, str]:
    """The world of a map_server map (see the module docstring), and a comment that says
    where it came from (file, resolution, origin, units) for its world file; ``scale`` units
    a metre (1: a unit is a metre); its free space opened to ``clearance`` units
    (``open_free``; 0, the default: every free pixel kept)."""
    path = Path(path)
    _check_scale(scale, path)
    meta = read_map_yaml(path)
    resolution = _number(meta, "resolution", 0.0, path)
    if resolution <= 0:
        raise InputError(f"{path}: 'resolution' must be positive, got {resolution:g}")
    occupied = _number(meta, "occupied_thresh", 0.65, path)
    free = _number(meta, "free_thresh", 0.196, path)
    if not 0 <= free < occupied <= 1:
        raise InputError(
            f"{path}: thresholds must satisfy 0 <= free_thresh < occupied_thresh <= 1, got "
            f"{free:g} and {occupied:g}"
        )
    negate = _number(meta, "negate", 0.0, path)
    if negate not in (0.0, 1.0):
        raise InputError(f"{path}: 'negate' must be 0 or 1, got {negate:g}")
    origin = meta.get("origin", [0.0, 0.0, 0.0])
    if not (
        isinstance(origin, list)
        and len(origin) == 3
        and all(isinstance(v, float) and math.isfinite(v) for v in origin)
    ):
        raise InputError(f"{path}: 'origin' must be [x, y, yaw], got {origin!r}")
    if not isinstance(meta["image"], str) or not meta["image"]:
        raise InputError(f"{path}: 'image' must name the map's image file")
    image = read_image(path.parent / meta["image"])
    rows, cols = image.shape
    occupancy = image / 255.0 if negate else (255.0 - image) / 255.0
    blocked = ~(occupancy < free)  # occupied or unknown
    if blocked.all():
        raise InputError(f"{path}: the map has no free pixel (free_thresh {free:g})")
    blocked = open_free(blocked[::-1], resolution * scale, clearance, path)  # row 0: the top
    world = grid_world(blocked, resolution * scale, name or _stem(path), path)
    comment = (
        f"imported from the ROS map {path.name} ({meta['image']}, {cols} x {rows} pixels of "
        f"{resolution:g} m{_opened(clearance)}; origin {origin} m: add it to go back to map "
        f"coordinates; {units(scale)})"
    )
    return world, comment


def units(scale: float) -> str:
    """What a world unit is, for a world made from a map in metres at ``scale`` units a metre."""
    return f"1 unit = {1 / scale:g} m (--scale {scale:g} units a metre)"


def _check_scale(scale: float, path: Path) -> None:
    if not (isinstance(scale, int | float) and 0 < scale <= MAX_SIZE and math.isfinite(scale)):
        raise InputError(f"{path}: --scale must be a positive number of units a metre, got {scale!r}")


def _stem(path: Path) -> str:
    stem = path.name.removesuffix(".gz").removesuffix(".gridmap").removesuffix(".yaml")
    return re.sub(r"[^A-Za-z0-9_.+-]+", "-", stem).strip("_.+-") or "map"


def grid_world(blocked: np.ndarray, resolution: float, name: str, path: Path) -> World:
    """The world of an occupancy grid: ``blocked`` (rows, cols; row 0 at y = 0) cells of
    ``resolution`` (units), walls along every edge between a blocked and a free cell
    (``wall_segments``), the grid's rectangle the world's, its lower-left corner at (0, 0)."""
    if not NAME_PATTERN.fullmatch(name):
        raise InputError(f"{path}: cannot name the world {name!r}")
    rows, cols = blocked.shape
    walls = wall_segments(blocked, resolution)
    return world_from_dict(
        {"name": name, "size": [cols * resolution, rows * resolution], "walls": walls}, str(path)
    )


def import_mrpt_map(
    path: str | Path, name: str | None = None, clearance: float = CLEARANCE, scale: float = 1.0
) -> tuple[World, str]:
    """The world of an MRPT occupancy grid (``.gridmap``, ``.gridmap.gz``; read by
    ``sim.mrpt.read_gridmap``) and its world file's comment.

    Thresholds, those of a ROS map (``free_thresh`` 0.196): a cell is free when its occupancy
    (1 - MRPT's P(free)) is below ``FREE_THRESH``; else blocked (occupied or unknown). The world
    is the free space the robot can reach: the largest 4-connected free region (free cells cut
    off from it, unreachable, are blocked); blocked specks of at most ``SPECK_CELLS`` cells
    inside it (laser noise: under 0.03 m^2 at MRPT's 8 cm) are made free, so they do not become
    four walls each. That region is opened to ``clearance`` units (``open_free``; ``CLEARANCE``
    by default, 0 for none) and the largest region left kept. The grid is cropped to that
    region's bounding box and one cell around, ``scale`` units a metre (1, the default: a unit
    a metre, as ``import-rawlog``'s default scale)."""
    from scipy import ndimage

    from sensorimotor.sim.mrpt import read_gridmap

    path = Path(path)
    _check_scale(scale, path)
    grid = read_gridmap(path)
    metres = float(f"{grid.resolution:.6g}")  # the float32 0.0799999982 is 0.08
    res = metres * scale  # units a cell
    region = _largest((1.0 - grid.free) < FREE_THRESH)
    if region is None:
        raise InputError(f"{path}: the grid has no free cell (occupancy below {FREE_THRESH:g})")
    blocked_labels, _ = ndimage.label(~region)
    speck = np.bincount(blocked_labels.ravel()) <= SPECK_CELLS
    speck[0] = False
    region |= speck[blocked_labels]
    region = _largest(~open_free(~region, res, clearance, path))
    ys, xs = np.nonzero(region)
    y0, y1 = max(int(ys.min()) - 1, 0), min(int(ys.max()) + 2, region.shape[0])
    x0, x1 = max(int(xs.min()) - 1, 0), min(int(xs.max()) + 2, region.shape[1])
    world = grid_world(~region[y0:y1, x0:x1], res, name or _stem(path), path)
    origin = [grid.x_min + x0 * metres, grid.y_min + y0 * metres]
    comment = (
        f"imported from the MRPT gridmap {path.name} (COccupancyGridMap2D {grid.version}, "
        f"{grid.free.shape[1]} x {grid.free.shape[0]} cells of {metres:g} m; free: occupancy < "
        f"{FREE_THRESH:g}, the largest connected free region, specks of <= {SPECK_CELLS} cells "
        f"dropped{_opened(clearance)}; cropped to {x1 - x0} x {y1 - y0} cells at map "
        f"({origin[0]:.3f}, {origin[1]:.3f}) m: add it to go back to map coordinates; "
        f"{units(scale)})"
    )
    return world, comment


def _largest(free: np.ndarray) -> np.ndarray | None:
    """The largest 4-connected region of ``free`` (bool, same shape), None when none is free."""
    from scipy import ndimage

    labels, n = ndimage.label(free)
    if n == 0:
        return None
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    return labels == int(np.argmax(sizes))


def _opened(clearance: float) -> str:
    """The world file comment's words for the opening (none for 0)."""
    return f", opened to a clearance of {clearance:g} m" if clearance > 0 else ""


def open_free(
    blocked: np.ndarray, resolution: float, clearance: float, path: str | Path
) -> np.ndarray:
    """``blocked`` (rows, cols) with its free space opened by a disk of diameter ``clearance``
    (units; cells of ``resolution``): a free cell stays free when it lies in a disk of cells
    (those whose centres are within ``clearance / 2`` of one cell's centre) made of free cells
    alone; the other free cells become blocked. So free pockets, slots and corridors narrower
    than ``clearance`` close, and what stays is the union of the free disks (a morphological
    opening, by two Euclidean distance transforms). The grid's border counts as blocked (the
    world's outer walls). 0 returns ``blocked`` unchanged; InputError naming ``path`` when the
    clearance is not a number from 0 to ``MAX_SIZE`` or when nothing free is that wide."""
    from scipy import ndimage

    if not (isinstance(clearance, int | float) and 0 <= clearance <= MAX_SIZE):
        raise InputError(
            f"{path}: --clearance must be a number of units from 0 to {MAX_SIZE:g}, got "
            f"{clearance!r}"
        )
    if clearance == 0:
        return blocked
    radius = clearance / 2 / resolution  # cells
    free = np.pad(~blocked, 1)  # a blocked frame: the outer walls
    centres = ndimage.distance_transform_edt(free) > radius  # a free disk around each
    if not centres.any():
        raise InputError(
            f"{path}: no free place is {clearance:g} units wide (--clearance {clearance:g}); "
            "lower --clearance or use 0"
        )
    kept = ndimage.distance_transform_edt(~centres) <= radius  # within a free disk
    return ~kept[1:-1, 1:-1]


def wall_segments(blocked: np.ndarray, resolution: float) -> list[list[float]]:
    """Segments ``[x0, y0, x1, y1]`` along every edge between a blocked and a free cell of
    ``blocked`` (rows, cols; row 0 at y = 0), merged along each row and column; the edges on
    the grid's border are left out (the world's outer walls)."""
    walls: list[list[float]] = []
    # horizontal edges: between row r - 1 and row r, at y = r
    change = blocked[1:, :] != blocked[:-1, :]  # (rows - 1, cols)
    for r, c0, c1 in _runs(change):
        walls.append([c0 * resolution, (r + 1) * resolution, c1 * resolution, (r + 1) * resolution])
    # vertical edges: between column c - 1 and column c, at x = c
    change = blocked[:, 1:] != blocked[:, :-1]  # (rows, cols - 1)
    for c, r0, r1 in _runs(change.T):
        walls.append([(c + 1) * resolution, r0 * resolution, (c + 1) * resolution, r1 * resolution])
    return walls


def _runs(mask: np.ndarray) -> list[tuple[int, int, int]]:
    """``(row, start, stop)`` of each run of True along each row of ``mask``."""
    out = []
    padded = np.zeros((mask.shape[0], mask.shape[1] + 2), dtype=np.int8)
    padded[:, 1:-1] = mask
    diff = np.diff(padded, axis=1)  # +1 where a run starts, -1 one past where it stops
    for r in np.flatnonzero(mask.any(axis=1)):
        starts = np.flatnonzero(diff[r] == 1)
        stops = np.flatnonzero(diff[r] == -1)
        out += [(int(r), int(a), int(b)) for a, b in zip(starts, stops, strict=True)]
    return out
