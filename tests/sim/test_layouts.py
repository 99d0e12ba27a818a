"""Sensor layouts of any size and noisy sensory streams: the paper's layout keeps its bytes, any
other is recorded, trained on and analysed; the noises are what they say and are seeded."""

from __future__ import annotations

import hashlib
import json
import math

import numpy as np
import pytest

import reference_sim as ref
from conftest import assert_one_line_error, run_cli
from sensorimotor.errors import InputError
from sensorimotor.sim import core as sim
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.sim.world import load_world, world_from_dict

# sha256 of sensors, motors, poses and meta (less its version) of `generate(WORLD, 3000, 7,
# noise_std=NOISE)`, computed with the code of main before layouts of any size existed
# (commit 972dc53): the paper's layout must give the same bytes.
BEFORE = {
    ("square", 0.0): "f48d443ea023144b75b12c018a45782f3ba787e21f4f2738fead1628bf5b0a37",
    ("square", 0.1): "fa19be23fb2b43b759b5f4ea0e3b446f76455332c37a78b0a1b5f2492cd175aa",
    ("rooms2", 0.0): "cad1e7e43528bd54174184e28c7744ad6b05be4596d06802a936189ccd5cdae8",
    ("rooms2", 0.1): "360c942626f64e55b86d5a52193d130a37cea5bb3321784ad4baca803f9295ac",
}
OBLIQUE = world_from_dict(
    {
        "name": "oblique",
        "size": [50, 40],
        "walls": [[5, 5, 20, 30], [49.5, 0.5, 30, 35], [10, 38, 45, 36], [25, 3, 40, 18]],
    }
)
FULL = 2 * math.pi


def digest(db) -> str:
    h = hashlib.sha256()
    for a in (db.sensors, db.motors, db.poses):
        h.update(a.tobytes())
    h.update(json.dumps({k: v for k, v in db.meta.items() if k != "version"}).encode())
    return h.hexdigest()


@pytest.mark.parametrize(("name", "noise"), BEFORE)
def test_the_paper_layout_gives_the_bytes_of_before(name, noise):
    layout = sim.spread_layout()  # what `generate` builds from its defaults
    assert layout == sim.DEFAULT_LAYOUT
    assert (
        digest(generate(load_world(name), 3000, 7, layout, noise_std=noise)) == BEFORE[name, noise]
    )


def test_spread_layouts():
    assert sim.spread_layout(5, 1.2).angles == (-0.6, -0.3, 0.0, 0.3, 0.6)  # to the bit
    full = np.array(sim.spread_layout(64, FULL).angles)
    assert full[0] == pytest.approx(-math.pi, abs=1e-11)
    assert 0.0 in full
    assert len(full) == 64
    np.testing.assert_allclose(np.diff(full), FULL / 64, atol=1e-11)
    four = sim.spread_layout(4, 1.0, 3.0)
    assert four.angles[0] == -0.5
    assert four.angles[-1] == 0.5
    assert 0.0 not in four.angles
    assert four.max_range == 3.0
    assert len(four.angles) == 4
    assert sim.spread_layout(1, 0.0).angles == (0.0,)
    assert sim.spread_layout(1024, FULL).describe().startswith("1024 rays over [-3.14159")


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        ((0, 1.0, 10.0), "--rays must be an integer from 1 to 1,024, got 0"),
        ((5000, 1.0, 10.0), "got 5000"),
        ((5, 7.0, 10.0), "--fov must be from 0 to 2 pi"),
        ((5, 0.0, 10.0), "--fov must be positive for 5 rays"),
        ((5, 1.0, -1.0), "--range must be a positive number"),
        ((5, 1.0, math.inf), "--range must be a positive number"),
    ],
)
def test_bad_layouts_are_refused(args, needle):
    with pytest.raises(InputError, match=re_escape(needle)):
        sim.spread_layout(*args)


def re_escape(text: str) -> str:
    import re

    return re.escape(text)


@pytest.mark.parametrize(
    ("option", "needle"),
    [
        (["--rays", "5000"], "'--rays': Input should be less than or equal to 1024"),
        (["--fov", "6.3"], "'--fov': Input should be less than or equal to 6.2832"),
        (["--fov", "6.2832"], "--fov must be from 0 to 2 pi"),  # the bound, then exactly
        (["--dropout", "1.5"], "'--dropout': Input should be less than or equal to 1"),
    ],
)
def test_generate_refuses_a_bad_option_in_one_line_writing_nothing(tmp_path, option, needle):
    out = tmp_path / "db.npz"
    proc = run_cli("generate", "square", "--steps", "100", "--out", out, *option)
    assert_one_line_error(proc, needle)
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        ((-0.1, "absolute", 0.0, 0.0), "--noise must be a non-negative number"),
        ((0.0, "absolute", 0.0, math.inf), "--motor-noise must be a non-negative number"),
        ((0.0, "absolute", -0.1, 0.0), "--dropout must be a probability"),
        ((0.0, "gaussian", 0.0, 0.0), "--noise-kind must be one of absolute, relative"),
    ],
)
def test_bad_noises_are_refused(args, needle):
    with pytest.raises(InputError, match=re_escape(needle)):
        sim.check_noise(*args)


@pytest.mark.parametrize(("rays", "fov"), [(64, FULL), (4, 1.0), (1, 0.0), (16, 3.0)])
def test_every_layout_walks_the_paper_path_and_records_its_own_rays(rays, fov):
    """The behaviour reads the paper's 5 rays whatever is recorded: a layout without a ray
    straight ahead (4 rays) walks the paper's path, which never crosses a wall."""
    w = load_world("rooms2")
    paper = sim.rollout(w, 3000, seed=5)
    layout = sim.spread_layout(rays, fov, 7.0)
    run = sim.rollout(w, 3000, seed=5, layout=layout)
    assert run.sensors.shape == (3000, rays)
    np.testing.assert_array_equal(run.poses, paper.poses)
    np.testing.assert_array_equal(run.motors, paper.motors)
    # the rollout turns its rays by the angle-sum identities: equal to rounding
    np.testing.assert_allclose(run.sensors, sim.read_sensors(w, run.poses, layout), atol=1e-9)
    assert run.sensors.max() == 7.0
    assert run.sensors.min() < 1.0


def test_new_kernel_features_match_the_reference():
    """Another layout, relative noise, dropouts and motor noise, step by step against the
    plain-Python oracle (tests/reference_sim.py)."""
    from test_core import run_kernel

    w = OBLIQUE
    steps = 1500
    rng = np.random.default_rng(11)
    start = sim.sample_start(w, rng)
    uniforms = rng.random((steps, 2))
    angles = np.array(sim.spread_layout(8, 2.0, 6.0).angles)
    noise = rng.normal(0.0, 0.2, (steps, 8))
    dropped = rng.random((steps, 8)) < 0.1
    motor = rng.normal(0.0, 0.3, (steps, 2))
    out = np.empty((steps, 8)), np.empty((steps, 2)), np.empty((steps, 3))
    run_kernel(w, angles, start, uniforms, noise, *out, True, dropped, motor, max_range=6.0)
    expected = ref.rollout(
        [tuple(s) for s in w.segments.tolist()], angles.tolist(), 6.0, start, uniforms.tolist(),
        noise.tolist(), True, dropped.tolist(), motor.tolist(),
    )  # fmt: skip
    for got, want in zip(out, expected, strict=True):
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
    assert (out[0][dropped] == 6.0).all()


def test_noises_are_what_they_say_and_recorded_in_the_meta():
    w = load_world("square")
    db = generate(w, 20_000, 3, sim.spread_layout(16, 2.0), 0.1, None, "relative", 0.2, 0.05)
    true = sim.read_sensors(w, db.poses.astype(np.float64), db.layout)
    kept = (db.sensors < 10.0) & (true > 2) & (true < 5)  # not dropped, not clipped
    ratio = db.sensors[kept] / true[kept] - 1.0
    assert ratio.std() == pytest.approx(0.1, rel=0.05)  # relative: 10 % of the reading
    dropped = (db.sensors == 10.0) & (true < 9)
    assert dropped.sum() / (true < 9).sum() == pytest.approx(0.2, abs=0.02)
    assert {k: db.meta[k] for k in ("noise_std", "noise_kind", "dropout", "motor_noise_std")} == {
        "noise_std": 0.1, "noise_kind": "relative", "dropout": 0.2, "motor_noise_std": 0.05
    }  # fmt: skip
    # motor noise: the executed step is not the recorded one, and never reaches the wall ahead
    p = db.poses.astype(np.float64)
    moved = np.hypot(np.diff(p[:, 0]), np.diff(p[:, 1]))
    assert np.abs(moved - db.motors[:-1, 0]).max() > 0.05
    ahead = sim.read_sensors(w, p[:-1], sim.SensorLayout((0.0,), 100.0))[:, 0]
    assert (moved < ahead).all()
    # the same seed gives the same bytes; without motor noise the paper's path
    again = generate(w, 20_000, 3, sim.spread_layout(16, 2.0), 0.1, None, "relative", 0.2, 0.05)
    assert digest(again) == digest(db)
    plain = generate(w, 20_000, 3, sim.spread_layout(16, 2.0), 0.1, None, "relative", 0.2)
    np.testing.assert_array_equal(plain.poses, generate(w, 20_000, 3).poses)
    assert "dropout" not in generate(w, 10, 3).meta


def test_databases_of_any_layout_load_and_a_wrong_one_is_refused(tmp_path):
    db = generate(load_world("square"), 500, 0, sim.spread_layout(64, FULL))
    assert load_database(save_database(db, tmp_path / "a.npz")).sensors.shape == (500, 64)
    from dataclasses import replace

    no_layout = {k: v for k, v in db.meta.items() if k != "sensor_layout"}
    save_database(replace(db, meta=no_layout), tmp_path / "b.npz")
    with pytest.raises(InputError, match=r"64 sensors but no meta\.sensor_layout"):
        load_database(tmp_path / "b.npz")
    short = {**db.meta, "sensor_layout": {"angles": [0.0], "max_range": 10.0}}
    save_database(replace(db, meta=short), tmp_path / "c.npz")
    with pytest.raises(InputError, match="must give 64 finite angles"):
        load_database(tmp_path / "c.npz")


@pytest.mark.slow
def test_a_64_ray_database_trains_and_analyses_from_the_command_line(tmp_path):
    def cli(*args):
        return run_cli(*args, cwd=tmp_path)

    fov = repr(FULL)
    assert (
        cli(
            "generate", "rooms1", "--steps", 2500, "--rays", 64, "--fov", fov, "--out", "d.npz"
        ).returncode
        == 0
    )
    proc = cli("train", "s", "--data", "d.npz", "--out", "run", "--max-epochs", 1)
    assert proc.returncode == 0, proc.stderr
    config = json.loads((tmp_path / "run" / "config.json").read_text())
    assert config["model"]["n_sensors"] == 64
    assert len(config["data"]["sensor_layout"]["angles"]) == 64
    proc = cli("analyze", "run", "--data", "d.npz", "--out", "an", "--no-svg")
    assert proc.returncode == 0, proc.stderr
    analysis = json.loads((tmp_path / "an" / "metrics.json").read_text())["analysis"]
    assert analysis["dim"] == 10
    # the events follow the layout: nothing in view = all 64 readings at the range
    test = load_database(tmp_path / "d.npz").take("test")
    assert analysis["n_steps"] == len(test) == 250
    nothing = (test.sensors >= 10.0 * (1 - 1e-6)).all(axis=1)
    assert analysis["events"]["nothing"]["count"] == nothing.sum()
    # a database of the paper's layout given to the 64-ray model: one line naming both
    assert cli("generate", "rooms1", "--steps", 500, "--out", "p.npz").returncode == 0
    proc = cli("evaluate", "run", "--data", "p.npz")
    assert_one_line_error(
        proc, "recorded with 5 rays over [-0.6, 0.6] rad", "trained on 64 rays over [-3.14159"
    )


def test_the_environment_takes_the_same_options():
    from sensorimotor.envs.laser_world import LaserWorldEnv

    env = LaserWorldEnv("square", rays=32, fov=FULL, max_range=5.0, dropout=0.5, noise=0.1,
                        noise_kind="relative", motor_noise=0.1)  # fmt: skip
    obs, info = env.reset(seed=0)
    assert obs.shape == (32,)
    assert env.observation_space.shape == (32,)
    assert info["paper_readings"].shape == (5,)
    assert (obs == 5.0).sum() > 5  # dropouts read the range
    with pytest.raises(InputError, match="--rays must be"):
        LaserWorldEnv("square", rays=0)
    with pytest.raises(InputError, match="--noise must be"):
        LaserWorldEnv("square", noise=-1.0)
