"""Recordings of real robots in MRPT's format: a rawlog (laser scans and odometry) made into a
database. The objects are read by ``sim.mrpt`` (the format, its classes and versions, bounds).

How the rows are made (``import_rawlog``):

- **Odometry.** The robot's pose is the composition of the odometry increments from (0, 0, 0)
  at the start of the log (or, in the observations form, the odometry readings, made to start
  at (0, 0, 0)). A frame whose scan comes before any odometry in the observations form is
  dropped (counted).
- **Poses** are the laser's: the robot's odometry pose composed with the scan's sensor pose on
  the robot (x, y and yaw; the simulator's agent is its lasers' centre), times ``scale``.
- **Readings.** Each ray of the layout takes the nearest beam to its angle (beam ``i`` at
  ``-aperture/2 + i aperture/(N-1)``, mirrored when the scan runs left to right); a beam marked
  invalid, or above the scan's maximum range, is no return and reads the range; every reading
  is multiplied by ``scale`` (metres to units) and capped at the range. A scan whose aperture
  does not reach a ray of the layout is refused.
- **Commands** ``(d, r)``: the motion between a row's pose and the next's, in the simulator's
  terms (``sim.core.apply_motor``): ``d`` the displacement along the heading, ``r`` the change
  of heading in (-pi, pi]; the sideways drift, which (d, r) cannot express, is reported. The
  last scan has no next and is dropped (counted).

The default ``scale`` is 1: a unit is a metre, the paper's range of 10 units is 10 m (a corridor
or a room is then the size of the paper's 50 x 50 worlds' features), and readings beyond 10 m
read 10. The world is unknown (``meta.world`` a name alone) unless one is given (``world``,
``--world``): the poses, from odometry from (0, 0, 0) and times the scale, must then lie in its
frame, inside it.
"""

from __future__ import annotations

import math
import re
import struct
from pathlib import Path

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.sim.core import DEFAULT_LAYOUT, SensorLayout
from sensorimotor.sim.database import Database
from sensorimotor.sim.mrpt import (
    END,
    MRPT_EPOCH_S,
    Odometry,
    Scan,
    compose,
    head,
    inverse_compose,
    movement_bytes,
    read_rawlog,
    scan_bytes,
    wrap,
)
from sensorimotor.sim.rosbag import check_inside
from sensorimotor.sim.world import BUILTIN_WORLDS, World
from sensorimotor.version import __version__


def beam_index(scan: Scan, angles: np.ndarray) -> np.ndarray:
    """The nearest beam of ``scan`` to each angle (rad, counter-clockwise from the heading),
    or -1 where the angle lies outside the scan's aperture."""
    n = len(scan.ranges)
    if n == 1:
        return np.where(np.abs(angles) <= 1e-9, 0, -1)
    step = scan.aperture / (n - 1)
    offset = angles + scan.aperture / 2 if scan.right_to_left else scan.aperture / 2 - angles
    i = np.rint(offset / step).astype(np.int64) if step > 0 else np.zeros(len(angles), np.int64)
    inside = (offset >= -1e-9) & (offset <= scan.aperture + 1e-9)
    return np.where(inside, np.clip(i, 0, n - 1), -1)


def import_rawlog(
    log: str | Path,
    layout: SensorLayout = DEFAULT_LAYOUT,
    scale: float = 1.0,
    sensor: str | None = None,
    world: World | None = None,
) -> Database:
    """Read an MRPT rawlog into a Database (see the module docstring for every rule); with
    ``world``, the walls are known: the poses (times ``scale``) must lie inside it."""
    log = Path(log)
    if not (math.isfinite(scale) and 0 < scale <= 1e6):
        raise InputError(f"--scale must be a positive number (units a metre), got {scale}")
    entries, form = read_rawlog(log)
    counts = {
        "frames": 0,
        "actions": 0,
        "scans": 0,
        "scans_other_sensor": 0,
        "scans_before_odometry": 0,
        "frames_without_action": 0,
        "beams_invalid": 0,
        "beams_no_return": 0,
    }
    odo = (0.0, 0.0, 0.0)
    first_abs = None
    moved = True  # whether odometry arrived since the last scan kept
    seen_odometry = form == "frames"
    kept: list[tuple[Scan, tuple]] = []
    labels: list[str] = []
    for entry in entries:
        items = entry if isinstance(entry, list) else [entry]
        if isinstance(entry, list):
            is_frame = any(isinstance(o, Scan) for o in items) or not any(
                isinstance(o, Odometry) for o in items
            )
            counts["frames" if is_frame else "actions"] += 1
        for item in items:
            if isinstance(item, Odometry):
                if item.absolute:
                    if first_abs is None:
                        first_abs = item.pose
                    odo = inverse_compose(item.pose, first_abs)
                else:
                    odo = compose(odo, item.pose)
                seen_odometry = moved = True
        scans = [o for o in items if isinstance(o, Scan)]
        if not scans:
            continue
        counts["scans"] += len(scans)
        if sensor is None:
            sensor = scans[0].label
        mine = [o for o in scans if o.label == sensor]
        counts["scans_other_sensor"] += len(scans) - len(mine)
        labels += [o.label for o in scans if o.label not in labels]
        if not mine:
            continue
        if not seen_odometry:
            counts["scans_before_odometry"] += 1
            continue
        if not moved and kept:
            counts["frames_without_action"] += 1
        kept.append((mine[0], odo))
        moved = False
    if not kept:
        have = ", ".join(repr(x) for x in labels) or "none"
        raise InputError(f"{log}: no scan of sensor {sensor!r} with odometry (scans: {have})")
    angles = np.asarray(layout.angles, dtype=np.float64)
    sensors = np.empty((len(kept), len(angles)), dtype=np.float64)
    poses = np.empty((len(kept), 3), dtype=np.float64)
    stamps = np.empty(len(kept), dtype=np.int64)
    for k, (scan, pose) in enumerate(kept):
        idx = beam_index(scan, angles)
        if (idx < 0).any():
            ray = float(angles[int(np.argmax(idx < 0))])
            raise InputError(
                f"{log}: scan {k} covers {-scan.aperture / 2:.3f}..{scan.aperture / 2:.3f} rad, "
                f"the layout's ray at {ray:g} rad lies outside (choose --fov within it)"
            )
        r = scan.ranges[idx].astype(np.float64)
        ok = scan.valid[idx]
        far = ok & ((r > scan.max_range) | (r < 0))
        counts["beams_invalid"] += int((~ok).sum())
        counts["beams_no_return"] += int(far.sum())
        r = np.where(ok & ~far, r * scale, layout.max_range)
        sensors[k] = np.minimum(r, layout.max_range)
        x, y, yaw = compose(pose, scan.sensor)
        poses[k] = (x * scale, y * scale, yaw)
        stamps[k] = scan.stamp
    poses[:, 2] = wrap(poses[:, 2])
    counts["rows_without_next"] = 1
    nxt = poses[1:]
    here = poses[:-1]
    dx, dy = nxt[:, 0] - here[:, 0], nxt[:, 1] - here[:, 1]
    c, s_ = np.cos(here[:, 2]), np.sin(here[:, 2])
    d = dx * c + dy * s_
    lateral = -dx * s_ + dy * c
    r = wrap(nxt[:, 2] - here[:, 2])
    n = len(kept) - 1
    if n < 1:
        raise InputError(f"{log}: one scan with odometry; a row needs the next scan too")
    counts["max_sideways_drift"] = float(np.abs(lateral).max())
    counts["rows"] = n
    arrays = [sensors[:n], np.stack([d, r], axis=1), poses[:n]]
    if not all(np.isfinite(a).all() for a in arrays):
        raise InputError(f"{log}: odometry too large to integrate (NaN or inf)")
    dt = np.diff(stamps) / 1e7
    good = dt[(dt > 0) & np.isfinite(dt)]
    rate = float(1.0 / np.median(good)) if len(good) and (stamps > 0).all() else None
    if world is not None:
        check_inside(log, world, arrays[2])
    first = kept[0][0]
    meta = {
        "format": "sensorimotor-database/1",
        "world": world.to_dict() if world is not None else {"name": rawlog_name(log)},
        "seed": None,
        "steps": n,
        "sensor_layout": layout.to_dict(),
        "noise_std": 0.0,
        "behaviour": "a real robot's (recorded)",
        "source": {
            "kind": "rawlog",
            "rawlog": str(log),
            "format": f"MRPT rawlog ({form} form)",
            "sensor": sensor,
            "beams": len(first.ranges),
            "aperture_rad": first.aperture,
            "scan_max_range_m": first.max_range,
            "sensor_pose_on_robot": list(first.sensor),
            "scale_units_per_m": scale,
            "pose": "odometry: increments composed from (0, 0, 0), the laser's pose on the robot "
            "composed with it, times the scale",
            "rate_hz": rate,
            "start_s": (int(first.stamp) / 1e7 - MRPT_EPOCH_S) if first.stamp else None,
            "duration_s": float((stamps[n - 1] - stamps[0]) / 1e7) if rate else None,
            "beam": "nearest beam to each ray's angle; invalid or beyond the scan's range: no "
            "return (reads the range)",
            "motors": "odometry: d = displacement along the heading, r = change of heading, to "
            "the next row",
            "counts": counts,
        },
        "version": __version__,
    }
    return Database(*(a.astype(np.float32) for a in arrays), meta=meta)


def summary(db: Database) -> str:
    """One line on an imported rawlog: its rows, and what was dropped."""
    src = db.meta["source"]
    c = src["counts"]
    rate = f" at {src['rate_hz']:.4g} Hz" if src["rate_hz"] else ""
    return (
        f"{len(db):,} rows{rate} from {c['scans']:,} scans of {src['rawlog']} (sensor "
        f"{src['sensor']!r}); dropped {c['scans_other_sensor']:,} other sensors', "
        f"{c['scans_before_odometry']:,} before odometry, {c['rows_without_next']} without a "
        f"next scan; {c['beams_invalid']:,} invalid beams read the range"
    )


def rawlog_name(log: Path) -> str:
    """The name of the recording (runs are named by it): the log's, made safe."""
    stem = log.name
    for suffix in (".gz", ".rawlog"):
        stem = stem.removesuffix(suffix)
    name = re.sub(r"[^A-Za-z0-9_.+-]+", "-", stem).strip("_.+-") or "rawlog"
    return f"{name}-rawlog" if name in BUILTIN_WORLDS else name


def write_rawlog(db: Database, path: str | Path, rate: float = 10.0) -> Path:
    """Write ``db`` as a plain rawlog in the frames form (a frame with one scan, beams at the
    layout's angles when they are evenly spaced, then the odometry increment to the next pose),
    readings and poses in metres (a unit a metre). For tests: not atomic."""
    angles = np.asarray(db.layout.angles)
    if len(angles) < 2 or not np.allclose(np.diff(angles), angles[1] - angles[0]):
        raise ValueError("write_rawlog needs evenly spaced rays, two or more")
    aperture = float(angles[-1] - angles[0])
    if not math.isclose(angles[0], -aperture / 2, abs_tol=1e-9):
        raise ValueError("write_rawlog needs rays centred on the heading")
    tick = round(1e7 / rate)
    start = (MRPT_EPOCH_S + 1_700_000_000) * 10_000_000
    out = bytearray()
    poses = db.poses.astype(np.float64)
    for k in range(len(db)):
        readings = db.sensors[k]
        valid = (readings < db.max_range).astype(np.uint8)
        scan = scan_bytes(readings, aperture, db.max_range, start + k * tick, valid=valid)
        out += head("CSensoryFrame", 2) + struct.pack("<I", 1) + scan + bytes([END])
        if k + 1 < len(db):
            inc = inverse_compose(tuple(poses[k + 1]), tuple(poses[k]))
            inc = (inc[0], inc[1], float(wrap(np.array(inc[2]))))
            move = movement_bytes(*inc, start + k * tick + tick // 2)
            out += head("CActionCollection", 0) + struct.pack("<I", 1) + move + bytes([END])
    path = Path(path)
    path.write_bytes(bytes(out))
    return path
