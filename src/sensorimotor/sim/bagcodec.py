"""Decoding a bag's LaserScan and Odometry messages in bulk: the speed of ``sim.rosbag``.

Decoding each message into an object (``rosbags``' deserializer) costs about as much as all the
rest of an import. The few numbers a row needs sit at fixed byte offsets once the lengths of a
message's strings are known, so the messages of a topic are grouped by total length and string
lengths, each group is one ``(K, L)`` uint8 array, and every field is read for the whole group
at once. Both encodings start alike: 4 bytes (ROS 2: the CDR encapsulation header, little-endian
``00 01``; ROS 1: the header's ``seq``), ``stamp.sec`` and ``stamp.nanosec`` (uint32), then
``frame_id`` (uint32 length, bytes; ROS 2 counts and writes a final NUL). After it, ROS 2 aligns
each field to its size counted from byte 4; ROS 1 packs. ``decode`` falls back on the generic
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

import numpy as np


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
                out.pose[i] = (p.x, p.y, yaw(q.x, q.y, q.z, q.w))
            continue
        out.stamp[rows] = _u32(a, 4) * 1_000_000_000 + _u32(a, 8)
        f = _f(a, pos, 7, 8)  # (K, 7) x, y, z, qx, qy, qz, qw
        out.pose[rows] = np.stack([f[:, 0], f[:, 1], yaw(f[:, 3], f[:, 4], f[:, 5], f[:, 6])], 1)
    return out


def yaw(x, y, z, w):
    """The heading (rotation about z) of unit quaternions, (-pi, pi]."""
    if np.ndim(x) == 0:
        return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
