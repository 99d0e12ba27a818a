"""Traps of the paper's behaviour in imported maps: a free pocket narrower than the clearance
closes at import (``sim.rosmap.open_free``), a wide room or bay stays, every place left has a
heading whose five rays all clear the turn-around distance; the campus figure marks a trap.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import assert_one_line_error, run_cli
from sensorimotor.errors import InputError
from sensorimotor.sim.core import SENSOR_ANGLES, TURN_THRESHOLD, read_sensors
from sensorimotor.sim.database import generate
from sensorimotor.sim.figures import campus_figure
from sensorimotor.sim.mrpt import gridmap_bytes
from sensorimotor.sim.plots import save_figure
from sensorimotor.sim.rosmap import CLEARANCE, grid_world, import_mrpt_map, open_free
from sensorimotor.sim.world import load_world
from sim.test_floorplan import EXPECTED_WALLS, draw_map


def test_the_clearance_is_twice_the_turn_around_distance():
    assert CLEARANCE == 2 * TURN_THRESHOLD == 2.0


def _room_with_a_pocket_and_a_bay(path):
    """An MRPT grid of 0.25 m cells: a 10 x 7 m room (rows 4-31, columns 4-43), a pocket 1 m
    wide and 1.5 m deep out of its top (columns 10-13), a bay 3 m wide and 2.5 m deep out of
    its right side (rows 12-23); unknown around."""
    free = np.full((40, 56), 0.5)
    free[4:32, 4:44] = 0.99  # the room
    free[32:38, 10:14] = 0.99  # the pocket
    free[12:24, 44:54] = 0.99  # the bay
    path.write_bytes(gridmap_bytes(free, 0.25))
    return path


def test_a_pocket_narrower_than_the_clearance_closes_and_a_wide_bay_stays(tmp_path):
    path = _room_with_a_pocket_and_a_bay(tmp_path / "yard.gridmap")
    kept, _ = import_mrpt_map(path, clearance=0)
    opened, comment = import_mrpt_map(path)  # CLEARANCE, the default
    assert "opened to a clearance of 2 m" in comment
    # cropped one cell around the free space: the pocket, 1.5 m deep, made the world taller;
    # opened, one cell of its mouth is left (the disks that touch the room's top reach in)
    assert (kept.width, kept.height) == (13.0, 9.0)
    assert (opened.width, opened.height) == (13.0, 7.75)
    assert np.asarray(kept.walls)[:, [1, 3]].max() == 8.75  # the pocket's end
    assert np.asarray(opened.walls)[:, [1, 3]].max() == 7.5  # the room's top is at 7.25
    # the bay stays: from the room, a ray along its middle reads its far end as before
    pose = np.array([5.0, 3.75, 0.0])
    assert read_sensors(kept, pose)[0, 2] == pytest.approx(7.75)
    assert read_sensors(opened, pose)[0, 2] == pytest.approx(7.75)


def _clear_heading(world, points: np.ndarray, headings: int = 72) -> np.ndarray:
    """(P,) whether some heading at each point reads at least TURN_THRESHOLD on all five of
    the paper's rays: where the behaviour can walk on, not turn in place."""
    h = np.arange(headings) * (2 * np.pi / headings)
    poses = np.column_stack([np.repeat(points, headings, axis=0), np.tile(h, len(points))])
    lowest = read_sensors(world, poses).min(axis=1).reshape(len(points), headings)
    return (lowest >= TURN_THRESHOLD).any(axis=1)


def test_from_every_place_left_by_the_opening_some_heading_clears_the_five_rays(tmp_path):
    assert len(SENSOR_ANGLES) == 5
    res = 0.2
    blocked = np.ones((50, 80), dtype=bool)  # row 0 at y = 0
    blocked[5:35, 5:50] = False  # a 9 x 6 m room
    blocked[35:45, 20:24] = False  # a pocket 0.8 m wide, 2 m deep
    blocked[10:30, 50:60] = False  # a bay 4 m wide
    for t in range(12):  # out of the bay, a wedge narrowing from 2.2 m to one cell
        half = (11 - t) // 2
        blocked[20 - half : 21 + half, 60 + t] = False
    trap = np.array([[4.4, 8.7]])  # (x, y): the pocket's far end
    worlds = {}
    for clearance in (0.0, CLEARANCE):
        opened = open_free(blocked, res, clearance, tmp_path)
        world = grid_world(opened, res, "pocket", tmp_path)
        rows, cols = np.nonzero(~opened)
        centres = np.column_stack([(cols + 0.5) * res, (rows + 0.5) * res])
        worlds[clearance] = (world, centres, _clear_heading(world, centres))
    world, centres, clear = worlds[0.0]
    assert not _clear_heading(world, trap)[0]  # deep in the pocket every heading turns
    assert not clear.all()
    world, centres, clear = worlds[CLEARANCE]
    assert clear.all(), centres[~clear]  # no place left where it can only turn
    assert not (np.hypot(*(centres - trap[0]).T) < 1.0).any()  # the pocket is closed
    assert (np.hypot(*(centres - [8 * res, 8 * res]).T) < res).any()  # the room is not


def test_an_opening_that_leaves_nothing_or_a_bad_clearance_is_one_line(tmp_path):
    blocked = np.ones((20, 20), dtype=bool)
    blocked[5:10, 5:10] = False  # 1 m across at 0.2 m
    assert (open_free(blocked, 0.2, 0.0, tmp_path) == blocked).all()
    for clearance, needle in ((2.0, "no free place is 2 units wide"), (-1.0, "--clearance")):
        with pytest.raises(InputError, match=needle) as err:
            open_free(blocked, 0.2, clearance, tmp_path / "map.yaml")
        assert "map.yaml" in str(err.value)
    with pytest.raises(InputError, match="--clearance"):
        open_free(blocked, 0.2, float("nan"), tmp_path)


def test_world_import_opens_a_ros_map_when_asked(tmp_path):
    yaml = draw_map(tmp_path)  # a hall of 0.5 m pixels: every free place wider than 2 m
    out = tmp_path / "opened.toml"
    proc = run_cli("world", "import", yaml, "--out", out, "--clearance", "2")
    assert proc.returncode == 0, proc.stderr
    world = load_world(out)
    walls = {tuple(w) for w in world.walls.tolist()}
    assert walls != EXPECTED_WALLS  # the hall's corners are rounded off
    assert "opened to a clearance of 2 m" in out.read_text().splitlines()[0]
    # the hall is still there: from its middle the inner wall's face reads as before
    ray = read_sensors(world, np.array([10.0, 12.0, 0.0]))[0, 2]
    assert ray == pytest.approx(5.0)
    bad = tmp_path / "bad.toml"
    proc = run_cli("world", "import", yaml, "--out", bad, "--clearance", "40")
    assert_one_line_error(proc, "map.yaml", "no free place is 40 units wide")
    assert not bad.exists()


def test_the_campus_figure_marks_a_trap_and_says_from_which_step(tmp_path):
    world = load_world("square")
    db = generate(world, 3_000, seed=0)
    plain = campus_figure(world, db, 1_000)
    assert len(plain.axes[0].texts) == 0
    fig = campus_figure(world, db, 1_000, trapped=2_500)
    ax = fig.axes[0]
    assert [t.get_text().splitlines()[0] for t in ax.texts] == ["trapped from step 2,500"]
    marks = [ln for ln in ax.lines if ln.get_markeredgecolor() == "red"]
    assert len(marks) == 1
    assert np.allclose(np.ravel(marks[0].get_xydata()), db.poses[2_500, :2])
    png = tmp_path / "campus.png"
    save_figure(fig, png, dpi=60)
    assert png.stat().st_size > 5_000
