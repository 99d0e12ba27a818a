"""ROS bags' bytes: LaserScan and Odometry decoded in bulk (the speed of ``sim.rosbag``), and
a database written as a bag (``write_bag``: the tests' round trip, the benchmark's input).

Decoding each message into an object (``rosbags``' deserializer) costs about as much as all the
rest of an import. The few numbers a row needs sit at fixed byte offsets once the lengths of a
message's strings are known, so the messages of a topic are grouped by total length and string
lengths, each group is one ``(K, L)`` uint8 array, and every field is read for the whole group
at once. Both encodings start alike: 4 bytes (ROS 2: the CDR encapsulation header, little-endian
``00 01``; ROS 1: the header's ``seq``), ``stamp.sec`` and ``stamp.nanosec`` (uint32), then
``frame_id`` (uint32 length, bytes; ROS 2 counts and writes a final NUL). After it, ROS 2 aligns
each field to its size counted from byte 4; ROS 1 packs. Both decoders fall back on the generic
decoder for a message it cannot read this way (another encoding); ``sim.rosbag`` can also be
asked for the generic decoder alone (``decoder="rosbags"``), the reference the tests compare.

LaserScan after the header: angle_min, angle_max, angle_increment, time_increment, scan_time,
range_min, range_max (float32), ranges (uint32 count, float32 each), intensities.
Odometry after the header: child_frame_id (string), pose.pose.position x, y, z and orientation
x, y, z, w (float64), ...
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.sim.core import SensorLayout

if TYPE_CHECKING:
    from sensorimotor.sim.database import Database

INSTALL_HINT = "install the [ros] extra: pip install -e '.[ros]'"
SCAN_TYPES = ("sensor_msgs/msg/LaserScan",)
ODOM_TYPES = ("nav_msgs/msg/Odometry",)
CMD_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")


def rosbags_reader():
    """The ``rosbags`` reader, or an InputError telling how to install it."""
    try:
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore
    except ImportError:
        raise InputError(INSTALL_HINT) from None
    return AnyReader, get_typestore(Stores.ROS2_HUMBLE)


@dataclass(frozen=True)
class Scans:
    """Decoded scans: the beams nearest to the layout's rays and what they need, in input order."""

    stamp: np.ndarray  # (K,) int64 header stamp, ns
    beams: np.ndarray  # (K, R) float64 the beam nearest to each ray (NaN where not covered)
    covered: np.ndarray  # (K,) bool every ray's angle lies within the scan's beams
    range_min: np.ndarray  # (K,) float64
    range_max: np.ndarray  # (K,) float64
    span: np.ndarray  # (K, 2) float64 angles of the first and last beams (rad)


@dataclass(frozen=True)
class Poses:
    """Decoded odometry, in input order."""

    stamp: np.ndarray  # (K,) int64 header stamp, ns
    pose: np.ndarray  # (K, 3) float64 x, y, yaw


def _u32(a: np.ndarray, at: int) -> np.ndarray:
    return np.ascontiguousarray(a[:, at : at + 4]).view("<u4")[:, 0].astype(np.int64)


def _f(a: np.ndarray, at: int, n: int, size: int) -> np.ndarray:
    """(K, n) float64 from ``n`` consecutive little-endian floats of ``size`` bytes at ``at``."""
    return np.ascontiguousarray(a[:, at : at + n * size]).view(f"<f{size}").astype(np.float64)


def _align(pos: int, size: int, ros1: bool) -> int:
    return pos if ros1 else 4 + -(-(pos - 4) // size) * size


def _groups(raws: list, lengths_at: Callable[[np.ndarray], list[int]]):
    """Yield ``(rows, a, offsets)``: rows of ``raws`` of one total length and one set of string
    lengths (``lengths_at`` reads them from a group), ``a`` their (K, L) bytes."""
    lengths = np.fromiter(map(len, raws), dtype=np.int64, count=len(raws))
    for size in np.unique(lengths):
        rows = np.flatnonzero(lengths == size)
        a = np.frombuffer(b"".join([raws[i] for i in rows]), dtype=np.uint8)
        a = a.reshape(len(rows), int(size))
        yield from _split(rows, a, lengths_at)


def _split(rows, a, lengths_at):
    """Split a group by the string lengths ``lengths_at`` reads (None: too short to read)."""
    keys = lengths_at(a)
    if keys is None:  # the generic decoder's
        yield rows, a, None
        return
    uniq, inv = np.unique(np.stack(keys, axis=1), axis=0, return_inverse=True)
    for j, k in enumerate(uniq):
        take = np.flatnonzero(inv.ravel() == j)
        yield rows[take], a[take], [int(v) for v in k]


def decode_scans(raws: list, ros1: bool, angles: np.ndarray, slow) -> Scans:
    """The scans of ``raws`` (serialized LaserScans); ``slow(i)`` decodes message i generically
    (a rosbags message) when these bytes are not the little-endian layout read here."""
    k, r = len(raws), len(angles)
    out = Scans(
        np.zeros(k, np.int64),
        np.full((k, r), np.nan),
        np.zeros(k, bool),
        np.zeros(k),
        np.zeros(k),
        np.zeros((k, 2)),
    )

    def lengths_at(a):
        return [_u32(a, 12)] if a.shape[1] >= 16 else None

    for rows, a, lens in _groups(raws, lengths_at):
        pos = None if lens is None else _align(16 + lens[0], 4, ros1)
        if pos is None or pos + 32 > a.shape[1] or not (ros1 or (a[:, :2] == (0, 1)).all()):
            for i in rows:
                _scan_from_msg(out, i, slow(i), angles)
            continue
        out.stamp[rows] = _u32(a, 4) * 1_000_000_000 + _u32(a, 8)
        f = _f(a, pos, 7, 4)  # (K, 7) angle_min .. range_max
        n = _u32(a, pos + 28)
        _fill(out, rows, f[:, 0], f[:, 2], n, f[:, 5], f[:, 6], angles, a, pos + 32)
    return out


def _fill(out: Scans, rows, amin, inc, n, rmin, rmax, angles, a=None, at=0, ranges=None):
    """Store scans ``rows``: the beam nearest to each ray, ``round((angle - amin) / inc)``."""
    with np.errstate(invalid="ignore", divide="ignore"):
        idx = np.rint((angles[None, :] - amin[:, None]) / inc[:, None])  # (K, R)
    ok = np.isfinite(idx).all(axis=1) & (inc != 0)
    ok &= ((idx >= 0) & (idx < n[:, None])).all(axis=1)
    if a is not None:
        ok &= at + 4 * n <= a.shape[1]
    idx = np.where(ok[:, None], idx, 0).astype(np.int64)
    if a is not None:
        cols = at + 4 * idx[:, :, None] + np.arange(4)  # (K, R, 4) bytes of each beam
        beams = np.ascontiguousarray(a[np.arange(len(a))[:, None, None], cols])
        beams = beams.view("<f4")[..., 0].astype(np.float64)  # (K, R)
    else:
        beams = ranges[idx[0]][None, :].astype(np.float64)
    out.beams[rows] = np.where(ok[:, None], beams, np.nan)
    out.covered[rows] = ok
    out.range_min[rows], out.range_max[rows] = rmin, rmax
    out.span[rows] = np.stack([amin, amin + inc * np.maximum(n - 1, 0)], axis=1)


def _scan_from_msg(out: Scans, i: int, msg, angles) -> None:
    s = msg.header.stamp
    out.stamp[i] = s.sec * 1_000_000_000 + s.nanosec
    one = [np.array([v], dtype=np.float64) for v in (msg.angle_min, msg.angle_increment)]
    n = np.array([len(msg.ranges)])
    rmin, rmax = np.array([msg.range_min]), np.array([msg.range_max])
    _fill(out, [i], *one, n, rmin, rmax, angles, ranges=np.asarray(msg.ranges))


def decode_odometry(raws: list, ros1: bool, slow) -> Poses:
    """The odometry of ``raws`` (serialized Odometry): stamp, x, y and yaw."""
    k = len(raws)
    out = Poses(np.zeros(k, np.int64), np.zeros((k, 3)))

    def lengths_at(a):
        if a.shape[1] < 16:
            return None
        n = _u32(a, 12)
        child = 16 + n if ros1 else 4 + -(-(12 + n) // 4) * 4  # child_frame_id's length, per row
        if (child + 4 > a.shape[1]).any():
            return None
        m = np.ascontiguousarray(a[np.arange(len(a))[:, None], child[:, None] + np.arange(4)])
        return [n, m.view("<u4")[:, 0].astype(np.int64)]

    for rows, a, lens in _groups(raws, lengths_at):
        ok = lens is not None and (ros1 or (a[:, :2] == (0, 1)).all())
        if ok:
            child = _align(16 + lens[0], 4, ros1)
            pos = _align(child + 4 + lens[1], 8, ros1)
            ok = pos + 56 <= a.shape[1]
        if not ok:
            for i in rows:
                msg = slow(i)
                s, p, q = msg.header.stamp, msg.pose.pose.position, msg.pose.pose.orientation
                out.stamp[i] = s.sec * 1_000_000_000 + s.nanosec
                out.pose[i] = (p.x, p.y, unit_yaw(q.x, q.y, q.z, q.w))
            continue
        out.stamp[rows] = _u32(a, 4) * 1_000_000_000 + _u32(a, 8)
        f = _f(a, pos, 7, 8)  # (K, 7) x, y, z, qx, qy, qz, qw
        heading = unit_yaw(f[:, 3], f[:, 4], f[:, 5], f[:, 6])
        out.pose[rows] = np.stack([f[:, 0], f[:, 1], heading], 1)
    return out


QUATERNION_TOLERANCE = 0.01  # |x^2 + y^2 + z^2 + w^2 - 1| of an orientation taken as a rotation


def unit_yaw(x, y, z, w):
    """``yaw``, or NaN for a quaternion that is not of unit norm (0, 0, 0, 0 says nothing of a
    heading: the importer drops the message and counts it)."""
    with np.errstate(all="ignore"):  # 1e300 squared: inf, not a unit norm
        norm = np.square(np.asarray(x, dtype=np.float64)) + np.square(y) + np.square(z)
        bad = ~(np.abs(norm + np.square(w) - 1) <= QUATERNION_TOLERANCE)
        heading = yaw(x, y, z, w)
    if np.ndim(x) == 0:
        return math.nan if bad else heading
    return np.where(bad, np.nan, heading)


def yaw(x, y, z, w):
    """The heading (rotation about z) of unit quaternions, (-pi, pi]."""
    if np.ndim(x) == 0:
        return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


FORMATS = ("rosbag2/sqlite3", "rosbag2/mcap", "rosbag1")
BAG_START_NS = 1_700_000_000_000_000_000  # the first stamp of a written bag (ns since 1970)


def scan_geometry(layout: SensorLayout, beams: int) -> tuple[float, float]:
    """``(angle_min, angle_increment)`` of a ``beams``-beam scan, centred on the heading, one of
    whose beams lies on each of ``layout``'s rays (so that a written bag reads back exactly):
    the increment divides the rays' smallest spacing (about a degree for 360 beams)."""
    angles = np.sort(np.asarray(layout.angles, dtype=np.float64))
    spacing = float(np.diff(angles).min()) if len(angles) > 1 else 2 * math.pi / beams
    inc = spacing / max(1, round(spacing / (2 * math.pi / beams)))
    return -(beams // 2) * inc, inc


def write_bag(
    db: Database,
    path: str | Path,
    fmt: str = "rosbag2/sqlite3",
    rate: float = 10.0,
    beams: int = 360,
    cmd: bool = False,
    times: np.ndarray | None = None,
    received: np.ndarray | None = None,
    odom_frame: tuple[float, float, float] | None = None,
) -> Path:
    """Write ``db`` as a ROS bag of ``fmt`` (one of FORMATS) that ``import_bag`` reads back to
    the same rows (but the last, whose step leads nowhere recorded): ``/scan`` LaserScans of
    ``beams`` beams (``scan_geometry``) whose beams on the layout's rays hold the readings (the
    range as ``+inf``, no return, REP 117) and the others NaN (not measured), and ``/odom``
    Odometry with each row's pose, both stamped at ``rate`` Hz; with ``cmd``, ``/cmd_vel`` Twists
    ``(d, r) * rate``. ``times`` (N,) stamps the rows elsewhere (seconds after the first's
    default, ``row / rate``: gaps, clock jumps) and ``received`` the times the recorder got
    them (default ``times``; readers yield messages in this order: disorder). With
    ``odom_frame`` (x, y, yaw: where the odometry frame ``odom`` lies in the database's frame,
    ``map``; ROS 2 only), ``/odom`` holds the poses in ``odom`` and ``/tf`` the transform
    ``map`` -> ``odom`` at each row. For tests, benchmarks, and ROS tools that want a simulated
    run."""
    if fmt not in FORMATS:
        raise InputError(f"unknown bag format {fmt!r}: use one of {', '.join(FORMATS)}")
    rosbags_reader()  # the install hint when the extra is missing
    from rosbags.typesys import Stores, get_typestore

    ros1 = fmt == "rosbag1"
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T = ts.types
    msg = {k: T[k].__msgtype__ for k in (*SCAN_TYPES, *ODOM_TYPES, CMD_TYPES[0])}
    serialize = ts.serialize_ros1 if ros1 else ts.serialize_cdr
    angle_min, inc = scan_geometry(db.layout, beams)
    index = np.rint((np.asarray(db.layout.angles) - angle_min) / inc).astype(np.int64)
    ranges = np.full((len(db), beams), np.nan, dtype=np.float32)
    ranges[:, index] = np.where(db.sensors >= db.max_range, np.inf, db.sensors)
    if times is None:
        times = np.arange(len(db)) / rate
    stamps = BAG_START_NS + np.rint(np.asarray(times, dtype=np.float64) * 1e9).astype(np.int64)
    if received is None:
        received = times
    recv = BAG_START_NS + np.rint(np.asarray(received, dtype=np.float64) * 1e9).astype(np.int64)
    path = Path(path)
    if path.exists():
        raise InputError(f"{path}: exists already; a bag is not overwritten")
    if ros1:
        from rosbags.rosbag1 import Writer

        writer = Writer(path)
    else:
        from rosbags.rosbag2 import StoragePlugin, Writer

        plugin = StoragePlugin.MCAP if fmt.endswith("mcap") else StoragePlugin.SQLITE3
        writer = Writer(path, version=9, storage_plugin=plugin)
    vec, zero36 = T["geometry_msgs/msg/Vector3"], np.zeros(36)
    with writer:
        cs = writer.add_connection("/scan", SCAN_TYPES[0], typestore=ts)
        co = writer.add_connection("/odom", ODOM_TYPES[0], typestore=ts)
        cc = writer.add_connection("/cmd_vel", CMD_TYPES[0], typestore=ts) if cmd else None
        tf_type = "tf2_msgs/msg/TFMessage"
        ct = writer.add_connection("/tf", tf_type, typestore=ts) if odom_frame else None
        if odom_frame is not None:
            if ros1:
                raise InputError("write_bag: odom_frame is written in ROS 2 bags only")
            ox, oy, oyaw = odom_frame
            co_, so_ = math.cos(oyaw), math.sin(oyaw)
        for i in range(len(db)):
            ns, at = int(stamps[i]), int(recv[i])
            stamp = T["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9)

            def header(frame: str, stamp=stamp, i=i):
                extra = {"seq": i} if ros1 else {}
                return T["std_msgs/msg/Header"](stamp=stamp, frame_id=frame, **extra)

            scan = T[SCAN_TYPES[0]](
                header=header("base_scan"),
                angle_min=angle_min,
                angle_max=angle_min + inc * (beams - 1),
                angle_increment=inc,
                time_increment=0.0,
                scan_time=1.0 / rate,
                range_min=0.0,
                range_max=float(db.max_range),
                ranges=ranges[i],
                intensities=np.zeros(0, dtype=np.float32),
            )
            writer.write(cs, at, serialize(scan, msg[SCAN_TYPES[0]]))
            x, y, h = (float(v) for v in db.poses[i])
            if ct is not None:  # the pose in odom: the inverse of map -> odom applied
                dx, dy = x - ox, y - oy
                x, y, h = co_ * dx + so_ * dy, -so_ * dx + co_ * dy, h - oyaw
                h = math.atan2(math.sin(h), math.cos(h))
                tr = T["geometry_msgs/msg/TransformStamped"](
                    header=header("map"),
                    child_frame_id="odom",
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=vec(x=ox, y=oy, z=0.0),
                        rotation=T["geometry_msgs/msg/Quaternion"](
                            x=0.0, y=0.0, z=math.sin(oyaw / 2), w=math.cos(oyaw / 2)
                        ),
                    ),
                )
                writer.write(ct, at, serialize(T[tf_type](transforms=[tr]), tf_type))
            d, r = (float(v) * rate for v in db.motors[i])
            twist = T["geometry_msgs/msg/Twist"](
                linear=vec(x=d, y=0.0, z=0.0), angular=vec(x=0.0, y=0.0, z=r)
            )
            pose = T["geometry_msgs/msg/Pose"](
                position=T["geometry_msgs/msg/Point"](x=x, y=y, z=0.0),
                orientation=T["geometry_msgs/msg/Quaternion"](
                    x=0.0, y=0.0, z=math.sin(h / 2), w=math.cos(h / 2)
                ),
            )
            odom = T[ODOM_TYPES[0]](
                header=header("odom"),
                child_frame_id="base_link",
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=zero36),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](twist=twist, covariance=zero36),
            )
            writer.write(co, at, serialize(odom, msg[ODOM_TYPES[0]]))
            if cc is not None:
                writer.write(cc, at, serialize(twist, msg[CMD_TYPES[0]]))
    return path
