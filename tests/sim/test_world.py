"""World files: the built-in worlds are DESIGN.md's, and every bad file is refused in one line."""

from __future__ import annotations

import numpy as np
import pytest

from sensorimotor.errors import InputError
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.sim.world import (
    BUILTIN_WORLDS,
    free_start_cells,
    load_world,
    point_segment_distance,
    world_from_dict,
)

# DESIGN.md, "Built-in worlds": the inner walls of each, x0, y0, x1, y1.
DESIGN_WALLS = {
    "square": [],
    "rooms1": [[25, 0, 25, 35], [0, 25, 15, 25]],
    "rooms2": [[0, 25, 38, 25], [17, 0, 17, 17], [33, 0, 33, 17], [25, 25, 25, 42]],
}
OUTER = [[0, 0, 50, 0], [50, 0, 50, 50], [50, 50, 0, 50], [0, 50, 0, 0]]

# (file text, words the one-line message must contain): every way a world file can be bad.
BAD_WORLD_FILES = {
    "not_toml": ("size = 50\nwalls = [[1, 2, 3\n", "not valid TOML"),
    "empty": ("", "empty"),
    "blank": ("  \n\n", "empty"),
    "unknown_key": ("size = 50\nwalls = []\ncolour = 'red'\n", "unknown key 'colour'"),
    "missing_size": ("walls = []\n", "missing key 'size'"),
    "missing_walls": ("size = 50\n", "missing key 'walls'"),
    "size_zero": ("size = 0\nwalls = []\n", "must be positive"),
    "size_negative": ("size = [50, -3]\nwalls = []\n", "must be positive"),
    "size_three": ("size = [50, 50, 50]\nwalls = []\n", "'size' must be"),
    "size_text": ("size = 'big'\nwalls = []\n", "'size' must be numbers"),
    "size_nan": ("size = nan\nwalls = []\n", "not a finite number"),
    "size_inf": ("size = [inf, 50]\nwalls = []\n", "not a finite number"),
    "wall_nan": ("size = 50\nwalls = [[1, 1, nan, 5]]\n", "not a finite number"),
    "wall_inf": ("size = 50\nwalls = [[1, 1, 5, -inf]]\n", "not a finite number"),
    "wall_three": ("size = 50\nwalls = [[1, 1, 5]]\n", "must be 4 numbers"),
    "wall_text": ("size = 50\nwalls = [[1, 1, 5, 'x']]\n", "must be 4 numbers"),
    "wall_bool": ("size = 50\nwalls = [[1, 1, 5, true]]\n", "must be 4 numbers"),
    "walls_not_list": ("size = 50\nwalls = 3\n", "'walls' must be a list"),
    "wall_outside": ("size = 50\nwalls = [[10, 10, 60, 10]]\n", "outside the 50 x 50 world"),
    "wall_negative": ("size = 50\nwalls = [[-1, 10, 20, 10]]\n", "outside"),
    "wall_zero_length": ("size = 50\nwalls = [[10, 10, 10, 10]]\n", "zero length"),
    "no_free_start": ("size = 1.5\nwalls = []\n", "no free start position"),
    "no_free_start_walls": (
        # 10 x 10 cut into 2-wide strips: every point is within 1 of a wall
        "size = 10\nwalls = [[2, 0, 2, 10], [4, 0, 4, 10], [6, 0, 6, 10], [8, 0, 8, 10]]\n",
        "no free start position",
    ),
    "name_empty": ("name = ''\nsize = 50\nwalls = []\n", "'name'"),
    "name_a_path": (
        "name = '../escape'\nsize = 50\nwalls = []\n",
        "'name' must be 1 to 100 letters",
    ),
    "name_a_folder": ("name = 'a/b'\nsize = 50\nwalls = []\n", "'name' must be 1 to 100 letters"),
    "name_newline": ("name = 'a\\nb'\nsize = 50\nwalls = []\n", "'name' must be 1 to 100 letters"),
    "size_huge_int": ("size = 1" + "0" * 400 + "\nwalls = []\n", "not a finite number"),
    "size_huge": ("size = 1e300\nwalls = []\n", "at most 10000"),
    "wall_huge_int": ("size = 50\nwalls = [[1, 1, 5, 1" + "0" * 400 + "]]\n", "not a finite"),
    "too_many_walls": (
        "size = 50\nwalls = [" + ",".join(["[1,1,2,2]"] * 100_001) + "]\n",
        "100,001 walls; at most 100,000",
    ),
}


@pytest.mark.parametrize("name", BUILTIN_WORLDS)
def test_builtin_worlds_have_the_walls_of_design(name):
    world = load_world(name)
    assert world.name == name
    assert (world.width, world.height) == (50.0, 50.0)
    assert world.walls.dtype == np.float64
    assert world.walls.shape == (len(DESIGN_WALLS[name]), 4)
    assert world.walls.tolist() == DESIGN_WALLS[name]
    assert world.segments.dtype == np.float64
    assert world.segments.tolist() == OUTER + DESIGN_WALLS[name]


def test_world_file_round_trip(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text("size = [40, 30]\nwalls = [[0, 10, 20.5, 10], [30, 30, 30, 5]]\n")
    world = load_world(path)
    assert world.name == "mine"  # no `name`: the file's stem
    assert (world.width, world.height) == (40.0, 30.0)
    assert world.walls.tolist() == [[0, 10, 20.5, 10], [30, 30, 30, 5]]
    assert world.segments[:4].tolist() == [[0, 0, 40, 0], [40, 0, 40, 30], [40, 30, 0, 30],
                                           [0, 30, 0, 0]]  # fmt: skip
    assert world_from_dict(world.to_dict()) == world


def test_oblique_walls_are_accepted():
    world = world_from_dict({"size": 50, "walls": [[5, 5, 20, 30], [49.5, 0.5, 30, 45]]})
    assert world.walls.shape == (2, 4)
    assert world.to_dict() == {
        "name": "dict",
        "size": [50.0, 50.0],
        "walls": [[5.0, 5.0, 20.0, 30.0], [49.5, 0.5, 30.0, 45.0]],
    }


@pytest.mark.parametrize("case", sorted(BAD_WORLD_FILES))
def test_bad_world_file_is_refused_naming_file_and_problem(tmp_path, case):
    text, problem = BAD_WORLD_FILES[case]
    path = tmp_path / f"{case}.toml"
    path.write_text(text)
    with pytest.raises(InputError) as info:
        load_world(path)
    message = str(info.value)
    assert "\n" not in message
    assert str(path) in message
    assert problem in message


def test_missing_world_file_and_folder_and_unknown_name(tmp_path):
    with pytest.raises(InputError, match="world file not found"):
        load_world(tmp_path / "nope.toml")
    with pytest.raises(InputError, match="is a folder"):
        load_world(tmp_path)
    with pytest.raises(InputError, match=r"unknown world 'mars'.*square, rooms1, rooms2"):
        load_world("mars")


def test_a_world_without_a_name_is_named_after_its_file_made_safe(tmp_path):
    path = tmp_path / "my world (v2).toml"
    path.write_text("size = 50\nwalls = []\n")
    assert load_world(path).name == "my-world-v2"


def test_binary_world_file_is_refused(tmp_path):
    path = tmp_path / "bin.toml"
    path.write_bytes(b"\xff\xfe\x00size")
    with pytest.raises(InputError, match=r"bin\.toml"):
        load_world(path)


def test_point_segment_distance_by_hand():
    segments = np.array([[0.0, 0.0, 10.0, 0.0], [0.0, 0.0, 3.0, 4.0]])
    d = point_segment_distance(segments, np.array([5.0, -3.0, 13.0]), np.array([2.0, 0.0, 4.0]))
    # (5, 2): 2 above the first; its projection on the second (3, 4)/5 is u = 23/25 -> beyond no
    # end, distance |cross| / 5 = |5*4 - 2*3| / 5 = 2.8.
    np.testing.assert_allclose(d[0], [2.0, 2.8])
    # (-3, 0): before both starts -> distance to (0, 0) = 3.
    np.testing.assert_allclose(d[1], [3.0, 3.0])
    # (13, 4): beyond both ends -> to (10, 0) is 5, to (3, 4) is 10.
    np.testing.assert_allclose(d[2], [5.0, 10.0])


@pytest.mark.parametrize("name", BUILTIN_WORLDS)
def test_free_start_cells_keep_their_distance(name):
    world = load_world(name)
    cells = free_start_cells(world)
    assert len(cells) > 1000
    dist = point_segment_distance(world.segments, cells[:, 0], cells[:, 1]).min(axis=1)
    assert dist.min() >= 1.0


def test_a_wide_world_checks_x_against_its_width_and_y_against_its_height():
    wide = {"name": "wide", "size": [50, 20]}
    assert world_from_dict({**wide, "walls": [[45, 1, 45, 10]]}).width == 50  # x in 20..50
    with pytest.raises(InputError, match="lies outside the 50 x 20 world"):
        world_from_dict({**wide, "walls": [[1, 25, 5, 25]]})  # y beyond 20
    cells = free_start_cells(world_from_dict({**wide, "walls": []}))
    assert cells[:, 0].max() > 45  # the grid spans 50 x 20
    assert cells[:, 1].max() < 19
    assert cells[:, :2].min() >= 1


def test_a_world_file_may_not_take_a_builtin_name_with_other_walls(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text('name = "square"\nsize = 50\nwalls = [[10, 10, 10, 20]]\n')
    with pytest.raises(InputError, match="name of a built-in world with other walls") as info:
        load_world(path)
    assert str(path) in str(info.value)
    unnamed = tmp_path / "square.toml"  # named after its file
    unnamed.write_text("size = 50\nwalls = [[10, 10, 10, 20]]\n")
    with pytest.raises(InputError, match="'square'"):
        load_world(unnamed)
    path.write_text('name = "square"\nsize = 50\nwalls = []\n')  # the built-in Square itself
    assert load_world(path) == load_world("square")


def test_the_built_in_worlds_name_their_rooms_and_every_free_point_lies_in_one():
    expected = {"square": 1, "rooms1": 3, "rooms2": 5}
    for name, n in expected.items():
        world = load_world(name)
        assert len(world.rooms) == n
        free = free_start_cells(world)
        assert (world.room_index(free[:, 0], free[:, 1]) >= 0).all()
    rooms1 = load_world("rooms1")
    idx = rooms1.room_index(np.array([10.0, 10.0, 40.0, 25.0]), np.array([10.0, 40.0, 10.0, 10.0]))
    assert [rooms1.rooms[i].name for i in idx] == ["southwest", "northwest", "east", "southwest"]


def test_a_polygon_room_holds_what_is_inside_it_and_only_that(tmp_path):
    path = tmp_path / "tri.toml"
    path.write_text(
        'name = "tri"\nsize = 10\nwalls = []\n'
        'rooms = [{ name = "corner", polygon = [[0, 0], [10, 0], [0, 10]] }]\n'
    )
    world = load_world(path)
    x, y = np.array([1.0, 6.0, 5.0, 0.0]), np.array([1.0, 6.0, 5.0, 10.0])
    assert world.room_index(x, y).tolist() == [0, -1, 0, 0]  # the hypotenuse and a vertex count


def test_a_rectangle_room_is_the_same_closed_box_by_its_bounds_as_by_the_general_rule(
    monkeypatch,
):
    """The bounds test of an axis-aligned rectangle (every built-in room) answers as the even-odd
    and on-edge rule does, on random points, its edges, its corners and just off them."""
    from sensorimotor.sim import world as world_module

    rng = np.random.default_rng(0)
    for room in (*load_world("rooms2").rooms, *load_world("rooms1").rooms):
        (x0, y0), (x1, y1) = room.polygon.min(axis=0), room.polygon.max(axis=0)
        xs = np.concatenate([rng.uniform(-5, 55, 4000), np.repeat([x0, x1], 50),
                             [x0 - 1e-12, x1 + 1e-12, x0 + 1e-12, x1 - 1e-12, x0, x1]])
        ys = np.concatenate([rng.uniform(-5, 55, 4000), rng.uniform(y0, y1, 100),
                             [y0, y1, y0 - 1e-12, y1 + 1e-12, y0, y1]])  # fmt: skip
        fast = world_module.point_in_polygon(room.polygon, xs, ys)
        with monkeypatch.context() as m:
            m.setattr(world_module, "_axis_aligned_box", lambda _: None)  # the general rule
            general = world_module.point_in_polygon(room.polygon, xs, ys)
        assert np.array_equal(fast, general), room.name
        assert fast[-6:].tolist() == [False, False, False, False, True, True]
    skew = np.array([[0.0, 0.0], [10.0, 1.0], [10.0, 10.0], [0.0, 10.0]])  # not a box: the rule
    assert world_module._axis_aligned_box(skew) is None


def test_rooms_travel_with_a_custom_worlds_database_but_not_a_built_in_ones(tmp_path):
    path = tmp_path / "two.toml"
    path.write_text(
        'name = "two"\nsize = 20\nwalls = [[10, 0, 10, 15]]\n'
        'rooms = [{ name = "a", rect = [0, 0, 10, 20] }, { name = "b", rect = [10, 0, 20, 20] }]\n'
    )
    for world, recorded in ((load_world(path), True), (load_world("rooms1"), False)):
        save_database(generate(world, 500, seed=0), tmp_path / "db.npz")
        db = load_database(tmp_path / "db.npz")
        assert ("rooms" in db.meta["world"]) is recorded
        assert [r.name for r in db.world.rooms] == [r.name for r in world.rooms]


@pytest.mark.parametrize(
    ("rooms", "needle"),
    [
        ('[{ name = "a", rect = [0, 0, 60, 10] }]', "outside"),
        ('[{ name = "a", rect = [0, 0, 0, 10] }]', "zero area"),
        ('[{ name = "a", rect = [0, 0, 5, 5] }, { name = "a", rect = [5, 5, 9, 9] }]', "taken"),
        ('[{ name = "a", polygon = [[0, 0], [1, 1]] }]', "polygon 3 or more"),
        ('[{ name = "a" }]', "room 0 must be"),
        ('"hall"', "'rooms' must be a list"),
    ],
)
def test_bad_rooms_are_refused_naming_the_file(rooms, needle, tmp_path):
    path = tmp_path / "w.toml"
    path.write_text(f'name = "w"\nsize = 50\nwalls = []\nrooms = {rooms}\n')
    with pytest.raises(InputError, match=needle) as err:
        load_world(path)
    assert str(path) in str(err.value)
