"""``reproduce --experiment walls``: Table I's Square models on wall layouts that fit the paper's
sentences, each family one cached job, a section per family."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

import sensorimotor
from sensorimotor import experiments as ex
from sensorimotor.errors import InputError
from sensorimotor.experiments import walls
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.report.blocks import to_markdown
from sensorimotor.sim.world import load_world, point_segment_distance


@pytest.mark.parametrize(("world", "horizontal", "vertical"), [("rooms1", 1, 1), ("rooms2", 1, 3)])
def test_layout_families_fit_the_papers_sentences(world, horizontal, vertical):
    family = walls.wall_family(world, 8, seed=1)
    assert family[0].walls.tolist() == load_world(world).walls.tolist()  # the built-in first
    assert len({tuple(map(tuple, w.walls.tolist())) for w in family}) == 8  # all distinct
    for w in family:
        segs = w.walls
        assert ((segs[:, 1] == segs[:, 3]) & (segs[:, 0] != segs[:, 2])).sum() == horizontal
        assert ((segs[:, 0] == segs[:, 2]) & (segs[:, 1] != segs[:, 3])).sum() == vertical
        # every wall hangs from another: its end lies on an outer or another wall
        for k, (x0, y0, x1, y1) in enumerate(segs):
            others = np.delete(w.segments, 4 + k, axis=0)
            d = point_segment_distance(others, np.array([x0, x1]), np.array([y0, y1]))
            assert d.min() < 1e-9


# the old Rooms1 family's layout 7: a sealed 15 x 25 box
SEALED = [[15.0, 25.0, 15.0, 50.0], [0.0, 25.0, 15.0, 25.0]]


def test_a_sealed_layout_is_refused_by_the_family(monkeypatch):
    from sensorimotor.sim.floorplan import free_regions, reachable
    from sensorimotor.sim.world import world_from_dict

    sealed = world_from_dict({"name": "x", "size": 50.0, "walls": SEALED})
    assert free_regions(sealed) == 2
    assert not reachable(sealed)
    assert reachable(load_world("rooms1"))
    # a family whose draw offers the sealed layout first, then an open one: only the open one kept
    opened = [[15.0, 25.0, 15.0, 50.0], [0.0, 25.0, 8.0, 25.0]]  # a 7-wide opening
    offers = iter([SEALED, SEALED, opened])
    monkeypatch.setitem(walls.DRAW, "rooms1", lambda rng: next(offers))
    family = walls.wall_family("rooms1", 2)
    assert [w.walls.tolist() for w in family][1] == opened


@pytest.mark.parametrize("world", ["rooms1", "rooms2"])
def test_every_layout_of_a_family_is_reachable_and_the_seed_fixes_the_family(world):
    from sensorimotor.sim.floorplan import reachable

    family = walls.wall_family(world)
    assert len(family) == walls.FAMILY_SIZE == 20
    assert all(reachable(w) for w in family)
    assert SEALED not in [w.walls.tolist() for w in family]
    again = walls.wall_family(world, seed=walls.FAMILY_SEED)
    assert [w.walls.tolist() for w in again] == [w.walls.tolist() for w in family]
    other = walls.wall_family(world, seed=walls.FAMILY_SEED + 1)
    assert [w.walls.tolist() for w in other][1:] != [w.walls.tolist() for w in family][1:]


def _context(tmp_path, run, jobs_seen: list):
    rep = SimpleNamespace(
        out=tmp_path,
        worlds=("square",),
        runs=[("square", "s", 0)],
        run_dir=lambda world, model, seed: run,
        scale=SimpleNamespace(name="smoke", steps=1500),
    )

    def runner(jobs, workers, progress):
        jobs_seen.extend(job.name for job in jobs)
        return run_jobs(jobs, workers, progress)

    return ex.Context(rep, "walls", runner, 1, None, print)


def test_the_walls_experiment_tests_the_square_runs_on_each_family_and_keeps_its_result(
    square_db_path, tmp_path
):
    run = tmp_path / "runs" / "square__s__s0"
    sensorimotor.train(square_db_path, run, sensorimotor.TrainConfig(model="s", max_epochs=1))
    seen: list[str] = []
    found = ex.run_experiment(_context(tmp_path, run, seen))
    assert seen == ["walls rooms1", "walls rooms2"]
    json.dumps(found, allow_nan=False)  # strict JSON
    layouts, _ = walls.FAMILIES["smoke"]
    for world in ("rooms1", "rooms2"):
        cell = found["worlds"][world]["cells"]["s"]
        assert len(found["worlds"][world]["layouts"]) == layouts
        assert len(cell["per_layout"]) == layouts
        assert cell["min"] <= cell["builtin"] <= cell["max"]
        assert cell["paper"] == pytest.approx({"rooms1": 0.04299, "rooms2": 0.07290}[world])
        assert [lay["reachable"] for lay in found["worlds"][world]["layouts"]] == [True] * layouts
        low, high = cell["band_5_95"]
        assert cell["min"] <= low <= high <= cell["max"]
        assert 0.0 <= found["worlds"][world]["share_within"] <= 1.0
    again: list[str] = []
    assert ex.run_experiment(_context(tmp_path, run, again)) == found
    assert again == []  # kept: nothing evaluated twice
    md = to_markdown(ex.sections(None, {"walls": found}), tmp_path)
    assert "wall layout" in md
    assert "| s |" in md
    assert f"Reachable layouts (every free place reachable from every other): {layouts} of" in md
    assert "5-95 % band:" in md


def test_the_walls_experiment_needs_square(tmp_path):
    ctx = _context(tmp_path, tmp_path, [])
    ctx = ex.Context(SimpleNamespace(**{**vars(ctx.rep), "worlds": ("rooms1",)}), "walls",
                     ctx.run_jobs, 1, None, print)  # fmt: skip
    with pytest.raises(InputError, match="add square to --worlds"):
        walls.run(ctx)
