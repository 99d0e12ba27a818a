"""Generated floor plans and ROS building maps: rooms reachable, walls where the map draws them."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_one_line_error, run_cli
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.floorplan import check_reachable, random_plan, world_toml
from sensorimotor.sim.rosmap import import_ros_map
from sensorimotor.sim.world import load_world, world_from_dict


@pytest.mark.parametrize(("rooms", "seed"), [(1, 0), (6, 1), (25, 2)])
def test_a_plan_has_its_rooms_all_reachable_and_named(rooms, seed):
    w = random_plan(rooms, seed, door=1.5)
    assert [r.name for r in w.rooms] == [f"room{k}" for k in range(rooms)]
    assert check_reachable(w) == []
    # the rooms tile the world: their areas add up to it, and every free point lies in one
    area = sum(np.ptp(r.polygon[:, 0]) * np.ptp(r.polygon[:, 1]) for r in w.rooms)
    assert area == pytest.approx(w.width * w.height)
    run = sim.rollout(w, 2000, seed=0)
    assert (w.room_index(run.poses[:, 0], run.poses[:, 1]) >= 0).all()
    # each cut leaves one doorway: a wall of two pieces (or one, at an end) per cut
    assert rooms - 1 <= len(w.walls) <= 2 * (rooms - 1)


def test_the_flood_fill_finds_a_room_sealed_off():
    plan = random_plan(4, 3)
    assert check_reachable(plan) == []
    sealed = world_from_dict(
        {
            "name": "sealed",
            "size": [20, 10],
            "walls": [[10, 0, 10, 10]],  # no door
            "rooms": [
                {"name": "a", "rect": [0, 0, 10, 10]},
                {"name": "b", "rect": [10, 0, 20, 10]},
            ],
        }
    )
    assert check_reachable(sealed) == ["b"]


def test_same_seed_same_plan_and_the_world_file_round_trips(tmp_path):
    a, b = random_plan(9, 5), random_plan(9, 5)
    assert a == b
    assert random_plan(9, 6) != a
    path = tmp_path / "plan.toml"
    path.write_text(world_toml(a, "a comment"))
    back = load_world(path)
    assert back == a
    assert [r.name for r in back.rooms] == [r.name for r in a.rooms]


def test_too_many_rooms_and_bad_doors_are_refused():
    with pytest.raises(InputError, match="30 rooms do not fit a 20 x 20 world"):
        random_plan(30, 0, size=(20.0, 20.0))
    with pytest.raises(InputError, match="--door must be positive"):
        random_plan(4, 0, door=0.0)
    with pytest.raises(InputError, match="--door must be positive"):
        random_plan(4, 0, door=5.0)


def test_world_random_from_the_command_line(tmp_path):
    out = tmp_path / "plan.toml"
    proc = run_cli("world", "random", "--rooms", "7", "--seed", "4", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert load_world(out) == random_plan(7, 4)
    bad = tmp_path / "big.toml"
    proc = run_cli("world", "random", "--rooms", "40", "--size", "20", "--out", bad)
    assert_one_line_error(proc, "40 rooms do not fit a 20 x 20 world")
    assert not bad.exists()


# ---------------------------------------------------------------- ROS map_server maps


def draw_map(folder, negate=False, png=False, resolution=0.5, image=None):
    """A 40 x 60 pixel map: unknown outside, a free hall inside a 2-pixel wall, and an inner
    wall (columns 30-31) from the hall's top down to row 24, leaving a gap below it."""
    img = np.full((40, 60), 205, np.uint8)  # unknown
    img[5:35, 5:55] = 254  # free
    img[5:35, 5:7] = img[5:35, 53:55] = img[5:7, 5:55] = img[33:35, 5:55] = 0  # outer walls
    img[5:25, 30:32] = 0  # inner wall, hanging from the top
    if negate:
        img = 255 - img
    name = image or ("map.png" if png else "map.pgm")
    if png:
        from matplotlib.image import imsave

        imsave(folder / name, img, cmap="gray", vmin=0, vmax=255)
    else:
        (folder / name).write_bytes(b"P5\n# drawn by a test\n60 40\n255\n" + img.tobytes())
    yaml = folder / "map.yaml"
    yaml.write_text(
        f"image: {name}  # beside\nresolution: {resolution}\norigin: [-2.0, -1.0, 0.0]\n"
        f"negate: {int(negate)}\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
    )
    return yaml


EXPECTED_WALLS = {  # in metres, 0.5 m pixels, image row 0 at the top (y = 20)
    (3.5, 3.5, 26.5, 3.5),  # the hall's bottom, top, left and right sides
    (3.5, 16.5, 15.0, 16.5),
    (16.0, 16.5, 26.5, 16.5),
    (3.5, 3.5, 3.5, 16.5),
    (26.5, 3.5, 26.5, 16.5),
    (15.0, 7.5, 16.0, 7.5),  # the inner wall: its end and both faces
    (15.0, 7.5, 15.0, 16.5),
    (16.0, 7.5, 16.0, 16.5),
}


@pytest.mark.parametrize(("negate", "png"), [(False, False), (True, False), (False, True)])
def test_a_drawn_map_becomes_the_walls_it_draws(tmp_path, negate, png):
    world, comment = import_ros_map(draw_map(tmp_path, negate, png))
    assert (world.width, world.height) == (30.0, 20.0)
    assert {tuple(w) for w in world.walls.tolist()} == EXPECTED_WALLS
    assert "origin [-2.0, -1.0, 0.0]" in comment
    # a ray from the hall's middle to the right stops at the inner wall's left face (x = 15)
    assert sim.read_sensors(world, np.array([10.0, 12.0, 0.0]), sim.SensorLayout((0.0,), 50.0))[
        0, 0
    ] == pytest.approx(5.0)


def test_world_import_from_the_command_line(tmp_path):
    out = tmp_path / "building.toml"
    proc = run_cli("world", "import", draw_map(tmp_path), "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert {tuple(w) for w in load_world(out).walls.tolist()} == EXPECTED_WALLS
    assert "units: 1 unit = 1 m" in proc.stderr  # it says what a unit is
    scaled = tmp_path / "scaled.toml"
    proc = run_cli("world", "import", draw_map(tmp_path), "--out", scaled, "--scale", "2")
    assert proc.returncode == 0, proc.stderr
    assert "1 unit = 0.5 m" in proc.stderr
    assert {tuple(w) for w in load_world(scaled).walls.tolist()} == {
        tuple(2 * v for v in w) for w in EXPECTED_WALLS
    }
    assert_one_line_error(
        run_cli("world", "import", draw_map(tmp_path), "--out", tmp_path / "z.toml", "--scale", "0"),
        "--scale must be a positive number",
    )
    yaml = tmp_path / "map.yaml"
    yaml.write_text(yaml.read_text().replace("resolution: 0.5", "resolution: -0.5"))
    other = tmp_path / "other.toml"
    assert_one_line_error(run_cli("world", "import", yaml, "--out", other), "must be positive")
    assert not other.exists()


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda y, d: y.write_text(y.read_text().replace("map.pgm", "gone.pgm")), "gone.pgm: map image not found"),
        (lambda y, d: y.write_text(y.read_text().replace("resolution: 0.5", "resolution: -0.5")), "'resolution' must be positive"),
        (lambda y, d: (d / "map.pgm").write_text("hello, not a map"), "not a map image"),
        (lambda y, d: (d / "map.pgm").write_bytes(b"P5\n60 40\n255\n" + bytes(10)), "truncated PGM"),
        (lambda y, d: y.write_text(y.read_text().replace("free_thresh: 0.196", "free_thresh: 0.9")), "thresholds must satisfy"),
        (lambda y, d: y.write_text("resolution: 0.5\n"), "missing key 'image'"),
        (lambda y, d: y.write_text("image map.pgm\n"), "expected 'key: value'"),
    ],
)  # fmt: skip
def test_bad_maps_are_refused_in_one_line_naming_the_file(tmp_path, edit, needle):
    yaml = draw_map(tmp_path)
    edit(yaml, tmp_path)
    with pytest.raises(InputError) as err:
        import_ros_map(yaml)
    assert needle in str(err.value)
    assert "\n" not in str(err.value)
