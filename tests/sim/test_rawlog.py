"""Real data in MRPT's formats: a real robot's rawlog and a real campus grid (shipped in
src/sensorimotor/sim/data/mrpt, BSD-3-Clause, see its README.md), read by the reader written here (sim/mrpt.py).

The shipped log imports to one row a scan but the last, whose readings are the log's beams
nearest the paper's rays; a cut, corrupted or hostile log is refused with one line; a simulated
database written as a rawlog (``sim.rawlog.write_rawlog``) reads back to the same readings and
commands; the campus grid imports (opened to its clearance; its time and memory:
benchmarks/bench_import_map.py) with seed 0's start in its free space, and a tiny grid written
here gives the walls of its blocked cells.
"""

from __future__ import annotations

import gzip
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from conftest import assert_one_line_error, run_cli
from sensorimotor.errors import InputError
from sensorimotor.sim import mrpt
from sensorimotor.sim.core import SensorLayout, sample_start
from sensorimotor.sim.database import Database, generate, load_database
from sensorimotor.sim.floorplan import start_region
from sensorimotor.sim.mrpt import END, gridmap_bytes, head, read_rawlog, scan_bytes
from sensorimotor.sim.rawlog import import_rawlog, write_rawlog
from sensorimotor.sim.rosmap import import_mrpt_map
from sensorimotor.sim.world import load_world

LOG = mrpt.SENA_LOG
CAMPUS = mrpt.CAMPUS_MAP


def wrapped(a) -> np.ndarray:
    return (np.asarray(a, dtype=np.float64) + math.pi) % (2 * math.pi) - math.pi


@pytest.fixture(scope="module")
def real():
    return import_rawlog(LOG)


def test_shipped_log_imports_to_its_scans_at_the_kept_beams(real):
    entries, form = read_rawlog(LOG)
    assert form == "frames"
    scans = [e[0] for e in entries if isinstance(e, list) and hasattr(e[0], "ranges")]
    assert len(scans) == 225
    assert len(entries) == 225 + 224
    assert len(real) == 224
    src = real.meta["source"]
    assert src["counts"]["rows"] == 224
    assert src["beams"] == 361
    assert "odometry" in src["pose"]
    assert set(real.meta["world"]) == {"name"}
    # 361 beams over pi, right to left: the ray at angle a is beam 180 + a / (pi / 360)
    beams = [180 + round(a / (math.pi / 360)) for a in (-0.6, -0.3, 0.0, 0.3, 0.6)]
    assert beams == [111, 146, 180, 214, 249]
    for k in (0, 57, 111, 223):
        scan = scans[k]
        want = np.where(scan.valid[beams] & (scan.ranges[beams] <= 80), scan.ranges[beams], 10)
        np.testing.assert_array_equal(real.sensors[k], np.minimum(want, 10).astype(np.float32))
    # the robot's odometry, from (0, 0, 0), and the laser 0.78 m ahead of it
    np.testing.assert_allclose(real.poses[0], [0.78, 0, 0], atol=1e-6)
    assert real.motors[:, 0].min() >= 0
    assert real.motors[:, 0].max() < 1
    assert np.abs(real.motors[:, 1]).max() < 0.3


def test_cli_imports_the_log_and_refuses_a_cut_or_corrupted_copy(tmp_path):
    out = tmp_path / "sena.npz"
    proc = run_cli("import-rawlog", LOG, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "224 rows" in proc.stderr
    assert len(load_database(out)) == 224
    raw = LOG.read_bytes()
    cut = tmp_path / "cut.rawlog"
    cut.write_bytes(raw[: len(raw) // 2])
    assert_one_line_error(run_cli("import-rawlog", cut, "--out", tmp_path / "a.npz"), "cut.rawlog")
    bad = bytearray(raw)
    bad[len(bad) // 3] ^= 0x55
    corrupt = tmp_path / "corrupt.rawlog"
    corrupt.write_bytes(bytes(bad))
    proc = run_cli("import-rawlog", corrupt, "--out", tmp_path / "b.npz")
    assert_one_line_error(proc, "corrupt.rawlog", "gzip")
    assert not (tmp_path / "a.npz").exists()
    assert not (tmp_path / "b.npz").exists()


def _refused(path: Path, data: bytes, *needles: str) -> None:
    path.write_bytes(data)
    with pytest.raises(InputError) as err:
        import_rawlog(path)
    text = str(err.value)
    assert "\n" not in text
    assert str(path) in text
    for needle in needles:
        assert needle in text, text


def test_plain_logs_cut_damaged_or_hostile_are_refused(tmp_path):
    plain = gzip.decompress(LOG.read_bytes())
    p = tmp_path / "x.rawlog"
    _refused(p, plain[:100_000], "truncated")
    _refused(p, b"", "empty")
    _refused(p, b"\x05hello", "not an MRPT object")
    _refused(p, plain[:1] + b"X" + plain[2:], "XSensoryFrame")  # an unknown class
    _refused(p, plain[:14] + b"\x09" + plain[15:], "version 9")  # CSensoryFrame 9
    # a scan announcing 4 billion beams; one with a NaN range
    scan = scan_bytes([1.0, 2.0, 3.0], 1.2, 10.0, 1)
    at = scan.index(struct.pack("<I", 3))
    huge = scan[:at] + struct.pack("<I", 0xFFFFFFFF) + scan[at + 4 :]
    frame = head("CSensoryFrame", 2) + struct.pack("<I", 1)
    _refused(p, frame + huge + bytes([END]), "beam count")
    nan = scan_bytes([1.0, float("nan"), 3.0], 1.2, 10.0, 1)
    _refused(p, frame + nan + bytes([END]), "NaN")
    _refused(p, frame + scan + b"\x00", "does not end")
    # a log whose scans miss the layout's rays says so
    narrow = frame + scan_bytes([1.0, 2.0, 3.0], 0.2, 10.0, 1) + bytes([END])
    _refused(p, narrow * 3, "outside")


def test_a_simulated_run_written_as_a_rawlog_reads_back_the_same(tmp_path):
    db = generate(load_world("rooms1"), 2000, seed=4)
    log = write_rawlog(db, tmp_path / "sim.rawlog")
    zipped = tmp_path / "sim.rawlog.gz"
    zipped.write_bytes(gzip.compress(log.read_bytes(), mtime=0))
    for path in (log, zipped):
        back = import_rawlog(path)
        assert len(back) == len(db) - 1
        np.testing.assert_array_equal(back.sensors, db.sensors[:-1])
        np.testing.assert_allclose(back.motors[:, 0], db.motors[:-1, 0], atol=2e-5)
        np.testing.assert_allclose(wrapped(back.motors[:, 1] - db.motors[:-1, 1]), 0, atol=2e-5)
        # the poses are odometry's, from (0, 0, 0): the simulated ones moved to start there
        x0, y0, h0 = db.poses[0].astype(np.float64)
        dx, dy = db.poses[:-1, 0] - x0, db.poses[:-1, 1] - y0
        c, s = math.cos(h0), math.sin(h0)
        np.testing.assert_allclose(back.poses[:, 0], c * dx + s * dy, atol=1e-3)
        np.testing.assert_allclose(back.poses[:, 1], -s * dx + c * dy, atol=1e-3)
    assert import_rawlog(log).meta["source"]["rate_hz"] == pytest.approx(10.0)
    three = import_rawlog(log, SensorLayout((-0.6, 0.0, 0.6), 10.0))
    np.testing.assert_array_equal(three.sensors, db.sensors[:-1][:, [0, 2, 4]])


def test_with_a_world_the_walls_are_known_and_poses_outside_it_are_refused(real, tmp_path):
    sim = generate(load_world("square"), 30, seed=1)
    line = np.zeros((30, 3), dtype=np.float32)
    line[:, 0] = 0.2 * np.arange(30)  # odometry from (0, 0, 0) along x: inside the square
    log = write_rawlog(
        Database(sim.sensors, sim.motors, line, meta=sim.meta), tmp_path / "l.rawlog"
    )
    known = import_rawlog(log, world=load_world("square"))
    assert known.has_walls
    assert known.world.walls.tolist() == load_world("square").walls.tolist()
    np.testing.assert_allclose(known.poses[:, 0], line[:-1, 0], atol=1e-4)
    assert not real.has_walls
    with pytest.raises(InputError, match="outside the 50 x 50 world 'square'") as err:
        import_rawlog(LOG, world=load_world("square"))  # the loop goes below y = 0
    assert "\n" not in str(err.value)


def test_a_tiny_grid_gives_the_walls_of_its_blocked_cells(tmp_path):
    free = np.full((10, 12), 0.5)  # unknown around, cells of 1 m
    free[1:9, 1:11] = 0.99  # a 10 x 8 m room
    free[2, 3:6] = 0.01  # a pillar of three cells
    free[5, 1] = 0.3  # too uncertain to be free: blocked, a notch in the wall
    free[6, 7] = 0.01  # a one-cell speck inside: noise, dropped
    path = tmp_path / "room.gridmap"
    path.write_bytes(gridmap_bytes(free, 1.0, x_min=-2.0, y_min=3.0))
    world, comment = import_mrpt_map(path, clearance=0)  # every free cell (tests/sim/test_traps)
    assert world.name == "room"
    assert (world.width, world.height) == (12.0, 10.0)
    walls = {tuple(w) for w in np.asarray(world.walls).tolist()}
    pillar = {
        (3.0, 2.0, 6.0, 2.0),
        (3.0, 3.0, 6.0, 3.0),
        (3.0, 2.0, 3.0, 3.0),
        (6.0, 2.0, 6.0, 3.0),
    }
    notch = {(1.0, 5.0, 2.0, 5.0), (1.0, 6.0, 2.0, 6.0), (2.0, 5.0, 2.0, 6.0)}
    sides = {(1.0, 1.0, 11.0, 1.0), (1.0, 9.0, 11.0, 9.0), (11.0, 1.0, 11.0, 9.0)}
    sides |= {(1.0, 1.0, 1.0, 5.0), (1.0, 6.0, 1.0, 9.0)}
    assert walls == pillar | notch | sides
    assert "(-2.000, 3.000)" in comment
    gz = tmp_path / "room.gridmap.gz"
    gz.write_bytes(gzip.compress(path.read_bytes()))
    assert len(import_mrpt_map(gz, clearance=0)[0].walls) == len(world.walls)
    for data, needle in (
        (path.read_bytes()[:-5], "bytes after the cells"),
        (path.read_bytes()[:30], "truncated"),
        (head("CPose2D", 1), "expected a COccupancyGridMap2D"),
    ):
        path.write_bytes(data)
        with pytest.raises(InputError, match=needle):
            import_mrpt_map(path)


def test_the_campus_imports_and_seed_0_starts_in_its_free_space(tmp_path):
    # its time and memory: benchmarks/bench_import_map.py
    out = tmp_path / "campus.toml"
    proc = run_cli("world", "import", CAMPUS, "--out", out)
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    size = [float(v) for v in text.split("size = [", 1)[1].split("]", 1)[0].split(",")]
    assert 120 < size[0] < 140  # 127.28 x 207.52 m: opened, then cropped to its free space
    assert 200 < size[1] < 215
    assert 10_000 < text.count("\n  [") <= 100_000  # 19,948 walls (56,230 before the opening)
    # the start seed 0 draws (as ``generate`` does) lies in the free space, not inside a
    # building: a ray to the right crosses the walls an odd number of times (the grid's
    # border is blocked); and every seed's start lies in the campus's largest free region
    world = load_world(out)
    x, y, _ = sample_start(world, np.random.default_rng(0))
    walls = np.asarray(world.walls)
    upright = walls[walls[:, 0] == walls[:, 2]]
    low, high = np.minimum(upright[:, 1], upright[:, 3]), np.maximum(upright[:, 1], upright[:, 3])
    assert ((upright[:, 0] > x) & (low <= y) & (y < high)).sum() % 2 == 1
    region = start_region(world)
    assert region is not None  # buildings and the unknown around the campus: regions of their own
    for seed in range(20):  # before the start region, 5 of these 20 started inside a building
        assert region.contains(*sample_start(world, np.random.default_rng(seed))[:2])
