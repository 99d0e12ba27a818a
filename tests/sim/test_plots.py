"""The simulator figures: what each plot function draws, the paper's five situations found in
real databases, atomic saving, and the real ``sensorimotor plot`` commands on small data."""

from __future__ import annotations

import matplotlib.image
import numpy as np
import pytest
from matplotlib.axes import Axes
from matplotlib.colors import to_rgba
from matplotlib.figure import Figure

from conftest import assert_one_line_error
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim import events, figures, plots
from sensorimotor.sim.database import generate, load_database
from sensorimotor.sim.world import (
    BUILTIN_WORLDS,
    load_world,
    point_segment_distance,
    world_from_dict,
)

RED = to_rgba("red")


def gid_lines(ax: Axes, gid: str) -> list:
    return [line for line in ax.get_lines() if line.get_gid() == gid]


def percept(ax: Axes):
    (scatter,) = [c for c in ax.collections if c.get_gid() == "percept"]
    return scatter


# ---------------------------------------------------------------------------- plot functions


@pytest.mark.parametrize("name", BUILTIN_WORLDS)
def test_plot_world_draws_one_line_per_wall_within_the_world(name):
    world = load_world(name)
    ax = plots.plot_world(world)
    walls = gid_lines(ax, "wall")
    assert len(walls) == len(world.segments)
    drawn = sorted(tuple(np.ravel(line.get_xydata().T)) for line in walls)  # x0, x1, y0, y1
    expected = sorted((x0, x1, y0, y1) for x0, y0, x1, y1 in world.segments)
    assert drawn == expected
    assert ax.get_xlim() == (0.0, world.width)
    assert ax.get_ylim() == (0.0, world.height)
    assert ax.get_aspect() == 1.0
    assert ax.get_title() == name


def test_plot_functions_draw_on_the_given_axes_and_make_no_figure_otherwise():
    fig = Figure()
    ax = fig.add_subplot()
    world = load_world("rooms1")
    assert plots.plot_world(world, ax) is ax
    assert plots.plot_trajectory(world, np.array([[5.0, 5.0, 0.0], [6.0, 5.0, 0.0]]), ax) is ax
    assert plots.plot_perception(world, (5.0, 5.0, 0.0), np.full(5, 10.0), ax) is ax
    assert len(fig.axes) == 1
    new = plots.plot_world(world)
    assert new.figure is not fig
    assert isinstance(new.figure, Figure)


def test_plot_trajectory_draws_the_path_through_every_pose():
    world = load_world("square")
    poses = sim.rollout(world, 500, seed=0).poses
    ax = plots.plot_trajectory(world, poses)
    (path,) = gid_lines(ax, "path")
    np.testing.assert_array_equal(path.get_xydata(), poses[:, :2])
    assert "500 steps" in ax.get_title()


def test_plot_perception_draws_five_red_dots_at_the_readings():
    world = load_world("square")
    pose = (45.0, 25.0, 0.0)  # facing the wall x = 50, 5 away
    sensors = sim.read_sensors(world, np.array([pose]))[0]
    ax = plots.plot_perception(world, pose, sensors)
    dots = percept(ax)
    points = dots.get_offsets()
    assert points.shape == (5, 2)
    np.testing.assert_allclose(points[:, 0], 50.0)  # every dot on the wall it hit
    np.testing.assert_allclose(points[2], [50.0, 25.0])  # the middle ray straight ahead
    assert np.all(dots.get_edgecolors() == RED)
    assert np.all(dots.get_facecolors() == RED)  # filled: every ray hit a wall
    assert len(gid_lines(ax, "ray")) == 5
    assert len(gid_lines(ax, "agent")) == 1


def test_plot_perception_draws_hollow_dots_where_nothing_is_seen():
    world = load_world("square")
    ax = plots.plot_perception(world, (25.0, 25.0, 0.0), np.full(5, 10.0))
    dots = percept(ax)
    assert len(dots.get_offsets()) == 5
    assert np.all(dots.get_edgecolors() == RED)
    assert np.all(dots.get_facecolors()[:, 3] == 0.0)  # no fill


def test_plot_perception_zooms_around_the_sensor_fan():
    world = load_world("square")
    ax = plots.plot_perception(world, (45.0, 25.0, 0.0), np.full(5, 5.0), view=7.5)
    x0, x1 = ax.get_xlim()
    assert x1 - x0 == pytest.approx(15.0)
    assert x0 < 45.0 < 55.0 <= x1  # the agent and 10 units ahead of it


# --------------------------------------------------------------------- the five situations


@pytest.fixture(scope="module")
def rooms1_db(rooms1_db_path):
    return load_database(rooms1_db_path)


def test_hit_walls_names_the_wall_each_ray_hits():
    world = load_world("rooms1")  # segments: 4 outer walls, then (25,0)-(25,35), (0,25)-(15,25)
    poses = np.array([[30.0, 10.0, np.pi], [12.0, 20.0, np.pi / 2], [45.0, 45.0, 0.5]])
    walls = sim.hit_walls(world, poses)
    assert walls.tolist()[0] == [4] * 5  # the vertical inner wall, 5 ahead
    assert walls.tolist()[1] == [-1, 5, 5, 5, 5]  # the rightmost ray passes the end (15, 25)
    assert walls.tolist()[2] == [1, 1, 1, 2, 2]  # a corner: the right wall, then the top


def test_pick_situations_finds_the_papers_five_in_a_rooms1_database(rooms1_db):
    db = rooms1_db
    world = db.world
    found = figures.pick_situations(db)
    assert list(found) == list(figures.SITUATIONS)
    rows = np.array(list(found.values()))
    poses = db.poses[rows].astype(np.float64)
    true = sim.read_sensors(world, poses)
    by_name = dict(zip(found, range(len(rows)), strict=True))
    nothing, line, corner, left, end = (by_name[name] for name in figures.SITUATIONS)
    np.testing.assert_allclose(db.sensors[found["nothing"]], 10.0)
    walls = sim.hit_walls(world, poses)
    assert len(set(walls[line])) == 1
    assert walls[line, 0] >= 0
    assert events.corner_in_view(world, poses[[corner]])[0]
    assert np.all(true[left, 3:] < 10.0)
    assert np.all(true[left, :3] == 10.0)
    assert events.wall_end_in_view(world, poses[[end]])[0]
    assert not events.corner_in_view(world, poses[[nothing, line, left]]).any()


def test_a_world_without_inner_walls_has_no_wall_end(square_db_path):
    found = figures.pick_situations(load_database(square_db_path))
    assert "wall end" not in found
    assert {"nothing", "line", "corner", "wall at its left"} <= set(found)


def test_perception_figure_has_one_panel_per_situation(rooms1_db):
    fig = figures.perception_figure(rooms1_db)
    assert len(fig.axes) == 5
    for ax, caption in zip(fig.axes, figures.SITUATIONS.values(), strict=True):
        assert caption in ax.get_title()
        assert len(percept(ax).get_offsets()) == 5


def test_perception_figure_draws_a_databases_own_sensor_layout():
    layout = sim.SensorLayout(angles=(-1.2, -0.6, 0.0, 0.6, 1.2), max_range=6.0)
    db = generate(load_world("rooms1"), 20_000, seed=1, layout=layout)
    fig = figures.perception_figure(db)
    assert len(fig.axes) >= 4
    for ax in fig.axes:
        dots = percept(ax)
        hit = np.asarray(dots.get_facecolors())[:, 3] > 0  # filled: a wall was hit
        points = dots.get_offsets()[hit]
        gaps = point_segment_distance(db.world.segments, points[:, 0], points[:, 1]).min(axis=1)
        assert np.all(gaps < 1e-4), ax.get_title()  # every hit drawn on a wall, at its own angle


def test_generate_records_any_layout_and_walks_the_paper_path():
    """Layouts of any size (issue 23): 6 rays are 6 columns, and a layout without a ray straight
    ahead walks the path of the paper's (the behaviour reads the paper's 5 rays)."""
    world = load_world("square")
    six = generate(world, 100, layout=sim.SensorLayout(angles=(-0.6, -0.3, 0.0, 0.3, 0.6, 0.9)))
    assert six.sensors.shape == (100, 6)
    blind = generate(world, 100, layout=sim.SensorLayout(angles=(-1.2, -0.6, 0.1, 0.6, 1.2)))
    np.testing.assert_array_equal(blind.poses, generate(world, 100).poses)


def test_panels_take_the_shape_of_their_world():
    hall = world_from_dict({"name": "hall", "size": [60, 20], "walls": []})
    tower = world_from_dict({"name": "tower", "size": [20, 60], "walls": []})
    assert tuple(plots.plot_world(load_world("square")).figure.get_size_inches()) == (3.2, 3.2)
    width, height = plots.plot_world(hall).figure.get_size_inches()
    assert width == 3.2
    assert 1.2 < height < 1.6  # a third as high, and room for the tick labels
    width, height = plots.plot_world(tower).figure.get_size_inches()
    assert height == 3.2
    assert width < 2.3
    width, height = figures.worlds_figure([hall, hall]).get_size_inches()
    assert width > 3 * height  # two flat panels side by side, not two squares


# ----------------------------------------------------------------------------------- saving


def test_save_figure_writes_png_and_svg_atomically(tmp_path):
    fig = figures.worlds_figure([load_world("square")])
    written = plots.save_figure(fig, tmp_path / "w.png", svg=True)
    assert written == [tmp_path / "w.png", tmp_path / "w.svg"]
    assert matplotlib.image.imread(tmp_path / "w.png").ndim == 3
    assert (tmp_path / "w.svg").read_text().lstrip().startswith("<?xml")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w.png", "w.svg"]  # no temp left


def test_save_figure_into_a_missing_folder_is_an_input_error(tmp_path):
    fig = figures.worlds_figure([load_world("square")])
    with pytest.raises(InputError, match="does not exist"):
        plots.save_figure(fig, tmp_path / "nowhere" / "w.png")


# ------------------------------------------------------------------------ the real command


def png_shape(path) -> tuple[int, ...]:
    return matplotlib.image.imread(path).shape


def panel_pixels(n: int) -> tuple[int, int]:
    """(height, width) in pixels of a row of ``n`` panels saved at the default 150 dpi."""
    return round((plots.PANEL_SIZE + 0.3) * 150), round(plots.PANEL_SIZE * n * 150)


def test_cli_plot_world(cli, tmp_path):
    out = tmp_path / "worlds.png"
    proc = cli("plot", "world", "square", "rooms1", "rooms2", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert png_shape(out)[:2] == panel_pixels(3)


def test_cli_plot_trajectory(cli, tmp_path, square_db_path, rooms1_db_path):
    out = tmp_path / "traj.png"
    proc = cli("plot", "trajectory", "--data", square_db_path, "--data", rooms1_db_path,
               "--steps", "10000", "--out", out, "--svg")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert png_shape(out)[:2] == panel_pixels(2)
    assert out.with_suffix(".svg").exists()


def test_cli_plot_perception(cli, tmp_path, rooms1_db_path):
    out = tmp_path / "perception.png"
    proc = cli("plot", "perception", "--data", rooms1_db_path, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert png_shape(out)[:2] == panel_pixels(5)
    rows = tmp_path / "rows.png"
    proc = cli("plot", "perception", "--data", rooms1_db_path, "--row", "0", "--row", "7",
               "--view", "0", "--out", rows)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert png_shape(rows)[:2] == panel_pixels(2)


def test_cli_plot_bad_input_is_one_line_and_exit_2(cli, tmp_path, rooms1_db_path):
    missing = tmp_path / "missing.npz"
    assert_one_line_error(cli("plot", "trajectory", "--data", missing), "missing.npz")
    assert_one_line_error(cli("plot", "perception", "--data", missing), "missing.npz")
    assert_one_line_error(cli("plot", "world", "atlantis"), "atlantis")
    jpg = tmp_path / "w.jpg"
    assert_one_line_error(cli("plot", "world", "square", "--out", jpg), "w.jpg", ".png")
    nowhere = tmp_path / "no" / "w.png"
    assert_one_line_error(cli("plot", "world", "square", "--out", nowhere), "w.png")
    proc = cli("plot", "perception", "--data", rooms1_db_path, "--row", "99999999")
    assert_one_line_error(proc, "rooms1.npz", "99999999")
    not_db = tmp_path / "text.npz"
    not_db.write_text("hello")
    assert_one_line_error(cli("plot", "perception", "--data", not_db), "text.npz")
    proc = cli("plot", "perception", "--data", rooms1_db_path, "--view", "inf")
    assert_one_line_error(proc, "--view")
    (tmp_path / "w.svg").mkdir()
    proc = cli("plot", "world", "square", "--out", tmp_path / "w.png", "--svg")
    assert_one_line_error(proc, "w.svg", "is a folder")
    assert not list(tmp_path.glob("*.png"))
