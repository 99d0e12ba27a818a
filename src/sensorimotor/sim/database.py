"""Sensorimotor databases: the ``.npz`` files, their checks, splits and scaling.

A database holds ``sensors`` (N, R), ``motors`` (N, 2) and ``poses`` (N, 3), all float32, and
``meta``, a JSON string (world, seed, steps, sensor layout, noise, package version). R is the
layout's number of rays (``meta.sensor_layout``; the paper's 5 when the meta has none). Row t holds s_t,
the command m_t chosen after seeing s_t (it leads to s_{t+1}) and the pose where s_t was read.
Splits are by position: the first 80 % train, the next 10 % validation, the last 10 % test.

A database recorded where the walls are unknown (a real robot's, ``sim.rosbag``) has a
``meta.world`` that holds a ``name`` alone, no ``size`` and no ``walls``: its poses are in the
robot's odometry frame, and a stage that needs walls (events, maps, figures of the world) says
so instead of guessing them (``Database.has_walls``).
"""

from __future__ import annotations

import json
import math
import os
import zipfile
import zlib
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from sensorimotor.errors import InputError
from sensorimotor.files import DATABASE, atomic_path, check_input
from sensorimotor.sim.core import (
    BEHAVIOURS,
    DEFAULT_LAYOUT,
    LATTICE_STEP,
    MAX_RAYS,
    SMOOTH_SD,
    SMOOTH_TAU,
    SensorLayout,
    read_sensors,
    rollout,
)
from sensorimotor.sim.world import (
    BUILTIN_WORLDS,
    NAME_PATTERN,
    World,
    check_builtin_name,
    world_from_dict,
)
from sensorimotor.version import __version__

SPLITS = {"train": (0.0, 0.8), "val": (0.8, 0.9), "test": (0.9, 1.0)}
ARRAYS = {"sensors": None, "motors": 2, "poses": 3}  # name -> columns (None: the layout's rays)


@dataclass(frozen=True, eq=False)
class Database:
    """A loaded database: float32 arrays plus the ``meta`` that says where they came from."""

    sensors: np.ndarray = field(repr=False)  # (N, R) float32 readings, R rays
    motors: np.ndarray = field(repr=False)  # (N, 2) float32 (d, r)
    poses: np.ndarray = field(repr=False)  # (N, 3) float32 (x, y, heading) where s_t is read
    meta: dict
    path: Path | None = None
    part: str | None = None  # the split it is (``take``), or None for the whole file

    def __len__(self) -> int:
        return len(self.sensors)

    @property
    def source(self) -> str:
        """What error messages call it: its file (and split), or what it is when it has none."""
        where = (
            str(self.path)
            if self.path is not None
            else f"the in-memory database of {self.meta.get('world', {}).get('name', 'a world')}"
        )
        return where if self.part is None else f"{where} ({self.part} split)"

    @property
    def has_walls(self) -> bool:
        """Whether the meta gives the world's walls (False for a recording made without them)."""
        return not walls_unknown(self.meta)

    @property
    def world(self) -> World:
        """The world the database was recorded in; InputError when its walls are unknown."""
        if not self.has_walls:
            raise InputError(
                f"{self.source}: the walls are unknown (a recording imported without --world); "
                "this needs them"
            )
        return world_from_dict(self.meta["world"], f"{self.source}: meta.world")

    @property
    def max_range(self) -> float:
        return float(self.meta.get("sensor_layout", {}).get("max_range", 10.0))

    @property
    def behaviour(self) -> str:
        """The behaviour that recorded it (``sim.core.BEHAVIOURS``): ``meta.behaviour_name``,
        the paper's where the meta has none (every database made before there were two)."""
        return self.meta.get("behaviour_name", "paper")

    @property
    def layout(self) -> SensorLayout:
        """The lasers the database was recorded with (the paper's when the meta has none)."""
        layout = self.meta.get("sensor_layout", {})
        return SensorLayout(tuple(layout.get("angles", DEFAULT_LAYOUT.angles)), self.max_range)

    def split(self, name: str) -> slice:
        """Row range of split ``train``, ``val`` or ``test``."""
        return split_slice(len(self), name)

    def take(self, name: str) -> Database:
        """The rows of one split, as a Database of its own (views, no copy)."""
        s = self.split(name)
        return Database(self.sensors[s], self.motors[s], self.poses[s], self.meta, self.path, name)


def walls_unknown(meta: dict) -> bool:
    """Whether a database's ``meta.world`` names its source alone, without size or walls."""
    world = meta.get("world") if isinstance(meta, dict) else None
    return isinstance(world, dict) and set(world) == {"name"}


def as_database(db: Database | str | Path) -> Database:
    """``db`` itself, or the database loaded from that file."""
    return db if isinstance(db, Database) else load_database(db)


def database_file(data: str | Path | Database) -> Path:
    """The file of a database that training reads (its hash goes into the run folder): a
    Database stands for the whole file it was loaded from, as it is on disk."""
    if isinstance(data, Database):
        if data.part is not None:
            raise InputError(
                f"{data.source}: training reads a whole database file and splits it itself: "
                "pass the file, not one split"
            )
        if data.path is None:
            raise InputError(
                "training reads a database file (its hash identifies the run's data): "
                "save_database(db, path) first and pass the path"
            )
        return Path(data.path)
    return Path(data)


def split_slice(n: int, name: str) -> slice:
    """Rows of split ``name`` in a database of ``n`` rows (train 80 %, val 10 %, test 10 %)."""
    if name not in SPLITS:
        raise ValueError(f"unknown split {name!r}: use one of {', '.join(SPLITS)}")
    lo, hi = SPLITS[name]
    return slice(math.floor(n * lo + 1e-9), math.floor(n * hi + 1e-9))


def scale_sensors(sensors: np.ndarray, max_range: float = 10.0) -> np.ndarray:
    """Readings divided by the range, into [0, 1]."""
    return (np.asarray(sensors, dtype=np.float32) / np.float32(max_range)).astype(np.float32)


def scale_motors(motors: np.ndarray) -> np.ndarray:
    """``d`` as is (already in [0, 1)), ``r`` divided by pi."""
    out = np.asarray(motors, dtype=np.float32).copy()
    out[:, 1] /= np.float32(math.pi)
    return out


def generate(
    world: World,
    steps: int,
    seed: int = 0,
    layout: SensorLayout = DEFAULT_LAYOUT,
    noise_std: float = 0.0,
    progress: Callable[[int], None] | None = None,
    noise_kind: str = "absolute",
    dropout: float = 0.0,
    motor_noise_std: float = 0.0,
    behaviour: str = "paper",
) -> Database:
    """Roll ``behaviour`` (the paper's by default) out for ``steps`` steps and package it as a
    Database.

    ``layout`` says what is recorded (any number of rays, any field of view and range); the
    behaviour reads the paper's five rays whatever it is (``sim.rollout``), and the noises are
    ``sim.rollout``'s. The meta records the layout and every noise; the keys of the noises
    the paper has not (``noise_kind``, ``dropout``, ``motor_noise_std``) appear only when one
    of them is used, so that a paper database keeps its bytes; ``behaviour_name`` likewise
    only for a behaviour other than the paper's."""
    run = rollout(
        world,
        steps,
        seed,
        layout,
        noise_std,
        progress=progress,
        noise_kind=noise_kind,
        dropout=dropout,
        motor_noise_std=motor_noise_std,
        behaviour=behaviour,
    )
    meta = {
        "format": "sensorimotor-database/1",
        "world": world.to_dict(),
        "seed": int(seed),
        "steps": int(steps),
        "sensor_layout": layout.to_dict(),
        "noise_std": float(noise_std),
        "behaviour": BEHAVIOUR_TEXT[behaviour],
        "version": __version__,
    }
    if noise_kind != "absolute" or dropout or motor_noise_std:
        meta["noise_kind"] = noise_kind
        meta["dropout"] = float(dropout)
        meta["motor_noise_std"] = float(motor_noise_std)
    if behaviour != "paper":
        meta["behaviour_name"] = behaviour
    if layout.angles != DEFAULT_LAYOUT.angles or layout.max_range < 1:
        meta["behaviour"] += " on the paper's 5 rays (-0.6 to 0.6 rad), cast apart from the layout"
    return Database(
        run.sensors.astype(np.float32),
        run.motors.astype(np.float32),
        run.poses.astype(np.float32),
        meta,
    )


BEHAVIOUR_TEXT = {
    "paper": "paper IV.C: min(s) < 1 -> (0, U(pi - pi/10, pi + pi/10)); "
    "else (U(0, 1), U(-pi/6, pi/6))",
    "smooth": "smooth: min(s) < 1 -> (0, U(pi - pi/10, pi + pi/10)); else (U(0, 1), rate), "
    f"rate an Ornstein-Uhlenbeck process (mean 0, time constant {SMOOTH_TAU:g} steps, "
    f"stationary sd {SMOOTH_SD:.4f} rad) running every step",
    "lattice": "lattice: min(s) < 1 -> (0, pi + k pi/6), k in {-1, 0, 1}; else "
    f"({LATTICE_STEP:g}, 0), (0, pi/6) or (0, -pi/6) with probabilities 1/2, 1/4, 1/4; "
    "headings on the multiples of pi/6",
    "grid": "grid: min(s) < 1 -> (0, pi + k pi/2), k in {-1, 0, 1}; else "
    f"({LATTICE_STEP:g}, 0), (0, pi/2) or (0, -pi/2) with probabilities 1/2, 1/4, 1/4; "
    f"headings on the multiples of pi/2, positions on start + {LATTICE_STEP:g} Z^2",
}
"""``meta.behaviour``: each behaviour in words (the paper's as every database before had it)."""


def check_memory(steps: int, bytes_per_step: int = 120) -> None:
    """Refuse early a database too big for this machine's memory (InputError, not a traceback).

    ``generate`` holds the float64 rollout (R + 5 numbers, 8 (R + 5) bytes a step for R rays)
    and its float32 copy (4 (R + 5) bytes a step) at once: 120 bytes for the paper's 5 rays.
    """
    try:
        have = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    except (AttributeError, ValueError, OSError):  # no sysconf (Windows): let numpy decide
        return
    need = steps * bytes_per_step
    if need > have:
        raise InputError(
            f"--steps {steps:,} needs about {need / 2**30:,.1f} GiB of memory; "
            f"this machine has {have / 2**30:,.1f} GiB"
        )


def save_database(db: Database, path: str | Path) -> Path:
    """Write ``db`` to ``path`` (.npz) through a temporary file in the same folder."""
    path = Path(path)
    with atomic_path(path, ".npz") as tmp, open(tmp, "wb") as f:
        np.savez(
            f,
            sensors=db.sensors,
            motors=db.motors,
            poses=db.poses,
            meta=np.array(json.dumps(db.meta)),
        )
    return path


def load_database(path: str | Path) -> Database:
    """Read and check a database; any problem is an InputError naming the file."""
    path = check_input(path, DATABASE)
    try:
        # our own file handle: np.load leaks its own when a damaged zip makes it raise
        with open(path, "rb") as f:
            if not f.read(6).startswith((b"PK", b"\x93NUMPY")):  # else numpy calls it a pickle
                raise InputError(f"{path}: not an .npz file (no zip archive inside)")
            f.seek(0)
            npz = np.load(f, allow_pickle=False)
            if not isinstance(npz, np.lib.npyio.NpzFile):  # a bare .npy array
                raise InputError(f"{path}: not an .npz file (a single .npy array)")
            missing = [k for k in (*ARRAYS, "meta") if k not in npz.files]
            if missing:
                raise InputError(f"{path}: not a sensorimotor database (missing {missing[0]!r})")
            arrays = {k: npz[k] for k in ARRAYS}
            meta_raw = npz["meta"]
    except InputError:
        raise
    except (zipfile.BadZipFile, EOFError, zlib.error) as err:
        raise InputError(f"{path}: truncated, damaged or not an .npz file ({err})") from None
    except (OSError, ValueError) as err:
        raise InputError(f"{path}: cannot read as .npz ({err})") from None
    except MemoryError as err:  # a header may claim any shape
        raise InputError(f"{path}: too large to load ({err})") from None
    n = None
    for name, cols in ARRAYS.items():
        a = arrays[name]
        if cols is None and a.ndim == 2 and 1 <= a.shape[1] <= MAX_RAYS:
            cols = a.shape[1]  # the layout's rays, checked against meta.sensor_layout below
        if a.ndim != 2 or a.shape[1] != cols:
            want = cols if cols is not None else f"R, 1 <= R <= {MAX_RAYS}"
            raise InputError(f"{path}: {name!r} must have shape (N, {want}), got {a.shape}")
        if n is not None and len(a) != n:
            raise InputError(f"{path}: {name!r} has {len(a)} rows, expected {n}")
        n = len(a)
        if not np.issubdtype(a.dtype, np.floating):
            raise InputError(f"{path}: {name!r} must be floating point, got {a.dtype}")
        with np.errstate(over="ignore"):
            arrays[name] = a = a.astype(np.float32, copy=False)  # what every stage reads
        if not np.isfinite(a).all():
            raise InputError(f"{path}: {name!r} contains NaN or inf (in float32)")
    if n == 0:
        raise InputError(f"{path}: database is empty")
    try:
        meta = json.loads(str(meta_raw))
        if walls_unknown(meta):
            world = None
            name = meta["world"]["name"]
            if not isinstance(name, str) or not NAME_PATTERN.fullmatch(name):
                raise InputError(f"{path}: meta.world.name {name!r} is not a valid name")
            if name in BUILTIN_WORLDS:
                raise InputError(f"{path}: meta.world names built-in {name!r} but not its walls")
        else:
            world = world_from_dict(meta["world"], f"{path}: meta.world")
            if "name" not in meta["world"]:
                raise InputError(f"{path}: meta.world has no 'name'")
            check_builtin_name(world, f"{path}: meta.world")
        _check_layout(meta, arrays["sensors"].shape[1], path)
        if meta.get("behaviour_name", "paper") not in BEHAVIOURS:
            raise InputError(
                f"{path}: meta.behaviour_name must be one of {', '.join(BEHAVIOURS)}, "
                f"got {meta['behaviour_name']!r}"
            )
    except InputError:
        raise
    except (ValueError, KeyError, TypeError) as err:
        raise InputError(f"{path}: 'meta' is not valid database metadata ({err})") from None
    db = Database(*(arrays[k] for k in ARRAYS), meta=meta, path=path)
    _check_in_world(db, world)
    return db


def _check_in_world(db: Database, world: World | None) -> None:
    """Poses inside the world (when its walls are known) and readings within the lasers' range
    (float32 rounding aside)."""
    path, max_range = db.path, db.max_range
    xy = db.poses[:, :2]
    tol = 1e-3
    outside = (
        (xy < -tol).any(axis=1) | (xy[:, 0] > world.width + tol) | (xy[:, 1] > world.height + tol)
        if world is not None
        else np.zeros(len(xy), dtype=bool)
    )
    if outside.any():
        row = int(np.argmax(outside))
        raise InputError(
            f"{path}: pose {row} {db.poses[row].tolist()} lies outside the "
            f"{world.width:g} x {world.height:g} world"
        )
    s = db.sensors
    bad = ((s < 0) | (s > max_range * (1 + 1e-6))).any(axis=1)
    if bad.any():
        row = int(np.argmax(bad))
        raise InputError(
            f"{path}: sensors row {row} {s[row].tolist()} is outside [0, {max_range:g}] "
            "(meta.sensor_layout.max_range)"
        )
    d, r, heading = db.motors[:, 0], db.motors[:, 1], db.poses[:, 2]
    step_limit = MAX_STEP if world is None else max(world.width, world.height)
    for name, bad, allowed in (
        ("motors (d)", np.abs(d) > step_limit, "a step longer than the world"),
        ("motors (r)", np.abs(r) > 2 * math.pi + 1e-3, "a turn of more than a full turn"),
        ("poses (heading)", np.abs(heading) > math.pi + 1e-3, "a heading outside [-pi, pi]"),
    ):
        if bad.any():
            row = int(np.argmax(bad))
            raise InputError(f"{path}: {name} of row {row} is out of range ({allowed})")
    if world is not None:
        _check_readings_match_world(db, world)
    _check_motors_match_poses(db)


MAX_STEP = 1_000.0  # units a step may move where the walls are unknown (a recording)
READINGS_CHECKED = 2_000  # rows ray-cast again to check that the readings are the world's
READINGS_TOLERANCE = 0.05  # units: float32 poses move a grazing ray's hit a little
READINGS_DISAGREE = 0.05  # of the checked rows may disagree (a ray through a wall's very end)


def _check_readings_match_world(db: Database, world: World) -> None:
    """Refuse a database whose readings are not ray casts in the world its meta names
    (readings recorded in one world, meta naming another), on rows spread over the file.
    Readings with noise or dropouts, and recordings of real robots (``meta.source``), are not
    compared: nothing exact to compare with."""
    meta = db.meta
    if meta.get("noise_std", 0) or meta.get("dropout", 0) or "source" in meta or len(db) == 0:
        return
    rows = np.unique(np.linspace(0, len(db) - 1, min(len(db), READINGS_CHECKED)).astype(int))
    cast = read_sensors(world, db.poses[rows].astype(np.float64), db.layout)
    off = np.abs(cast - db.sensors[rows]).max(axis=1) > READINGS_TOLERANCE
    if off.mean() > READINGS_DISAGREE:
        row = int(rows[np.argmax(off)])
        raise InputError(
            f"{db.path}: its readings are not those of the world its meta names "
            f"({world.name!r}): {off.mean():.0%} of {len(rows):,} checked rows disagree with "
            f"ray casts there (row {row}: read {np.round(db.sensors[row], 2).tolist()}, "
            f"the walls give {np.round(cast[np.argmax(off)], 2).tolist()})"
        )


MOTION_CHECKED = 2_000  # rows whose command is applied again to check that it leads to the next
MOTION_TOLERANCE = 1e-3  # units and rad: float32 poses of a world of 1,000 units round by 6e-5


def _check_motors_match_poses(db: Database) -> None:
    """Refuse a database the simulator wrote (its format, no ``meta.source``, no motor noise,
    whose executed commands differ from the recorded ones) whose motors do not move it: the
    motion from row t to t+1 is the command of row t (``sim.core.apply_motor``), checked on
    rows spread over the file as the readings are."""
    meta = db.meta
    if (
        meta.get("format") != "sensorimotor-database/1"
        or "source" in meta
        or meta.get("motor_noise_std", 0)
        or len(db) < 2
    ):
        return
    rows = np.unique(np.linspace(0, len(db) - 2, min(len(db) - 1, MOTION_CHECKED)).astype(int))
    now, nxt = db.poses[rows].astype(np.float64), db.poses[rows + 1].astype(np.float64)
    d, r = db.motors[rows, 0].astype(np.float64), db.motors[rows, 1].astype(np.float64)
    x = now[:, 0] + d * np.cos(now[:, 2])
    y = now[:, 1] + d * np.sin(now[:, 2])
    turn = np.mod(now[:, 2] + r - nxt[:, 2] + np.pi, 2 * np.pi) - np.pi
    off = (np.hypot(x - nxt[:, 0], y - nxt[:, 1]) > MOTION_TOLERANCE) | (
        np.abs(turn) > MOTION_TOLERANCE
    )
    if off.any():
        i = int(np.argmax(off))
        row = int(rows[i])
        raise InputError(
            f"{db.path}: its motors do not move it from one pose to the next, as the simulator's "
            f"do ({int(off.sum()):,} of {len(rows):,} checked rows; row {row}: command "
            f"{np.round(db.motors[row], 3).tolist()} from {np.round(now[i], 3).tolist()} "
            f"gives ({x[i]:.3f}, {y[i]:.3f}), the next pose is {np.round(nxt[i], 3).tolist()})"
        )


def _check_layout(meta: dict, n_sensors: int, path: Path) -> None:
    """The sensor layout in ``meta`` (optional: the paper's 5 rays) must describe the sensors."""
    layout = meta.get("sensor_layout")
    if layout is None:
        if n_sensors != len(DEFAULT_LAYOUT.angles):
            raise InputError(
                f"{path}: {n_sensors} sensors but no meta.sensor_layout (only the paper's "
                f"{len(DEFAULT_LAYOUT.angles)} rays may go without one)"
            )
        return
    angles = layout.get("angles") if isinstance(layout, dict) else None
    max_range = layout.get("max_range") if isinstance(layout, dict) else None
    ok = (
        isinstance(angles, list)
        and len(angles) == n_sensors
        and all(isinstance(a, int | float) and math.isfinite(a) for a in angles)
        and not any(isinstance(v, bool) for v in (*angles, max_range))
        and isinstance(max_range, int | float)
        and math.isfinite(max_range)
        and max_range > 0
    )
    if not ok:
        raise InputError(
            f"{path}: meta.sensor_layout must give {n_sensors} finite angles and a positive "
            f"max_range, got {layout!r}"
        )
