"""Databases: the .npz round trip, what meta records, splits by position, scaling, and the
refusal of every damaged file with one line naming it."""

from __future__ import annotations

import io
import json
import math
import zipfile

import numpy as np
import pytest

from sensorimotor.errors import InputError
from sensorimotor.files import file_hash
from sensorimotor.sim import core as sim
from sensorimotor.sim.database import (
    Database,
    generate,
    load_database,
    save_database,
    scale_motors,
    scale_sensors,
    split_slice,
)
from sensorimotor.sim.world import load_world, world_from_dict
from sensorimotor.version import __version__


@pytest.fixture(scope="module")
def rooms2_db():
    return generate(load_world("rooms2"), 3_000, seed=17)


def write_npz(path, **arrays):
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


def good_arrays(n=100):
    db = generate(load_world("square"), n, seed=0)
    return {
        "sensors": db.sensors,
        "motors": db.motors,
        "poses": db.poses,
        "meta": np.array(json.dumps(db.meta)),
    }


def test_round_trip(tmp_path, rooms2_db):
    path = save_database(rooms2_db, tmp_path / "r2.npz")
    db = load_database(path)
    assert db.path == path
    assert len(db) == 3_000
    for name, cols in (("sensors", 5), ("motors", 2), ("poses", 3)):
        got, want = getattr(db, name), getattr(rooms2_db, name)
        assert got.dtype == np.float32
        assert got.shape == (3_000, cols)
        assert got.tobytes() == want.tobytes()
    assert db.meta == rooms2_db.meta
    assert db.world == load_world("rooms2")
    assert db.max_range == 10.0
    # no temporary file is left beside it
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r2.npz"]


def test_file_is_plain_npz(tmp_path, rooms2_db):
    """Readable with numpy alone and no pickle, as DESIGN.md promises."""
    path = save_database(rooms2_db, tmp_path / "r2.npz")
    with np.load(path, allow_pickle=False) as npz:
        assert sorted(npz.files) == ["meta", "motors", "poses", "sensors"]
        assert npz["sensors"].dtype == np.float32
        assert npz["meta"].dtype.kind == "U"
        meta = json.loads(str(npz["meta"]))
    assert meta["steps"] == 3_000
    assert len(file_hash(path)) == 64
    assert file_hash(path) == file_hash(path)


def test_database_holds_the_rollout_as_float32(rooms2_db):
    run = sim.rollout(load_world("rooms2"), 3_000, seed=17)
    assert rooms2_db.sensors.tobytes() == run.sensors.astype(np.float32).tobytes()
    assert rooms2_db.motors.tobytes() == run.motors.astype(np.float32).tobytes()
    assert rooms2_db.poses.tobytes() == run.poses.astype(np.float32).tobytes()


def test_meta_says_where_the_data_came_from(rooms2_db):
    meta = rooms2_db.meta
    assert meta["world"] == {
        "name": "rooms2",
        "size": [50.0, 50.0],
        "walls": [[0, 25, 38, 25], [17, 0, 17, 17], [33, 0, 33, 17], [25, 25, 25, 42]],
    }
    assert meta["seed"] == 17
    assert meta["steps"] == 3_000
    assert meta["sensor_layout"] == {"angles": [-0.6, -0.3, 0.0, 0.3, 0.6], "max_range": 10.0}
    assert meta["noise_std"] == 0.0
    assert meta["version"] == __version__
    assert meta["format"] == "sensorimotor-database/1"
    json.dumps(meta)  # JSON-ready


@pytest.mark.parametrize(
    ("n", "train", "val", "test"),
    [
        (1_000_000, (0, 800_000), (800_000, 900_000), (900_000, 1_000_000)),
        (20_000, (0, 16_000), (16_000, 18_000), (18_000, 20_000)),
        (10, (0, 8), (8, 9), (9, 10)),
        (11, (0, 8), (8, 9), (9, 11)),
        (999, (0, 799), (799, 899), (899, 999)),
    ],
)
def test_splits_are_80_10_10_by_position(n, train, val, test):
    for name, want in (("train", train), ("val", val), ("test", test)):
        s = split_slice(n, name)
        assert (s.start, s.stop) == want, name


@pytest.mark.parametrize("n", [10, 11, 64, 999, 12_345, 1_000_003])
def test_splits_cover_every_row_once_in_order(n):
    rows = np.concatenate([np.arange(n)[split_slice(n, k)] for k in ("train", "val", "test")])
    assert np.array_equal(rows, np.arange(n))
    assert abs(split_slice(n, "train").stop - 0.8 * n) <= 1


def test_take_gives_the_rows_of_a_split(rooms2_db):
    test = rooms2_db.take("test")
    assert len(test) == 300
    assert np.shares_memory(test.sensors, rooms2_db.sensors)
    assert np.array_equal(test.sensors, rooms2_db.sensors[2_700:])
    assert np.array_equal(rooms2_db.take("val").poses, rooms2_db.poses[2_400:2_700])
    assert len(rooms2_db.take("train")) == 2_400


def test_scaling():
    sensors = np.array([[0.0, 2.5, 5.0, 10.0, 7.5]])
    np.testing.assert_array_equal(scale_sensors(sensors), [[0.0, 0.25, 0.5, 1.0, 0.75]])
    assert scale_sensors(sensors).dtype == np.float32
    np.testing.assert_allclose(scale_sensors(sensors, 20.0), [[0.0, 0.125, 0.25, 0.5, 0.375]])
    motors = np.array([[0.5, math.pi], [0.0, -math.pi / 6], [0.99, 1.1 * math.pi]])
    scaled = scale_motors(motors)
    assert scaled.dtype == np.float32
    np.testing.assert_allclose(scaled, [[0.5, 1.0], [0.0, -1 / 6], [0.99, 1.1]], rtol=1e-6)
    assert motors[0, 1] == math.pi  # the input is not changed


def test_scaled_database_lies_in_range(rooms2_db):
    s = scale_sensors(rooms2_db.sensors)
    m = scale_motors(rooms2_db.motors)
    assert s.min() > 0.0
    assert s.max() == 1.0
    assert m[:, 0].min() >= 0.0
    assert m[:, 0].max() < 1.0
    assert m[:, 1].min() >= -1 / 6 - 1e-6
    assert m[:, 1].max() <= 1.1 + 1e-6


# ---------------------------------------------------------------- refusals


def assert_refused(path, *needles):
    with pytest.raises(InputError) as info:
        load_database(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message
    for needle in needles:
        assert needle in message, (needle, message)


def test_missing_file_and_folder(tmp_path):
    assert_refused(tmp_path / "nope.npz", "not found")
    assert_refused(tmp_path, "is a folder")


@pytest.mark.parametrize("keep", [0.0, 0.1, 0.5, 0.9, 0.999])
def test_truncated_file(tmp_path, rooms2_db, keep):
    path = save_database(rooms2_db, tmp_path / "db.npz")
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * keep)])
    assert_refused(path)


def test_corrupted_bytes(tmp_path, rooms2_db):
    path = save_database(rooms2_db, tmp_path / "db.npz")
    data = bytearray(path.read_bytes())
    data[2_000:2_100] = b"\x00" * 100  # inside the first member's data: the CRC fails
    path.write_bytes(bytes(data))
    assert_refused(path)


def test_damaged_compressed_npz(tmp_path):
    path = tmp_path / "db.npz"
    np.savez_compressed(path, **good_arrays(2000))
    data = bytearray(path.read_bytes())
    data[2_000:2_040] = bytes(b ^ 0x5A for b in data[2_000:2_040])  # inside a deflate stream
    path.write_bytes(bytes(data))
    assert_refused(path)


def test_float64_beyond_float32_is_refused(tmp_path):
    arrays = good_arrays()
    arrays["sensors"] = arrays["sensors"].astype(np.float64) * 1e300  # finite, inf in float32
    assert_refused(write_npz(tmp_path / "db.npz", **arrays), "sensors", "NaN or inf")


def test_poses_outside_the_world_and_readings_beyond_the_range_are_refused(tmp_path):
    arrays = good_arrays()
    arrays["poses"] = arrays["poses"].copy()
    arrays["poses"][41, 0] = 1e30
    assert_refused(write_npz(tmp_path / "far.npz", **arrays), "pose 41", "outside the 50 x 50")
    arrays = good_arrays()
    arrays["sensors"] = arrays["sensors"].copy()
    arrays["sensors"][7, 2] = -0.5
    assert_refused(write_npz(tmp_path / "neg.npz", **arrays), "sensors row 7", "[0, 10]")


def test_a_header_claiming_a_huge_array_is_refused(tmp_path):
    path = tmp_path / "huge.npz"
    with zipfile.ZipFile(path, "w") as z:
        for key, value in good_arrays().items():
            buf = io.BytesIO()
            if key == "sensors":  # claims 5e11 readings, holds 100 bytes
                header = {"descr": "<f4", "fortran_order": False, "shape": (10**11, 5)}
                np.lib.format.write_array_header_1_0(buf, header)
                buf.write(b"\0" * 100)
            else:
                np.save(buf, value)
            z.writestr(f"{key}.npy", buf.getvalue())
    assert_refused(path)


def test_text_file(tmp_path):
    path = tmp_path / "notes.npz"
    path.write_text("these are not the arrays you are looking for\n")
    with pytest.raises(InputError, match=r"not an \.npz file") as info:
        load_database(path)
    assert "pickle" not in str(info.value)  # numpy's guess for an unknown file, with unsafe advice


def test_npy_file_is_not_a_database(tmp_path):
    path = tmp_path / "one.npz"
    with open(path, "wb") as f:
        np.save(f, np.zeros((10, 5), dtype=np.float32))
    assert_refused(path, "not an .npz")


def test_pickled_object_is_refused(tmp_path):
    """allow_pickle=False: an object array (which would run code on load) is refused."""
    arrays = good_arrays()
    arrays["meta"] = np.array([{"world": "square"}], dtype=object)
    path = write_npz(tmp_path / "pickle.npz", **arrays)
    assert_refused(path)


@pytest.mark.parametrize("key", ["sensors", "motors", "poses", "meta"])
def test_missing_key(tmp_path, key):
    arrays = good_arrays()
    del arrays[key]
    path = write_npz(tmp_path / "db.npz", **arrays)
    assert_refused(path, f"missing {key!r}")


@pytest.mark.parametrize(
    ("key", "shape"),
    [("sensors", (100, 4)), ("motors", (100, 3)), ("poses", (100,)), ("sensors", (100, 5, 1))],
)
def test_wrong_shape(tmp_path, key, shape):
    arrays = good_arrays()
    arrays[key] = np.zeros(shape, dtype=np.float32)
    path = write_npz(tmp_path / "db.npz", **arrays)
    assert_refused(path, key, "shape")


@pytest.mark.parametrize("key", ["sensors", "motors", "poses"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_not_finite(tmp_path, key, bad):
    arrays = good_arrays()
    arrays[key] = arrays[key].copy()
    arrays[key][37, 1] = bad
    path = write_npz(tmp_path / "db.npz", **arrays)
    assert_refused(path, key, "NaN or inf")


@pytest.mark.parametrize("key", ["motors", "poses"])
def test_mismatched_row_counts(tmp_path, key):
    arrays = good_arrays()
    arrays[key] = arrays[key][:-3]
    path = write_npz(tmp_path / "db.npz", **arrays)
    assert_refused(path, key, "97 rows", "100")


def test_not_floating_point(tmp_path):
    arrays = good_arrays()
    arrays["sensors"] = np.ones((100, 5), dtype=np.int64)
    assert_refused(write_npz(tmp_path / "db.npz", **arrays), "floating point")


def test_empty_database(tmp_path):
    arrays = good_arrays()
    for key, cols in (("sensors", 5), ("motors", 2), ("poses", 3)):
        arrays[key] = np.zeros((0, cols), dtype=np.float32)
    assert_refused(write_npz(tmp_path / "db.npz", **arrays), "empty")


@pytest.mark.parametrize(
    "meta",
    [
        "not json",
        json.dumps([1, 2]),
        json.dumps({"seed": 0}),
        json.dumps({"world": {"size": 50, "walls": [[1, 1, 1, 1]]}}),
        json.dumps({"world": {"size": 50, "walls": []}}),  # no name
        json.dumps(
            {
                "world": {"name": "w", "size": 50, "walls": []},
                "sensor_layout": {"angles": [-0.6, -0.3, 0, 0.3, 0.6], "max_range": True},
            }
        ),
    ],
)
def test_bad_meta(tmp_path, meta):
    arrays = good_arrays()
    arrays["meta"] = np.array(meta)
    assert_refused(write_npz(tmp_path / "db.npz", **arrays))


def test_a_file_without_npz_suffix_loads(tmp_path, rooms2_db):
    path = tmp_path / "db.npz"
    save_database(rooms2_db, path)
    other = tmp_path / "db.bin"
    other.write_bytes(path.read_bytes())
    assert len(load_database(other)) == 3_000


def test_zip_of_other_things(tmp_path):
    path = tmp_path / "db.npz"
    with zipfile.ZipFile(path, "w") as z:
        z.writestr("readme.txt", "hello")
    assert_refused(path, "missing 'sensors'")


def test_database_constructed_in_memory_has_no_path(rooms2_db):
    db = Database(rooms2_db.sensors, rooms2_db.motors, rooms2_db.poses, rooms2_db.meta)
    assert db.path is None
    assert len(db) == 3_000


def test_a_non_square_database_round_trips_and_its_poses_are_checked_by_height(tmp_path):
    world = world_from_dict({"name": "wide", "size": [40, 30], "walls": [[20, 0, 20, 20]]})
    db = generate(world, 2000, seed=0)
    assert db.poses[:, 0].max() > 30  # it wanders beyond y's bound in x
    path = save_database(db, tmp_path / "wide.npz")
    assert np.array_equal(load_database(path).poses, db.poses)
    arrays = {k: v for k, v in np.load(path, allow_pickle=False).items()}
    arrays["poses"][5, 1] = 35.0  # y beyond the height, x within
    assert_refused(write_npz(tmp_path / "tall.npz", **arrays), "pose 5", "outside the 40 x 30")


def test_a_database_whose_world_takes_a_builtin_name_with_other_walls_is_refused(tmp_path):
    arrays = good_arrays()
    meta = json.loads(str(arrays["meta"]))
    meta["world"]["walls"] = [[10.0, 10.0, 10.0, 20.0]]  # named "square", walls of another
    arrays["meta"] = np.array(json.dumps(meta))
    assert_refused(write_npz(tmp_path / "fake.npz", **arrays), "meta.world", "other walls")
