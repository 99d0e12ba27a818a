"""Real robots' recordings: a simulated run written as a ROS bag imports back to the same rows.

The bags are written here with ``rosbags``' own writers (``sim.rosbag.write_bag``), and one is
read back with ``rosbags`` alone, independently of the importer, to check what it holds. Broken
bags get one line (InputError; exit 2 at the command line) or are imported with the problem
counted in ``meta.source.counts``. The whole pipeline (import-bag, train, evaluate, analyze)
runs on an imported bag with and without ``--world``.
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from conftest import assert_one_line_error, run_cli
from sensorimotor.errors import InputError
from sensorimotor.sim.bagcodec import INSTALL_HINT, scan_geometry, write_bag
from sensorimotor.sim.core import DEFAULT_LAYOUT, SensorLayout
from sensorimotor.sim.database import Database, generate, load_database, save_database
from sensorimotor.sim.rosbag import BagTopics, import_bag, ray_layout
from sensorimotor.sim.world import load_world, world_from_dict

N = 3000  # rows of the simulated run (a few seconds to write and read)
TOL = 2e-5  # float32 poses of up to 50 units: a few ulps


@pytest.fixture(scope="module")
def sim_db() -> Database:
    return generate(load_world("square"), N, seed=3)


@pytest.fixture(scope="module")
def bags(sim_db, tmp_path_factory) -> dict[str, Path]:
    """The run as a bag of each format (with /cmd_vel): ``rosbag2/sqlite3``, ``rosbag2/mcap``,
    ``rosbag1``."""
    root = tmp_path_factory.mktemp("bags")
    names = {"rosbag2/sqlite3": "run2", "rosbag2/mcap": "run2mcap", "rosbag1": "run1.bag"}
    return {fmt: write_bag(sim_db, root / name, fmt, cmd=True) for fmt, name in names.items()}


def wrapped(a: np.ndarray) -> np.ndarray:
    return (np.asarray(a, dtype=np.float64) + math.pi) % (2 * math.pi) - math.pi


def assert_same_rows(got: Database, want: Database, rows: np.ndarray) -> None:
    """``got`` holds ``want``'s ``rows``: readings exactly, poses and executed commands within
    float tolerance (a turn of more than pi comes back as the same turn the other way)."""
    np.testing.assert_array_equal(got.sensors, want.sensors[rows])
    np.testing.assert_allclose(got.poses[:, :2], want.poses[rows, :2], atol=TOL, rtol=0)
    np.testing.assert_allclose(wrapped(got.poses[:, 2] - want.poses[rows, 2]), 0, atol=TOL)
    np.testing.assert_allclose(got.motors[:, 0], want.motors[rows, 0], atol=TOL, rtol=0)
    np.testing.assert_allclose(wrapped(got.motors[:, 1] - want.motors[rows, 1]), 0, atol=TOL)


def test_the_written_bag_holds_the_readings_at_the_rays_angles(sim_db, bags):
    """Read with rosbags alone: the beam at each ray's angle holds that ray's reading (the range
    as +inf), at 10 Hz; the importer is not involved."""
    from rosbags.highlevel import AnyReader

    with AnyReader([bags["rosbag2/sqlite3"]]) as reader:
        conns = [c for c in reader.connections if c.topic == "/scan"]
        scans = []
        for conn, _, raw in reader.messages(connections=conns):
            scans.append(reader.deserialize(raw, conn.msgtype))
            if len(scans) == 3:
                break
    for row, msg in enumerate(scans):
        assert len(msg.ranges) == 360
        beam_angles = msg.angle_min + msg.angle_increment * np.arange(360)
        for ray, angle in enumerate(DEFAULT_LAYOUT.angles):
            beam = int(np.argmin(np.abs(beam_angles - angle)))
            assert abs(beam_angles[beam] - angle) < 1e-5
            want = sim_db.sensors[row, ray]
            assert msg.ranges[beam] == (np.inf if want >= 10 else want)
    t = [m.header.stamp.sec + m.header.stamp.nanosec / 1e9 for m in scans]
    np.testing.assert_allclose(np.diff(t), 0.1, atol=1e-6)


def test_a_ros2_bag_imports_back_to_the_same_database(sim_db, bags):
    db = import_bag(bags["rosbag2/sqlite3"])
    assert len(db) == N - 1  # the last row's step leads nowhere recorded
    assert_same_rows(db, sim_db, np.arange(N - 1))
    src = db.meta["source"]
    assert db.meta["world"] == {"name": "run2"}
    assert not db.has_walls
    assert db.meta["sensor_layout"] == DEFAULT_LAYOUT.to_dict()
    assert src["frames"] == {
        "scan": "base_scan",
        "odom": "odom",
        "base": "base_link",
        "poses": "odom",
    }
    assert src["rate_hz"] == pytest.approx(10.0, rel=1e-9)
    c = src["counts"]
    assert c["scans"] == N
    assert c["rows"] == N - 1
    assert c["scans_invalid"] == c["gaps"] == c["rows_without_odometry"] == 0
    assert c["beams_no_return"] == int((sim_db.sensors >= 10).sum())


@pytest.mark.parametrize("fmt", ["rosbag1", "rosbag2/mcap"])
def test_ros1_and_mcap_bags_import_to_the_same_rows(sim_db, bags, fmt):
    db = import_bag(bags[fmt])
    assert db.meta["source"]["format"] == fmt
    assert_same_rows(db, sim_db, np.arange(N - 1))


def test_commands_from_cmd_vel_are_the_commands_sent(sim_db, bags):
    """With --cmd the commands are the Twists sent, turns of more than pi included."""
    db = import_bag(bags["rosbag2/sqlite3"], BagTopics(cmd="/cmd_vel"))
    np.testing.assert_allclose(db.motors, sim_db.motors[: N - 1], atol=TOL, rtol=0)
    assert (db.motors[:, 1] > math.pi).any()  # what odometry cannot tell from the other way


def test_an_imported_database_saves_and_loads_with_or_without_its_world(sim_db, bags, tmp_path):
    db = import_bag(bags["rosbag2/sqlite3"])
    back = load_database(save_database(db, tmp_path / "bag.npz"))
    assert back.meta == db.meta
    again = save_database(import_bag(bags["rosbag2/sqlite3"]), tmp_path / "again.npz")
    assert again.read_bytes() == (tmp_path / "bag.npz").read_bytes()  # same bag, same bytes
    assert not back.has_walls
    with pytest.raises(InputError, match="walls are unknown"):
        _ = back.world
    square = load_world("square")
    db = import_bag(bags["rosbag2/sqlite3"], world=square)
    back = load_database(save_database(db, tmp_path / "square_bag.npz"))
    assert back.world == square
    assert back.has_walls
    small = world_from_dict({"name": "small", "size": 20, "walls": []})
    assert (sim_db.poses[: N - 1, :2] > 20).any()
    with pytest.raises(InputError, match="outside the 20 x 20 world 'small'"):
        import_bag(bags["rosbag2/sqlite3"], world=small)


def test_a_walls_unknown_meta_that_names_a_built_in_world_is_refused(sim_db, bags, tmp_path):
    db = import_bag(bags["rosbag2/sqlite3"])
    fake = Database(db.sensors, db.motors, db.poses, {**db.meta, "world": {"name": "square"}})
    with pytest.raises(InputError, match="built-in 'square' but not its walls"):
        load_database(save_database(fake, tmp_path / "fake.npz"))


def test_invalid_readings_drop_their_scans_and_are_counted(sim_db, tmp_path):
    """NaN and -inf on a ray (REP 117: invalid) drop the scan; the row before the gap has no next
    row and goes too; every other row comes back as it was. NaN off the rays never matters (the
    written scans are NaN there)."""
    sensors = sim_db.sensors.copy()
    sensors[100:104, 2] = np.nan
    sensors[104, 0] = -np.inf
    broken = Database(sensors, sim_db.motors, sim_db.poses, sim_db.meta)
    db = import_bag(write_bag(broken, tmp_path / "nan", cmd=False))
    c = db.meta["source"]["counts"]
    assert (c["scans_invalid"], c["beams_nan"], c["beams_too_close"]) == (5, 4, 1)
    assert (c["gaps"], c["slots_empty"]) == (1, 5)
    keep = np.r_[0:99, 105 : N - 1]
    assert_same_rows(db, sim_db, keep)


def test_gaps_and_disorder_in_time_are_counted_and_a_jump_back_refused(sim_db, tmp_path):
    times = np.arange(N) / 10.0
    times[1000:] += 5.0  # five seconds without messages: 50 empty slots
    received = times.copy()
    received[[10, 11]] = received[[11, 10]]  # row 11 reached the recorder before row 10
    db = import_bag(write_bag(sim_db, tmp_path / "gap", times=times, received=received))
    c = db.meta["source"]["counts"]
    assert (c["gaps"], c["slots_empty"], c["scan_out_of_order"]) == (1, 50, 1)
    assert_same_rows(db, sim_db, np.r_[0:999, 1000 : N - 1])
    times = np.arange(N) / 10.0
    times[2000:] -= 60.0  # the driver's clock reset a minute back, the recorder's did not
    bag = write_bag(sim_db, tmp_path / "jump", times=times, received=np.arange(N) / 10.0)
    with pytest.raises(InputError, match=r"scan message 2000 is stamped 59\.900 s before"):
        import_bag(bag)


@pytest.mark.parametrize("fmt", ["rosbag2/sqlite3", "rosbag2/mcap", "rosbag1"])
def test_a_truncated_bag_is_one_line(sim_db, tmp_path, fmt):
    bag = write_bag(generate(load_world("square"), 300, seed=1), tmp_path / "t.bag", fmt)
    files = sorted(p for p in bag.iterdir() if p.suffix != ".yaml") if bag.is_dir() else [bag]
    data = files[0].read_bytes()
    files[0].write_bytes(data[: len(data) // 2])
    with pytest.raises(
        InputError, match=r"t\.bag: (cannot open as a ROS bag|damaged or truncated)"
    ):
        import_bag(bag)


def test_a_missing_extra_is_one_line_that_says_how_to_install_it(bags, monkeypatch, tmp_path):
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)  # import fails as if absent
    with pytest.raises(InputError) as err:
        import_bag(bags["rosbag1"])
    assert str(err.value) == INSTALL_HINT
    argv = ["sensorimotor", "import-bag", str(bags["rosbag1"]), "--out", str(tmp_path / "x.npz")]
    code = (
        "import sys; sys.modules['rosbags'] = None; "  # the extra absent
        f"sys.argv = {argv!r}; from sensorimotor.cli import main; main()"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert_one_line_error(done, INSTALL_HINT)


def test_the_default_layout_is_the_papers_and_scan_beams_fall_on_its_rays():
    assert ray_layout() == DEFAULT_LAYOUT
    angle_min, inc = scan_geometry(DEFAULT_LAYOUT, 360)
    beams = (np.asarray(DEFAULT_LAYOUT.angles) - angle_min) / inc
    np.testing.assert_allclose(beams, np.rint(beams), atol=1e-9)
    assert angle_min + 359 * inc > math.pi - 0.1
    assert angle_min < -math.pi + 0.1
    with pytest.raises(InputError, match="--fov"):
        ray_layout(5, 7.0)


def test_broken_bags_at_the_command_line_are_one_line_and_exit_2(bags, tmp_path):
    bag = bags["rosbag2/sqlite3"]
    out = tmp_path / "x.npz"
    assert_one_line_error(run_cli("import-bag", bag, "--out", out, "--odom", "/gone"), "'/gone'")
    narrow = write_bag(generate(load_world("square"), 50), tmp_path / "narrow", beams=40)
    wide = run_cli("import-bag", narrow, "--out", out, "--fov", "6.2")  # scans: -3.0 .. 2.85
    assert_one_line_error(wide, "the scans cover angles -3.000..2.850 rad", "ray at -3.1 rad")
    with pytest.raises(InputError, match="--rays must be an integer from 1 to 1,024"):
        import_bag(bag, layout=ray_layout(2_000))
    assert not out.exists()


def test_train_evaluate_analyze_run_on_an_imported_bag_with_and_without_a_world(
    bags, tmp_path, one_thread
):
    """The whole pipeline through the command line's own functions (in this process: one torch
    import): without walls the wall events are n/a, with --world they are scored."""
    from typer.testing import CliRunner

    from sensorimotor.cli import app

    def cli(*args) -> str:
        done = CliRunner().invoke(app, [str(a) for a in args])
        assert done.exit_code == 0, (done.output, done.exception)
        return done.output

    bag = bags["rosbag2/sqlite3"]
    db, run = tmp_path / "bag.npz", tmp_path / "run"
    assert f"{N - 1:,} rows at 10 Hz" in cli("import-bag", bag, "--out", db)
    cli("train", "s", "--data", db, "--out", run, "--max-epochs", "1")
    assert json.loads((run / "config.json").read_text())["data"]["world"] == "run2"
    cli("evaluate", run, "--data", db, "--json", tmp_path / "e.json")
    errors = json.loads((tmp_path / "e.json").read_text())["errors"]
    assert list(errors) == ["run2"]
    assert 0 < errors["run2"] < 10
    assert "corner in view     n/a (walls unknown)" in cli(
        "analyze", run, "--data", db, "--out", tmp_path / "a", "--no-svg"
    )
    m = json.loads((tmp_path / "a" / "metrics.json").read_text())["analysis"]
    assert list(m["events"]) == ["nothing"]
    assert not m["walls_known"]
    assert m["memory"]["distance_behind_r2"] is None
    assert 0 < m["position"]["knn_mse_chance"] < 1  # normalised by the path's extent
    with_world = tmp_path / "square_bag.npz"
    cli("import-bag", bag, "--out", with_world, "--world", "square")
    cli("analyze", "raw", "--data", with_world, "--out", tmp_path / "w", "--no-svg")
    m = json.loads((tmp_path / "w" / "metrics.json").read_text())["analysis"]
    assert {"corner", "nothing"} <= set(m["events"])
    assert m["walls_known"]


def test_other_ray_layouts_read_their_own_beams(sim_db, bags):
    """A layout of other angles reads the beams at its angles: here the written scans hold NaN
    off the paper's rays, so every scan is invalid (and the bag is refused, naming that)."""
    layout = SensorLayout((-0.5, -0.25, 0.0, 0.25, 0.5), 10.0)
    with pytest.raises(InputError, match="0 valid scans"):
        import_bag(bags["rosbag2/sqlite3"], layout=layout)


@pytest.mark.parametrize("fmt", ["rosbag2/sqlite3", "rosbag2/mcap", "rosbag1"])
def test_the_bulk_decoder_gives_the_database_rosbags_decoding_gives(bags, fmt):
    fast = import_bag(bags[fmt], BagTopics(cmd="/cmd_vel"))
    slow = import_bag(bags[fmt], BagTopics(cmd="/cmd_vel"), decoder="rosbags")
    for name in ("sensors", "motors", "poses"):
        np.testing.assert_array_equal(getattr(fast, name), getattr(slow, name))
    assert fast.meta == slow.meta


@pytest.mark.parametrize("ros1", [False, True])
def test_bulk_decoding_reads_scans_and_odometry_of_any_frame_names_and_beam_counts(ros1):
    """Messages whose frame names and beam counts differ (so their fields sit at other
    offsets), serialized by rosbags, decode to the fields rosbags reads back."""
    from rosbags.typesys import Stores, get_typestore

    from sensorimotor.sim.bagcodec import decode_odometry, decode_scans

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    T, ser = ts.types, (ts.serialize_ros1 if ros1 else ts.serialize_cdr)
    des = ts.deserialize_ros1 if ros1 else ts.deserialize_cdr
    rng = np.random.default_rng(0)
    scans, odoms = [], []
    for i, (frame, beams) in enumerate([("a", 40), ("laser_x", 41), ("b", 40), ("", 100)] * 2):
        extra = {"seq": i} if ros1 else {}
        head = T["std_msgs/msg/Header"](
            stamp=T["builtin_interfaces/msg/Time"](sec=100 + i, nanosec=7 * i),
            frame_id=frame,
            **extra,
        )
        ranges = rng.uniform(0.1, 9, beams).astype(np.float32)
        inc = 2 * math.pi / beams
        scans.append(
            T["sensor_msgs/msg/LaserScan"](
                header=head,
                angle_min=-math.pi,
                angle_max=math.pi - inc,
                angle_increment=inc,
                time_increment=0.0,
                scan_time=0.1,
                range_min=0.05,
                range_max=9.5,
                ranges=ranges,
                intensities=np.zeros(i % 3, dtype=np.float32),
            )
        )
        v = rng.normal(size=7)
        q = v[3:] / np.linalg.norm(v[3:])
        pose = T["geometry_msgs/msg/Pose"](
            position=T["geometry_msgs/msg/Point"](x=v[0], y=v[1], z=v[2]),
            orientation=T["geometry_msgs/msg/Quaternion"](x=q[0], y=q[1], z=q[2], w=q[3]),
        )
        vec = T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)
        odoms.append(
            T["nav_msgs/msg/Odometry"](
                header=head,
                child_frame_id="c" * i,  # 1 .. 8 bytes: every alignment
                pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose, covariance=np.zeros(36)),
                twist=T["geometry_msgs/msg/TwistWithCovariance"](
                    twist=T["geometry_msgs/msg/Twist"](linear=vec, angular=vec),
                    covariance=np.zeros(36),
                ),
            )
        )
    raw_s = [bytes(ser(m, "sensor_msgs/msg/LaserScan")) for m in scans]
    raw_o = [bytes(ser(m, "nav_msgs/msg/Odometry")) for m in odoms]

    def never(i):
        raise AssertionError(f"message {i} went to the generic decoder")

    angles = np.asarray(DEFAULT_LAYOUT.angles)
    got = decode_scans(raw_s, ros1, angles, never)
    for i, m in enumerate(scans):
        back = des(raw_s[i], "sensor_msgs/msg/LaserScan")
        beam = np.rint((angles - back.angle_min) / back.angle_increment).astype(int)
        np.testing.assert_array_equal(got.beams[i], back.ranges[beam].astype(np.float64))
        assert got.stamp[i] == m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        assert got.range_min[i] == np.float32(0.05)
    assert got.covered.all()
    pos = decode_odometry(raw_o, ros1, never)
    for i, m in enumerate(odoms):
        p, q = m.pose.pose.position, m.pose.pose.orientation
        yaw = math.atan2(2 * (q.w * q.z + q.x * q.y), 1 - 2 * (q.y * q.y + q.z * q.z))
        np.testing.assert_allclose(pos.pose[i], [p.x, p.y, yaw], rtol=0, atol=1e-12)


def test_poses_in_the_map_frame_come_from_tf_composed_with_odometry(sim_db, tmp_path):
    """/odom in a frame turned and shifted from the map, /tf map -> odom: --frame map gives the
    map poses back (and fits the world), the commands stay the motion odometry saw."""
    bag = write_bag(sim_db, tmp_path / "tf", odom_frame=(7.0, -4.0, 2.5))
    in_odom = import_bag(bag)
    assert np.abs(in_odom.poses[:, :2] - sim_db.poses[: N - 1, :2]).max() > 1  # another frame
    in_map = import_bag(bag, BagTopics(frame="map"), world=load_world("square"))
    assert_same_rows(in_map, sim_db, np.arange(N - 1))
    assert in_map.meta["source"]["frames"]["poses"] == "map"
    np.testing.assert_allclose(in_odom.motors[:, 0], in_map.motors[:, 0], atol=TOL, rtol=0)
    with pytest.raises(InputError, match="no transform base -> odom"):
        import_bag(bag, BagTopics(frame="base"))
    with pytest.raises(InputError, match="lies outside the 50 x 50 world 'square'"):
        import_bag(bag, world=load_world("square"))


def test_without_range_no_return_reads_each_scans_range_max_and_the_database_says_so(
    sim_db, tmp_path
):
    """A sensor that reaches 3.5 (a TurtleBot's LDS) reads 3.5 where nothing is in view, not the
    simulation's 10; ``--range`` still sets it, and the summary says which one it is."""
    layout = {**sim_db.meta["sensor_layout"], "max_range": 3.5}
    short = Database(sim_db.sensors, sim_db.motors, sim_db.poses, {**sim_db.meta, "sensor_layout": layout})
    bag = write_bag(short, tmp_path / "lds.bag", "rosbag1")
    own = import_bag(bag, scan_range=True)
    assert own.max_range == pytest.approx(3.5)
    assert own.sensors.max() <= 3.5 + 1e-6
    assert (own.sensors == np.float32(3.5)).any()  # far walls: no return, the scan's range
    assert "range_max" in own.meta["source"]["range"]
    told = import_bag(bag)
    assert told.max_range == 10.0
    proc = run_cli("import-bag", bag, "--out", tmp_path / "lds.npz")
    assert proc.returncode == 0, proc.stderr
    assert "range 3.5" in proc.stderr
    assert "each scan's range_max" in proc.stderr
