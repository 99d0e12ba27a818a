"""MRPT's binary serialisation, read and written here (no MRPT installation): the objects of
rawlogs (laser scans, odometry) and of occupancy grids.

MRPT (the Mobile Robot Programming Toolkit) distributes many classic laser datasets of the field
as *rawlogs*: a stream of serialised objects, gzip-compressed or plain. Each object is one byte
``0x80 + len(name)``, the class name, one version byte, the class's fields little-endian (strings
as a uint32 length and the bytes, nested objects the same way), and one end byte ``0x88``. The
reader here is written against that format (no MRPT installation); it knows the classes and
versions below and refuses any other with one line naming the file, the byte and the class:

- ``CSensoryFrame`` 0..2 (a count and observations) and ``CActionCollection`` 0 (a count and
  actions): the "sensory frame / action collection" form, frames and actions alternating;
- ``CObservation2DRangeScan`` 4..7: aperture, direction, maximum range, the sensor's pose on the
  robot, the ranges (float32, metres) and their validity, timestamp, label;
- ``CActionRobotMovement2D`` 4..6 estimated from odometry: the odometry increment (a ``CPose2D``
  in the robot's frame before the move);
- ``CObservationOdometry`` 0..2: the observations form (scans and absolute odometry poses);
- ``CPose2D`` 0 (float) and 1 (double), ``CPose3D`` 1 (a homogeneous ``CMatrixD`` 0);
- ``COccupancyGridMap2D`` 1..6 (``read_gridmap``).

Every count and length is bounded (``MAX_*``), every float must be finite, and the stream must
end where its last object ends: a cut, damaged or hostile file is an InputError, one line.
"""

from __future__ import annotations

import math
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.files import check_input

SHIPPED = Path(__file__).parent / "data" / "mrpt"
"""Two real datasets shipped with the package (BSD-3-Clause, MRPT; provenance and notice in its
``README.md``): a real robot's rawlog and a real campus's occupancy grid."""
SENA_LOG = SHIPPED / "sena_telecom_faculty_one_loop.rawlog"
CAMPUS_MAP = SHIPPED / "malaga_campus_2006.gridmap.gz"

MAX_FILE_BYTES = 1 << 30  # a rawlog or gridmap as stored (gzip or plain)
MAX_DATA_BYTES = 2 << 30  # once decompressed: a gzip bomb stops here
MAX_BEAMS = 100_000  # beams of one scan (a 2-D laser has a few thousand at most)
MAX_ITEMS = 1_000  # observations in a frame, actions in a collection
MAX_STRING = 1 << 16  # a sensor label
MAX_CELLS = 200_000_000  # cells of an occupancy grid (a campus at 8 cm is 5 million)
MAX_RANGE_M = 1e4  # metres: a laser's maximum range
MAX_STEP_M = 1e3  # metres: one odometry increment
END = 0x88  # the byte that ends every object
MRPT_EPOCH_S = 11_644_473_600  # seconds from 1601-01-01 (MRPT's clock, 100 ns ticks) to 1970


@dataclass
class Scan:
    """One ``CObservation2DRangeScan``: ranges (N,) float32 m, validity (N,) bool."""

    aperture: float
    right_to_left: bool
    max_range: float
    sensor: tuple[float, float, float]  # x, y, yaw of the laser on the robot (m, rad)
    ranges: np.ndarray = field(repr=False)
    valid: np.ndarray = field(repr=False)
    stamp: int  # MRPT ticks (100 ns since 1601), 0 when unknown
    label: str


@dataclass
class Odometry:
    """A ``CActionRobotMovement2D`` (an increment: ``absolute`` False) or a
    ``CObservationOdometry`` (a pose: ``absolute`` True), x, y, phi (m, rad)."""

    pose: tuple[float, float, float]
    absolute: bool
    stamp: int = 0


class Stream:
    """A bounded little-endian reader of one file's bytes; every error names the file and the
    byte where it was found."""

    def __init__(self, data: bytes, path: Path):
        self.data, self.path, self.pos = data, path, 0

    def fail(self, why: str, at: int | None = None) -> InputError:
        return InputError(f"{self.path}: {why} at byte {self.pos if at is None else at:,}")

    def take(self, n: int) -> bytes:
        if n < 0 or self.pos + n > len(self.data):
            raise self.fail(f"truncated ({n:,} bytes wanted, {len(self.data) - self.pos:,} left)")
        out = self.data[self.pos : self.pos + n]
        self.pos += n
        return out

    def unpack(self, fmt: str):
        s = struct.Struct("<" + fmt)
        values = s.unpack(self.take(s.size))
        return values[0] if len(values) == 1 else values

    def real(self, fmt: str = "f", lo: float = -math.inf, hi: float = math.inf) -> float:
        at = self.pos
        v = float(self.unpack(fmt))
        if not (math.isfinite(v) and lo <= v <= hi):
            raise self.fail(f"a number out of bounds ({v!r}, expected {lo:g}..{hi:g})", at)
        return v

    def count(self, limit: int, what: str) -> int:
        at = self.pos
        n = self.unpack("I")
        if n > limit:
            raise self.fail(f"{what} count {n:,} above the limit {limit:,}", at)
        return n

    def boolean(self) -> bool:
        at = self.pos
        b = self.unpack("B")
        if b > 1:
            raise self.fail(f"a boolean byte is {b}", at)
        return bool(b)

    def string(self) -> str:
        n = self.count(MAX_STRING, "string length")
        try:
            return self.take(n).decode("utf-8")
        except UnicodeDecodeError:
            raise self.fail("a string that is not UTF-8") from None

    def header(self) -> tuple[str, int, int]:
        """The class name and version of the next object, and where it starts."""
        at = self.pos
        b = self.unpack("B")
        if not b & 0x80 or not 1 <= b - 0x80 <= 100:
            raise self.fail(f"not an MRPT object (byte 0x{b:02x})", at)
        raw = self.take(b - 0x80)
        if not re.fullmatch(rb"[A-Za-z_][A-Za-z0-9_:]*", raw):
            raise self.fail("a class name that is not one", at)
        return raw.decode("ascii"), self.unpack("B"), at

    def end(self, name: str) -> None:
        at = self.pos
        if self.unpack("B") != END:
            raise self.fail(f"{name} does not end where its fields do (damaged)", at)

    def versions(self, name: str, version: int, known: range, at: int) -> None:
        if version not in known:
            raise self.fail(
                f"{name} version {version} is not one this reader knows "
                f"({known.start}..{known.stop - 1})",
                at,
            )


def read_bytes(path: str | Path, what: str) -> bytes:
    """The bytes of ``path``, gunzipped when it is gzip; bounded; InputError if it cannot be."""
    path = check_input(path, what, MAX_FILE_BYTES)
    try:
        raw = path.read_bytes()
    except OSError as err:
        raise InputError(f"{path}: cannot read the {what} ({err.strerror})") from None
    if raw[:2] != b"\x1f\x8b":
        return raw
    out, chunks, size = zlib.decompressobj(wbits=31), [], 0
    data = raw
    try:
        while data and not out.eof:
            chunk = out.decompress(data, 1 << 24)
            size += len(chunk)
            if size > MAX_DATA_BYTES:
                raise InputError(
                    f"{path}: more than {MAX_DATA_BYTES:,} bytes once decompressed, too large "
                    f"for a {what}"
                )
            chunks.append(chunk)
            data = out.unconsumed_tail
        if not out.eof:
            raise InputError(f"{path}: truncated gzip (the {what} is cut)")
    except zlib.error as err:
        raise InputError(f"{path}: damaged gzip ({err})") from None
    if out.unused_data.strip(b"\0"):
        raise InputError(f"{path}: bytes after the end of the gzip stream (damaged)")
    return b"".join(chunks)


def _pose2d(s: Stream) -> tuple[float, float, float]:
    name, version, at = s.header()
    if name != "CPose2D":
        raise s.fail(f"expected a CPose2D, found {name}", at)
    s.versions(name, version, range(0, 2), at)
    fmt = "f" if version == 0 else "d"
    x = s.real(fmt, -1e9, 1e9)
    y = s.real(fmt, -1e9, 1e9)
    phi = s.real(fmt, -1e3, 1e3)
    s.end(name)
    return x, y, phi


def _pose3d(s: Stream) -> tuple[float, float, float]:
    """A ``CPose3D`` 1 (a 4 x 4 homogeneous ``CMatrixD``): x, y and yaw."""
    name, version, at = s.header()
    if name != "CPose3D":
        raise s.fail(f"expected a CPose3D, found {name}", at)
    s.versions(name, version, range(1, 2), at)
    mname, mversion, mat = s.header()
    if mname != "CMatrixD":
        raise s.fail(f"expected a CMatrixD, found {mname}", mat)
    s.versions(mname, mversion, range(0, 1), mat)
    if s.unpack("II") != (4, 4):
        raise s.fail("the pose's matrix is not 4 x 4", mat)
    m = [s.real("d", -1e9, 1e9) for _ in range(16)]
    s.end(mname)
    s.end(name)
    return m[3], m[7], math.atan2(m[4], m[0])


def _scan(s: Stream, version: int, at: int) -> Scan:
    s.versions("CObservation2DRangeScan", version, range(4, 8), at)
    aperture = s.real("f", 0.0, 2 * math.pi + 1e-6)
    right_to_left = s.boolean()
    max_range = s.real("f", 0.0, MAX_RANGE_M)
    sensor = _pose3d(s)
    if version < 6:  # the sensor pose's covariance, dropped in version 6
        mname, mversion, mat = s.header()
        if mname != "CMatrix":
            raise s.fail(f"expected a CMatrix, found {mname}", mat)
        s.versions(mname, mversion, range(0, 1), mat)
        rows, cols = s.unpack("II")
        if rows * cols > 64:
            raise s.fail(f"a covariance of {rows} x {cols}", mat)
        s.take(4 * rows * cols)
        s.end(mname)
    n = s.count(MAX_BEAMS, "beam")
    ranges = np.frombuffer(s.take(4 * n), dtype="<f4").astype(np.float32)
    valid = np.frombuffer(s.take(n), dtype=np.uint8)
    if not np.isfinite(ranges).all():
        raise s.fail("a range that is NaN or infinite")
    s.real("f")  # stdError
    stamp = s.unpack("Q")
    s.real("f")  # beamAperture
    label = ""
    if version >= 5:
        label = s.string()
        # deltaPitch: a float32, but the 2006 logs of version 6 hold 8 bytes (a double) here
        wide = version == 6 and s.pos + 4 < len(s.data) and s.data[s.pos + 4] != END
        s.real("d" if wide else "f")
    if version >= 7 and s.boolean():  # intensities
        s.take(4 * n)
    return Scan(aperture, right_to_left, max_range, sensor, ranges, valid != 0, stamp, label)


def _movement(s: Stream, version: int, at: int) -> Odometry:
    s.versions("CActionRobotMovement2D", version, range(4, 7), at)
    method = s.unpack("i")
    if method != 0:
        raise s.fail(
            f"a CActionRobotMovement2D estimated by method {method}, not odometry (0): its "
            "increment is not stored",
            at,
        )
    pose = _pose2d(s)
    if max(abs(pose[0]), abs(pose[1])) > MAX_STEP_M:
        raise s.fail(f"an odometry increment of {pose[0]:g}, {pose[1]:g} m", at)
    s.unpack("I")  # motion model
    for _ in range(6):
        s.real("f")
    s.count(10_000_000, "particle")
    for _ in range(4 if version < 5 else 6):
        s.real("f")
    s.boolean()
    s.real("f"), s.real("f")  # velocities
    s.boolean()
    s.unpack("ii")  # encoder ticks
    stamp = s.unpack("Q") if version >= 6 else 0
    return Odometry(pose, False, stamp)


def _odometry_obs(s: Stream, version: int, at: int) -> Odometry:
    s.versions("CObservationOdometry", version, range(0, 3), at)
    pose = _pose2d(s)
    s.string()
    stamp = s.unpack("Q")
    if version >= 1:
        encoders = s.boolean()
        if encoders or version < 2:
            s.unpack("ii")
        velocities = s.boolean()
        if version < 2:
            s.real("f"), s.real("f")
        elif velocities:
            s.real("d"), s.real("d"), s.real("d")
    return Odometry(pose, True, stamp)


def _object(s: Stream):
    """The next object: a Scan, an Odometry, or a list of them (a frame, a collection)."""
    name, version, at = s.header()
    if name == "CSensoryFrame":
        s.versions(name, version, range(0, 3), at)
        if version < 2:
            s.unpack("I")  # an ID
        if version == 0:
            s.unpack("Q")
        out = [_object(s) for _ in range(s.count(MAX_ITEMS, "observation"))]
    elif name == "CActionCollection":
        s.versions(name, version, range(0, 1), at)
        out = [_object(s) for _ in range(s.count(MAX_ITEMS, "action"))]
    elif name == "CObservation2DRangeScan":
        out = _scan(s, version, at)
    elif name == "CActionRobotMovement2D":
        out = _movement(s, version, at)
    elif name == "CObservationOdometry":
        out = _odometry_obs(s, version, at)
    else:
        raise s.fail(
            f"class {name} is not one this reader knows (CSensoryFrame, CActionCollection, "
            "CObservation2DRangeScan, CActionRobotMovement2D, CObservationOdometry)",
            at,
        )
    if isinstance(out, list) and any(isinstance(o, list) for o in out):
        raise s.fail(f"a {name} inside a frame or collection", at)
    s.end(name)
    return out


def read_rawlog(path: str | Path) -> tuple[list, str]:
    """The entries of a rawlog in order (a Scan, an Odometry, or a list of them for a frame or
    a collection) and its form (``frames`` or ``observations``); InputError if it cannot be."""
    path = Path(path)
    s = Stream(read_bytes(path, "rawlog"), path)
    if not s.data:
        raise InputError(f"{path}: empty rawlog")
    entries = []
    while s.pos < len(s.data):
        entries.append(_object(s))
    form = "frames" if any(isinstance(e, list) for e in entries) else "observations"
    return entries, form


def compose(a, b) -> tuple[float, float, float]:
    """Pose ``a`` composed with the relative pose ``b`` (both x, y, phi)."""
    c, s_ = math.cos(a[2]), math.sin(a[2])
    return a[0] + c * b[0] - s_ * b[1], a[1] + s_ * b[0] + c * b[1], a[2] + b[2]


def inverse_compose(a, b) -> tuple[float, float, float]:
    """The pose of ``a`` relative to ``b``."""
    dx, dy = a[0] - b[0], a[1] - b[1]
    c, s_ = math.cos(b[2]), math.sin(b[2])
    return c * dx + s_ * dy, -s_ * dx + c * dy, a[2] - b[2]


def wrap(a: np.ndarray) -> np.ndarray:
    out = np.mod(a + np.pi, 2 * np.pi) - np.pi
    return np.where(out == -np.pi, np.pi, out)


# --- writing (the tests' round trip) ------------------------------------------------------


def head(name: str, version: int) -> bytes:
    return bytes([0x80 + len(name)]) + name.encode("ascii") + bytes([version])


def _pose3d_bytes(x: float, y: float, yaw: float) -> bytes:
    c, s_ = math.cos(yaw), math.sin(yaw)
    m = [c, -s_, 0, x, s_, c, 0, y, 0, 0, 1, 0, 0, 0, 0, 1]
    matrix = head("CMatrixD", 0) + struct.pack("<II16d", 4, 4, *m) + bytes([END])
    return head("CPose3D", 1) + matrix + bytes([END])


def scan_bytes(
    ranges,
    aperture: float,
    max_range: float,
    stamp: int,
    label: str = "LASER",
    valid=None,
    sensor=(0.0, 0.0, 0.0),
) -> bytes:
    """A ``CObservation2DRangeScan`` version 6 (right to left) as MRPT writes it."""
    ranges = np.asarray(ranges, dtype="<f4")
    valid = np.ones(len(ranges), dtype=np.uint8) if valid is None else np.asarray(valid, np.uint8)
    body = struct.pack("<fBf", aperture, 1, max_range) + _pose3d_bytes(*sensor)
    body += struct.pack("<I", len(ranges)) + ranges.tobytes() + valid.tobytes()
    text = label.encode("utf-8")
    body += struct.pack("<fQfI", 0.01, stamp, 0.0, len(text)) + text + struct.pack("<f", 0.0)
    return head("CObservation2DRangeScan", 6) + body + bytes([END])


def movement_bytes(dx: float, dy: float, dphi: float, stamp: int) -> bytes:
    """A ``CActionRobotMovement2D`` version 6 from odometry, increment (dx, dy, dphi)."""
    pose = head("CPose2D", 1) + struct.pack("<3d", dx, dy, dphi) + bytes([END])
    body = struct.pack("<i", 0) + pose + struct.pack("<I6fI6f", 0, *[0.01] * 6, 300, *[0.1] * 6)
    body += struct.pack("<BffBiiQ", 0, 0.0, 0.0, 0, 0, 0, stamp)
    return head("CActionRobotMovement2D", 6) + body + bytes([END])


# --- occupancy grids -------------------------------------------------------------------------

MAX_GRID_TAIL = 1 << 20  # bytes of options after the cells (about 500 in MRPT's maps)
LOGODDS_K = 16.0  # MRPT's cells are log-odds times 16: P(free) = 1 / (1 + exp(-cell / 16))


@dataclass
class Grid:
    """A ``COccupancyGridMap2D``: ``free`` (size_y, size_x) float32 probability that each cell
    is free (MRPT's convention: 1 free, 0 occupied, 0.5 unknown), row 0 at ``y_min``."""

    free: np.ndarray = field(repr=False)
    x_min: float
    y_min: float
    resolution: float
    version: int
    bits: int


def read_gridmap(path: str | Path) -> Grid:
    """An MRPT occupancy grid (``.gridmap`` or ``.gridmap.gz``: one ``COccupancyGridMap2D``,
    versions 1..6): the header (cells per side, extent, resolution) and the cells, 8- or 16-bit
    log-odds (versions 3 on) or probabilities (before 3); the options after the cells are not
    read (they hold no geometry) but bounded, and the object must end the file."""
    path = Path(path)
    s = Stream(read_bytes(path, "gridmap"), path)
    if not s.data:
        raise InputError(f"{path}: empty gridmap")
    name, version, at = s.header()
    if name != "COccupancyGridMap2D":
        raise s.fail(f"expected a COccupancyGridMap2D, found {name}", at)
    s.versions(name, version, range(1, 7), at)
    bits = s.unpack("B") if version >= 2 else 8
    if bits not in (8, 16):
        raise s.fail(f"cells of {bits} bits (expected 8 or 16)")
    size_x, size_y = s.unpack("II")
    if not (size_x > 0 and size_y > 0 and size_x * size_y <= MAX_CELLS):
        raise s.fail(f"a grid of {size_x:,} x {size_y:,} cells (at most {MAX_CELLS:,} cells)")
    x_min, x_max = s.real("f", -1e6, 1e6), s.real("f", -1e6, 1e6)
    y_min, y_max = s.real("f", -1e6, 1e6), s.real("f", -1e6, 1e6)
    resolution = s.real("f", 1e-4, 1e3)
    for lo, hi, n, axis in ((x_min, x_max, size_x, "x"), (y_min, y_max, size_y, "y")):
        if not abs((hi - lo) / resolution - n) <= 1.0 + 1e-3 * n:
            raise s.fail(
                f"{axis} extent {lo:g}..{hi:g} does not hold {n:,} cells of {resolution:g}"
            )
    dtype = np.dtype("<i1" if bits == 8 else "<i2")
    cells = np.frombuffer(s.take(size_x * size_y * dtype.itemsize), dtype=dtype)
    tail = len(s.data) - s.pos
    if not 1 <= tail <= MAX_GRID_TAIL or s.data[-1] != END:
        raise InputError(
            f"{path}: {tail:,} bytes after the cells, not the options of a COccupancyGridMap2D "
            "ending the file (cut, damaged or not one grid)"
        )
    if version >= 3:  # log-odds
        scale = LOGODDS_K * (1 if bits == 8 else 256)
        table = 1.0 / (1.0 + np.exp(-np.arange(-(1 << bits - 1), 1 << bits - 1) / scale))
        free = table.astype(np.float32)[cells.astype(np.int32) + (1 << bits - 1)]
    else:  # probabilities as unsigned cells
        free = (cells.view(f"<u{dtype.itemsize}") / float((1 << bits) - 1)).astype(np.float32)
    return Grid(free.reshape(size_y, size_x), x_min, y_min, resolution, version, bits)


def gridmap_bytes(free: np.ndarray, resolution: float, x_min: float = 0.0, y_min: float = 0.0):
    """A ``COccupancyGridMap2D`` version 3, 8-bit log-odds, from P(free) (rows, cols), row 0 at
    ``y_min``, with a short options tail (for tests: the reader does not read it)."""
    free = np.clip(np.asarray(free, dtype=np.float64), 1e-6, 1 - 1e-6)
    cells = np.clip(np.rint(LOGODDS_K * np.log(free / (1 - free))), -127, 127).astype("<i1")
    rows, cols = cells.shape
    body = struct.pack("<BII", 8, cols, rows)
    body += struct.pack(
        "<5f", x_min, x_min + cols * resolution, y_min, y_min + rows * resolution, resolution
    )
    return head("COccupancyGridMap2D", 3) + body + cells.tobytes() + bytes(16) + bytes([END])
