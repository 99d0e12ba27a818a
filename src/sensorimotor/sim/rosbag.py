"""Recordings of real robots: a ROS bag (2-D laser scans and odometry) made into a database.

``import_bag`` reads ROS 1 bags and ROS 2 bags (sqlite3 or MCAP) with ``rosbags`` (pure Python,
no ROS installation; the ``[ros]`` extra, imported only when a bag is read or written) and
returns a Database that trains, evaluates and analyses as a simulated one does.

How the rows are made:

- **Clock.** Each message is placed at its header stamp (the time the sensor saw it), or at the
  bag's receive time for a topic whose stamps are all zero and for ``geometry_msgs/Twist``,
  which has no header. Messages out of order are sorted (and counted); one stamped more than
  ``MAX_BACK_JUMP_S`` before an earlier one of its topic is a clock jump and refused.
- **Rows** sit on a fixed-rate grid on the scan clock (``rate``; default the median scan rate):
  scan ``i`` falls in slot ``round((t_i - t_0) * rate)``, the scan nearest to a slot's time
  keeps it. A row needs the next slot filled too, since its command is the motion that leads
  there: a time gap drops the row before it (counted as ``gaps``, ``slots_empty``).
- **Readings** (``sensor_msgs/LaserScan``): each ray of the layout takes the nearest beam to its
  angle, ``round((angle - angle_min) / angle_increment)``; REP 117: ``+inf`` and a reading above
  ``range_max`` mean no return and read the range, NaN, ``-inf`` and a reading below
  ``range_min`` are invalid and drop the scan (counted); every reading is capped at the range.
  With ``scan_range`` (``import-bag`` without ``--range``) the range is the scans' own: a scan's
  no return reads its ``range_max``, and the layout's range is the largest (``meta.source.range``
  says which); a sensor that reaches 3.5 m then reads 3.5 where nothing is in view, not 10.
  A scan whose angles do not reach a ray of the layout is refused (choose another ``--fov``).
- **Poses** (``nav_msgs/Odometry``): x, y and the yaw of the orientation, interpolated linearly
  (the yaw unwrapped) at each row's scan stamp, in the odometry frame (``meta.source.frames``).
  A message whose orientation is not a unit quaternion (``(0, 0, 0, 0)``), or whose pose is not
  finite in float32 (``1e300``), is dropped (counted: ``odom_bad_quaternion``,
  ``odom_not_finite``), and so is one that leaves the path faster than ``MAX_SPEED`` and comes
  back (``odom_jumps``).
  A row outside the odometry's time span, or between two odometry messages further apart than
  ``MAX_ODOM_GAP_S``, is dropped (counted). The laser is taken to sit at the robot's origin.
  With ``frame`` (``map``, say), the transform from it to the odometry frame on ``/tf`` (or
  ``/tf_static``: what a localiser such as amcl or slam_toolbox publishes), interpolated the
  same way, is composed with the odometry pose; a row without it is dropped (counted). The
  commands stay odometry's: the motion executed, not the localiser's corrections.
- **Commands** ``(d, r)``: by default the motion executed between a row and the next, in the
  simulator's terms (``sim.core.apply_motor``: move ``d`` along the heading, then turn ``r``):
  ``d`` the displacement projected on the heading (negative when reversing; sideways drift,
  which ``(d, r)`` cannot express, is dropped and its largest value reported), ``r`` the change
  of heading in (-pi, pi]. With ``cmd`` (``geometry_msgs/Twist`` or ``TwistStamped``): the last
  command sent at or before the row's scan, ``(linear.x * dt, angular.z * dt)`` with ``dt`` the
  time to the next row (rows before the first command are dropped, counted). A row whose
  command moves faster than ``MAX_SPEED`` or turns faster than ``MAX_TURN_RATE`` for the time
  to the next row (an odometry jump, a ``/cmd_vel`` of 1e30) is dropped (``rows_too_fast``).

The world is unknown unless one is given: ``meta.world`` is then only a name (the bag's), and
the stages that need walls say so (``Database.has_walls``). With ``world``, the poses must be in
that world's frame (a bag recorded in the map's frame): one outside it is refused.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.files import check_input, check_input_folder
from sensorimotor.sim import MAX_LASER_RANGE, bagcodec
from sensorimotor.sim.bagcodec import CMD_TYPES, ODOM_TYPES, SCAN_TYPES, rosbags_reader
from sensorimotor.sim.core import DEFAULT_LAYOUT, MAX_RAYS, SensorLayout, spread_layout
from sensorimotor.sim.database import Database
from sensorimotor.sim.world import BUILTIN_WORLDS, World
from sensorimotor.version import __version__

MAX_BACK_JUMP_S = 1.0  # s: a stamp this far before an earlier one is a clock jump, not jitter
MAX_ODOM_GAP_S = 1.0  # s: no pose is interpolated between odometry messages further apart
MAX_TF_GAP_S = 5.0  # s: the same for /tf's transform to the odometry frame (published slower)
TF_TOPICS = ("/tf", "/tf_static")
# the physically possible, for the rows' rate: no robot recorded with a 2-D laser moves 50 m/s
# or turns 100 rad/s (16 turns a second); the simulator's agent, written as a bag at 10 Hz,
# moves at most 10 units/s and turns 35 rad/s
MAX_SPEED = 50.0  # units (m)/s
MAX_TURN_RATE = 100.0  # rad/s
MOTION_SLACK = 0.01  # units or rad a row may move beyond them (same-stamp jitter)
MAX_BAG_BYTES = 1 << 40  # a bag file: 1 TB, far beyond a recording that fits in memory


@dataclass(frozen=True)
class BagTopics:
    """The topics to read (``cmd``: None takes the commands from odometry) and the frame of the
    poses (``frame``: None keeps odometry's; else /tf's ``frame`` -> odometry frame transform is
    composed with odometry, e.g. ``map``)."""

    scan: str = "/scan"
    odom: str = "/odom"
    cmd: str | None = None
    frame: str | None = None


def ray_layout(rays: int = 5, fov: float = 1.2, max_range: float = 10.0) -> SensorLayout:
    """The layout to read from the scans: ``sim.core.spread_layout``'s (the defaults: the
    paper's five rays at -0.6 .. 0.6 rad, range 10); InputError if out of range."""
    return spread_layout(rays, fov, max_range)


def summary(db: Database) -> str:
    """One line on an imported database: its rows, and what was dropped."""
    src = db.meta["source"]
    c = src["counts"]
    return (
        f"{len(db):,} rows at {src['rate_hz']:.4g} Hz from {c['scans']:,} scans of "
        f"{src['bag']}, range {db.max_range:g} ({src.get('range', '--range')}); "
        f"dropped {c['scans_invalid']:,} invalid scans, {c['gaps']:,} gaps "
        f"({c['slots_empty']:,} empty slots), {c['rows_without_odometry']:,} rows without odometry"
    )


def bag_format(path: Path) -> str:
    """``rosbag1``, ``rosbag2/sqlite3`` or ``rosbag2/mcap``, from the bag's files."""
    if path.is_dir():
        files = {p.suffix for p in path.iterdir()}
        return "rosbag2/mcap" if ".mcap" in files else "rosbag2/sqlite3"
    return "rosbag2/mcap" if path.suffix == ".mcap" else "rosbag1"


def check_bag(bag: str | Path) -> Path:
    """The bag through the input door (``files``): a ROS 1 ``.bag`` or an ``.mcap`` is a
    regular file, a ROS 2 bag folder holds only regular files (its ``.db3`` or ``.mcap`` and
    ``metadata.yaml``), each at most ``MAX_BAG_BYTES``: a FIFO, a device, a link to
    ``/dev/zero`` is refused before rosbags opens anything."""
    bag = Path(bag)
    try:
        is_dir = bag.is_dir()
    except OSError:
        is_dir = False
    if is_dir:
        check_input_folder(bag, "ROS 2 bag", MAX_BAG_BYTES)
    else:
        check_input(bag, "ROS bag", MAX_BAG_BYTES)
    return bag


CHUNK = 50_000  # messages of a topic decoded at once (bounds the raw bytes held)


@dataclass
class _Stream:
    """One topic as read, in bag order: receive times (ns), decoded chunks (scans:
    ``bagcodec.Scans``; odometry: ``bagcodec.Poses``; commands: (K, 3) header stamp, linear.x,
    angular.z), and the raw messages waiting to be decoded."""

    recv: list
    values: list
    raw: list


def _read(bag: Path, topics: BagTopics, layout: SensorLayout, decoder: str) -> tuple:
    """Every message of the three topics, decoded to the few numbers a row needs."""
    any_reader, typestore = rosbags_reader()
    angles = np.asarray(layout.angles, dtype=np.float64)
    wanted = {"scan": topics.scan, "odom": topics.odom}
    if topics.cmd is not None:
        wanted["cmd"] = topics.cmd
    streams = {k: _Stream([], [], []) for k in wanted}
    frames: dict[str, str] = {}
    try:
        reader = any_reader([bag], default_typestore=typestore)
        reader.open()
    except Exception as err:  # rosbags raises its own error classes per format
        raise InputError(f"{bag}: cannot open as a ROS bag ({_why(err)})") from None
    try:
        by_topic = {c.topic: c for c in reader.connections}
        kinds = {"scan": SCAN_TYPES, "odom": ODOM_TYPES, "cmd": CMD_TYPES}
        conns = []
        for key, topic in wanted.items():
            conn = by_topic.get(topic)
            if conn is None:
                have = ", ".join(sorted(by_topic)) or "none"
                raise InputError(f"{bag}: no topic {topic!r} (topics: {have}); see --{key}")
            if conn.msgtype not in kinds[key]:
                raise InputError(
                    f"{bag}: topic {topic!r} is {conn.msgtype}, expected {' or '.join(kinds[key])}"
                )
            conns += [c for c in reader.connections if c.topic == topic]
        key_of = {topic: key for key, topic in wanted.items()}
        tf: list = []  # (static, stamp ns, child, x, y, yaw) of each transform from the frame
        if topics.frame is not None:
            tf_conns = [c for c in reader.connections if c.topic in TF_TOPICS]
            if not tf_conns:
                raise InputError(f"{bag}: no /tf or /tf_static topic, which --frame needs")
            for c in tf_conns:
                if not c.msgtype.endswith("/TFMessage"):
                    raise InputError(f"{bag}: topic {c.topic!r} is {c.msgtype}, not TFMessage")
            conns += tf_conns
        ros1 = not reader.is2
        msgtype = {key: by_topic[topic].msgtype for key, topic in wanted.items()}

        def flush(key: str) -> None:
            s = streams[key]
            raws, s.raw[:] = list(s.raw), []

            def slow(i: int):
                return reader.deserialize(raws[i], msgtype[key])

            if key == "scan" and decoder == "fast":
                s.values.append(bagcodec.decode_scans(raws, ros1, angles, slow))
            elif key == "odom" and decoder == "fast":
                s.values.append(bagcodec.decode_odometry(raws, ros1, slow))
            else:
                s.values.append(_decode_slow(key, [slow(i) for i in range(len(raws))], angles))
            if key not in frames and raws:
                first = slow(0)
                if key == "odom":
                    frames["odom"], frames["base"] = first.header.frame_id, first.child_frame_id
                elif key == "scan":
                    frames["scan"] = first.header.frame_id

        try:
            for conn, recv, raw in reader.messages(connections=conns):
                if conn.topic in TF_TOPICS:
                    _transforms(reader.deserialize(raw, conn.msgtype), conn.topic, topics, tf)
                    continue
                key = key_of[conn.topic]
                s = streams[key]
                s.recv.append(recv)
                s.raw.append(raw)
                if len(s.raw) >= CHUNK:
                    flush(key)
            for key in streams:
                flush(key)
        except InputError:
            raise
        except Exception as err:  # a truncated or damaged bag, a message that does not decode
            raise InputError(f"{bag}: damaged or truncated bag ({_why(err)})") from None
    finally:
        reader.close()
    return streams, frames, tf


def _transforms(msg, topic: str, topics: BagTopics, out: list) -> None:
    """Keep the transforms of a tf2_msgs/TFMessage whose parent is ``topics.frame``."""
    for tr in msg.transforms:
        if tr.header.frame_id.lstrip("/") == topics.frame.lstrip("/"):
            v, q = tr.transform.translation, tr.transform.rotation
            stamp = tr.header.stamp.sec * 1_000_000_000 + tr.header.stamp.nanosec
            yaw = bagcodec.yaw(q.x, q.y, q.z, q.w)
            out.append((topic == "/tf_static", stamp, tr.child_frame_id.lstrip("/"), v.x, v.y, yaw))


def _to_frame(bag: Path, frame: str, odom_frame: str, tf: list, t, pose, seconds) -> tuple:
    """Poses (K, 3) in ``frame``: the /tf transform ``frame`` -> ``odom_frame`` at each time
    ``t`` (a static one, or interpolated between two at most MAX_TF_GAP_S apart) composed with
    the odometry ``pose``; and whether each time has one."""
    mine = [row for row in tf if row[2] == odom_frame.lstrip("/")]
    if frame.lstrip("/") == odom_frame.lstrip("/"):
        return pose, np.ones(len(t), dtype=bool)
    if not mine:
        seen = sorted({row[2] for row in tf}) or ["none"]
        raise InputError(
            f"{bag}: no transform {frame} -> {odom_frame} (the odometry's frame) on /tf or "
            f"/tf_static; children of {frame}: {', '.join(seen)}"
        )
    static = [row for row in mine if row[0]]
    if static:
        _, _, _, x, y, yaw = static[-1]
        trans, covered = np.tile([x, y, yaw], (len(t), 1)), np.ones(len(t), dtype=bool)
    else:
        ns = np.array([row[1] for row in mine], dtype=np.int64)
        order = np.argsort(ns, kind="stable")
        xyyaw = np.array([row[3:] for row in mine], dtype=np.float64)[order]  # (T, 3)
        trans, covered = _interpolate(seconds(ns[order]), xyyaw, t, MAX_TF_GAP_S)
    c, s_ = np.cos(trans[:, 2]), np.sin(trans[:, 2])
    x = trans[:, 0] + c * pose[:, 0] - s_ * pose[:, 1]
    y = trans[:, 1] + s_ * pose[:, 0] + c * pose[:, 1]
    return np.stack([x, y, _wrap(trans[:, 2] + pose[:, 2])], axis=1), covered


def _decode_slow(key: str, msgs: list, angles: np.ndarray):
    """The generic path: messages decoded by rosbags, read field by field."""
    if key == "scan":
        out = bagcodec.decode_scans([b""] * len(msgs), False, angles, msgs.__getitem__)
        return out
    if key == "odom":
        return bagcodec.decode_odometry([b""] * len(msgs), False, msgs.__getitem__)
    values = []
    for m in msgs:
        twist = m.twist if hasattr(m, "header") else m
        stamp = (
            m.header.stamp.sec * 1_000_000_000 + m.header.stamp.nanosec
            if hasattr(m, "header")
            else 0
        )
        values.append((stamp, twist.linear.x, twist.angular.z))
    return np.array(values, dtype=np.float64).reshape(-1, 3)


def _why(err: Exception) -> str:
    text = str(err).strip().splitlines()
    return f"{type(err).__name__}: {text[0]}" if text else type(err).__name__


def _clock(bag: Path, name: str, stamp, recv, counts: dict, clocks: dict) -> tuple:
    """Times (ns, int64) and the order that sorts them: header stamps, or receive times when a
    topic has no stamps. Out-of-order messages are counted; a jump back is refused."""
    ns = np.asarray(stamp, dtype=np.int64)
    clocks[name] = "header stamps"
    if not ns.any():
        ns = np.asarray(recv, dtype=np.int64)
        clocks[name] = "bag receive times"
    if len(ns) > 1:
        back = np.maximum.accumulate(ns)[:-1] - ns[1:]  # how far each is before the latest
        if back.max() > MAX_BACK_JUMP_S * 1e9:
            i = int(np.argmax(back > MAX_BACK_JUMP_S * 1e9)) + 1
            raise InputError(
                f"{bag}: {name} message {i} is stamped {back[i - 1] / 1e9:.3f} s before an "
                "earlier one (the clock jumped back: split the bag there)"
            )
        counts[f"{name}_out_of_order"] = int((back > 0).sum())
    return ns, np.argsort(ns, kind="stable")


def _scan_range(bag: Path, scans) -> float:
    """The largest ``range_max`` of the scans; InputError where one is not a positive number."""
    top = scans.range_max
    bad = ~(np.isfinite(top) & (top > 0))
    if bad.any():
        raise InputError(
            f"{bag}: scan {int(np.argmax(bad))} has range_max {top[bad][0]} (not a positive "
            "number): give --range"
        )
    if top.max() > MAX_LASER_RANGE:
        raise InputError(f"{bag}: range_max {top.max():g} > {MAX_LASER_RANGE:g}: give --range")
    return float(top.max())


def _rep117(bag: Path, scans, layout: SensorLayout, counts: dict, own: bool = False) -> tuple:
    """Readings (K, R) and whether each scan is valid (REP 117: NaN and below range_min, -inf
    included, invalid; above range_max, +inf included, no return: the range); InputError for a
    scan whose angles do not reach a ray."""
    if not scans.covered.all():
        i = int(np.argmin(scans.covered))
        lo, hi = np.sort(scans.span[i])
        outside = [a for a in layout.angles if not lo - 1e-9 <= a <= hi + 1e-9]
        what = f"ray at {outside[0]:g} rad lies outside" if outside else "rays are not reached"
        raise InputError(
            f"{bag}: the scans cover angles {lo:.3f}..{hi:.3f} rad, the layout's {what} "
            "(choose --fov within them)"
        )
    b = scans.beams
    nan = np.isnan(b)
    close = (b < scans.range_min[:, None]) & ~nan  # -inf included
    far = (b > scans.range_max[:, None]) & ~nan  # +inf included
    valid = ~(nan | close).any(axis=1)
    counts["beams_nan"] = int(nan.sum())
    counts["beams_too_close"] = int(close.sum())
    counts["beams_no_return"] = int(far[valid].sum())
    none = scans.range_max[:, None] if own else layout.max_range  # what no return reads
    readings = np.minimum(np.where(far | ~valid[:, None], none, b), layout.max_range)
    return readings, valid


def _concat(chunks: list, cls):
    return cls(*(np.concatenate([getattr(c, f) for c in chunks]) for f in cls.__dataclass_fields__))


def import_bag(
    bag: str | Path,
    topics: BagTopics = BagTopics(),
    layout: SensorLayout = DEFAULT_LAYOUT,
    rate: float | None = None,
    world: World | None = None,
    decoder: str = "fast",
    scan_range: bool = False,
) -> Database:
    """Read ``bag`` (a ROS 1 ``.bag``, a ROS 2 bag folder or ``.mcap``) into a Database: one row
    per slot of the ``rate`` grid (see the module docstring for every rule), the meta recording
    the bag, its topics and frames, and what was dropped. InputError, one line, for a bag that
    cannot be made into one. ``decoder="rosbags"`` decodes every message with rosbags (the
    reference ``bagcodec``'s bulk reading is checked against; slower, the same database).
    ``scan_range``: the range is the scans' ``range_max``, not ``layout.max_range``."""
    bag = check_bag(bag)
    if not 1 <= len(layout.angles) <= MAX_RAYS:
        raise InputError(f"--rays must be 1 to {MAX_RAYS:,}, got {len(layout.angles)}")
    if rate is not None and not (math.isfinite(rate) and rate > 0):
        raise InputError(f"--rate must be a positive number of Hz, got {rate}")
    if decoder not in ("fast", "rosbags"):
        raise ValueError(f"decoder must be 'fast' or 'rosbags', got {decoder!r}")
    streams, frames, tf = _read(bag, topics, layout, decoder)
    for key, s in streams.items():
        if not s.recv:
            raise InputError(f"{bag}: topic {getattr(topics, key)!r} has no messages")
    counts: dict = {}
    clocks: dict[str, str] = {}
    scans = _concat(streams["scan"].values, bagcodec.Scans)
    ns, order = _clock(bag, "scan", scans.stamp, streams["scan"].recv, counts, clocks)
    origin = int(ns[order[0]])  # the first scan's stamp: times are seconds after it

    def seconds(ns: np.ndarray) -> np.ndarray:
        return (ns - origin) / 1e9

    if scan_range:
        layout = SensorLayout(layout.angles, _scan_range(bag, scans))
    readings, valid = _rep117(bag, scans, layout, counts, own=scan_range)
    readings, valid = readings[order], valid[order]
    ts = seconds(ns[order])
    counts["scans"] = len(ts)
    counts["scans_invalid"] = int((~valid).sum())
    if len(ts) > 1:
        dt = np.diff(ts)
        counts["scans_same_stamp"] = int((dt == 0).sum())
        step = float(np.median(dt[dt > 0])) if (dt > 0).any() else 0.0
    else:
        step = 0.0
    if rate is None:
        if step <= 0:
            raise InputError(f"{bag}: fewer than two scans at distinct times: give --rate")
        rate = 1.0 / step
    elif step > 0 and rate > 1.5 / step:
        raise InputError(
            f"{bag}: --rate {rate:g} Hz is above the scans' {1 / step:.4g} Hz (a row a scan at "
            "most: every other slot would be empty)"
        )
    ts, readings = ts[valid], readings[valid]
    if len(ts) < 2:
        raise InputError(
            f"{bag}: {len(ts)} valid scans of {counts['scans']} (a reading on a ray NaN, -inf "
            f"or below range_min: {counts['beams_nan']:,} NaN, {counts['beams_too_close']:,} "
            "too close); need 2 or more"
        )
    t0 = ts[0]
    slot = np.rint((ts - t0) * rate).astype(np.int64)  # (S,) grid slot of each valid scan
    off = np.abs(ts - (t0 + slot / rate))
    # the scan nearest to its slot's time keeps the slot: sort by (slot, distance), keep firsts
    pick = np.lexsort((off, slot))
    keep = pick[np.r_[True, slot[pick][1:] != slot[pick][:-1]]]
    counts["scans_merged"] = len(slot) - len(keep)
    slot, t = slot[keep], ts[keep]
    sensors = readings[keep]  # (K, R) float64
    jumps = np.diff(slot)
    counts["gaps"] = int((jumps > 1).sum())
    counts["slots_empty"] = int((jumps - 1).sum())
    counts["rows_without_next"] = int((jumps > 1).sum()) + 1  # before a gap, and the last

    odom = _concat(streams["odom"].values, bagcodec.Poses)
    odom, odom_recv = _valid_odometry(bag, odom, streams["odom"].recv, counts)
    to, oo = _clock(bag, "odom", odom.stamp, odom_recv, counts, clocks)
    to, odom = _drop_jumps(seconds(to[oo]), odom.pose[oo], counts)  # (O,), (O, 3)
    pose, covered = _interpolate(to, odom, t)  # (K, 3), (K,) bool
    has_next = np.r_[jumps == 1, False]
    ok = has_next & covered & np.r_[covered[1:], False]
    counts["rows_without_odometry"] = int((has_next & ~ok).sum())
    dt_next = np.r_[np.diff(t), 0.0]
    if topics.cmd is None:
        nxt = np.roll(pose, -1, axis=0)
        dx, dy = nxt[:, 0] - pose[:, 0], nxt[:, 1] - pose[:, 1]
        c, s_ = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        d = dx * c + dy * s_
        lateral = -dx * s_ + dy * c
        r = _wrap(nxt[:, 2] - pose[:, 2])
        counts["max_sideways_drift"] = float(np.abs(lateral[ok]).max()) if ok.any() else 0.0
        how = "odometry: d = displacement along the heading, r = change of heading, to the next row"
    else:
        cmd = np.concatenate(streams["cmd"].values)  # (C, 3) stamp, linear.x, angular.z
        tc, oc = _clock(bag, "cmd", cmd[:, 0], streams["cmd"].recv, counts, clocks)
        tc, cmd = seconds(tc[oc]), cmd[oc, 1:]
        j = np.searchsorted(tc, t, side="right") - 1  # the last command at or before each row
        sent = j >= 0
        counts["rows_before_first_cmd"] = int((ok & ~sent).sum())
        ok &= sent
        j = np.maximum(j, 0)
        d, r = cmd[j, 0] * dt_next, cmd[j, 1] * dt_next
        how = f"{topics.cmd}: d = linear.x * dt, r = angular.z * dt, dt to the next row"
    with np.errstate(invalid="ignore"):
        possible = (np.abs(d) <= MAX_SPEED * dt_next + MOTION_SLACK) & (
            np.abs(r) <= MAX_TURN_RATE * dt_next + MOTION_SLACK
        )
    counts["rows_too_fast"] = int((ok & ~possible).sum())
    ok &= possible
    if topics.frame is not None:  # the commands stay odometry's: the motion executed
        pose, known = _to_frame(bag, topics.frame, frames["odom"], tf, t, pose, seconds)
        counts["rows_without_transform"] = int((ok & ~known).sum())
        ok &= known
    frames["poses"] = topics.frame if topics.frame is not None else frames["odom"]
    rows = np.flatnonzero(ok)
    if len(rows) == 0:
        raise InputError(
            f"{bag}: no row has a scan, the next slot's scan and odometry around both "
            f"({counts['scans']} scans; odometry {to[0]:.3f}..{to[-1]:.3f} s, scans "
            f"{t[0]:.3f}..{t[-1]:.3f} s)"
        )
    motors = np.stack([d, r], axis=1)[rows]
    out_pose, out_sensors = pose[rows], sensors[rows]
    arrays = [out_sensors, motors, out_pose]
    with np.errstate(over="ignore"):
        if not all(np.isfinite(a.astype(np.float32)).all() for a in arrays):
            raise InputError(f"{bag}: odometry or commands hold NaN or inf (in float32)")
    if world is not None:
        check_inside(bag, world, out_pose)
    counts["rows"] = len(rows)
    meta = {
        "format": "sensorimotor-database/1",
        "world": world.to_dict() if world is not None else {"name": bag_name(bag)},
        "seed": None,
        "steps": len(rows),
        "sensor_layout": layout.to_dict(),
        "noise_std": 0.0,
        "behaviour": "a real robot's (recorded)",
        "source": {
            "kind": "rosbag",
            "bag": str(bag),
            "format": bag_format(bag),
            "topics": {
                "scan": topics.scan,
                "odom": topics.odom,
                "cmd": topics.cmd,
                "tf": list(TF_TOPICS) if topics.frame is not None else None,
            },
            "frames": frames,
            "clocks": clocks,
            "rate_hz": float(rate),
            "start_s": origin / 1e9 + float(t[rows[0]]),
            "duration_s": float(t[rows[-1]] - t[rows[0]]),
            "beam": "nearest beam to each ray's angle",
            "range": "each scan's range_max (no return reads it)"
            if scan_range
            else "--range (no return reads it)",
            "motors": how,
            "counts": counts,
        },
        "version": __version__,
    }
    return Database(*(a.astype(np.float32) for a in arrays), meta=meta)


def _valid_odometry(bag: Path, odom, recv: list, counts: dict) -> tuple:
    """The odometry messages with a unit quaternion and a pose finite in float32, and their
    receive times; the others dropped and counted."""
    pose = odom.pose
    with np.errstate(over="ignore", invalid="ignore"):
        finite = np.isfinite(pose.astype(np.float32)).all(axis=1)
    unit = ~np.isnan(pose[:, 2])  # bagcodec.unit_yaw: NaN for a quaternion not of unit norm
    counts["odom_bad_quaternion"] = int((~unit).sum())
    counts["odom_not_finite"] = int((unit & ~finite).sum())
    if not finite.any():
        raise InputError(
            f"{bag}: no odometry message has a finite pose and a unit quaternion "
            f"({counts['odom_bad_quaternion']:,} quaternions not of unit norm)"
        )
    return bagcodec.Poses(odom.stamp[finite], pose[finite]), np.asarray(recv)[finite]


def _drop_jumps(to: np.ndarray, pose: np.ndarray, counts: dict) -> tuple:
    """Odometry without the messages that leave the path faster than ``MAX_SPEED`` and come
    back (an outlier, counted as ``odom_jumps``)."""
    out = np.zeros(len(to), dtype=bool)
    if len(to) >= 3:
        step = np.hypot(np.diff(pose[:, 0]), np.diff(pose[:, 1]))
        fast = step > MAX_SPEED * np.diff(to) + MOTION_SLACK
        out[1:-1] = fast[:-1] & fast[1:]
    counts["odom_jumps"] = int(out.sum())
    return to[~out], pose[~out]


def _interpolate(to, odom: np.ndarray, t, gap: float = MAX_ODOM_GAP_S) -> tuple:
    """Poses (K, 3) at times ``t`` from odometry (O, 3) at times ``to`` (sorted), and whether each
    time lies between two odometry messages at most ``gap`` seconds apart."""
    yaw = np.unwrap(odom[:, 2])
    pose = np.stack(
        [np.interp(t, to, odom[:, 0]), np.interp(t, to, odom[:, 1]), _wrap(np.interp(t, to, yaw))],
        axis=1,
    )
    hi = np.clip(np.searchsorted(to, t, side="left"), 0, len(to) - 1)
    lo = np.clip(np.searchsorted(to, t, side="right") - 1, 0, len(to) - 1)
    covered = (t >= to[0]) & (t <= to[-1]) & (to[hi] - to[lo] <= gap)
    return pose, covered


def _wrap(a: np.ndarray) -> np.ndarray:
    """Angles wrapped into (-pi, pi] (the simulator's ``wrap_angle``)."""
    out = np.mod(a + np.pi, 2 * np.pi) - np.pi
    return np.where(out == -np.pi, np.pi, out)


def check_inside(bag: Path, world: World, poses: np.ndarray) -> None:
    outside = (
        (poses[:, 0] < 0)
        | (poses[:, 1] < 0)
        | (poses[:, 0] > world.width)
        | (poses[:, 1] > world.height)
    )
    if outside.any():
        i = int(np.argmax(outside))
        raise InputError(
            f"{bag}: pose {i} ({poses[i, 0]:.3f}, {poses[i, 1]:.3f}) lies outside the "
            f"{world.width:g} x {world.height:g} world {world.name!r}: --world needs poses in "
            "its frame"
        )


def bag_name(bag: Path) -> str:
    """The name of a recording without a world (runs are named by it): the bag's, made safe."""
    name = re.sub(r"[^A-Za-z0-9_.+-]+", "-", bag.stem if bag.is_file() else bag.name)
    name = name.strip("_.+-") or "bag"
    return f"{name}-bag" if name in BUILTIN_WORLDS else name
