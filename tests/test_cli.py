"""The real command line (``python -m sensorimotor``) in a subprocess: ``generate`` writes a
database, and every bad input is one line on stderr, exit code 2, and no file left behind."""

from __future__ import annotations

import importlib
import os
import stat

import numpy as np
import pytest

from conftest import assert_one_line_error, run_cli
from sensorimotor.sim.database import generate, load_database
from sensorimotor.sim.world import load_world
from sim.test_world import BAD_WORLD_FILES

# the world-file problems of DESIGN.md, each through the real command
CLI_BAD_WORLDS = [
    "not_toml",
    "empty",
    "unknown_key",
    "missing_size",
    "missing_walls",
    "size_zero",
    "size_nan",
    "wall_inf",
    "wall_three",
    "wall_outside",
    "wall_zero_length",
    "no_free_start",
]


def test_generate_writes_a_loadable_database(cli, tmp_path):
    out = tmp_path / "db.npz"
    proc = cli("generate", "rooms1", "--steps", "1500", "--seed", "3", "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "Traceback" not in proc.stderr
    assert f"wrote {out}" in proc.stderr
    db = load_database(out)
    assert len(db) == 1_500
    assert db.meta["seed"] == 3
    assert db.meta["steps"] == 1_500
    assert db.meta["world"]["name"] == "rooms1"
    # the same bytes as the library's generate with that seed
    assert db.sensors.tobytes() == generate(load_world("rooms1"), 1_500, seed=3).sensors.tobytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["db.npz"]  # no temporary left over
    mode = stat.S_IMODE(out.stat().st_mode)
    assert mode & 0o044 == 0o044 & ~_umask(), oct(mode)  # readable as any new file


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def test_generate_default_name_and_world_file(cli, tmp_path):
    world = tmp_path / "lab.toml"
    world.write_text("size = [30, 20]\nwalls = [[10, 0, 20, 12.5]]\n")
    proc = cli("generate", world, "--steps", "300", "--seed", "8", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    db = load_database(tmp_path / "lab_s8.npz")
    assert len(db) == 300
    assert db.meta["world"] == {"name": "lab", "size": [30.0, 20.0], "walls": [[10, 0, 20, 12.5]]}
    assert db.poses[:, 0].max() < 30
    assert db.poses[:, 1].max() < 20


def test_generate_with_noise(cli, tmp_path):
    out = tmp_path / "noisy.npz"
    proc = cli("generate", "square", "--steps", "400", "--noise", "0.1", "--out", out)
    assert proc.returncode == 0, proc.stderr
    db = load_database(out)
    assert db.meta["noise_std"] == 0.1
    assert not np.array_equal(db.sensors, generate(load_world("square"), 400, seed=0).sensors)


def test_help(cli):
    proc = cli("--help")
    assert proc.returncode == 0
    assert "generate" in proc.stdout
    proc = cli("generate", "--help")
    assert proc.returncode == 0, proc.stderr
    for option in ("--steps", "--seed", "--out", "--noise", "square, rooms1, rooms2"):
        assert option in proc.stdout, option


def test_reproduce_help_states_what_each_scale_sets(cli):
    from sensorimotor.pipeline.paper import SCALES

    text = " ".join(cli("reproduce", "--help").stdout.split())  # unwrapped
    text = text.replace("│ ", "").replace(" │", "")
    for sc in SCALES.values():
        assert f"{sc.name}: " in text
        assert f"{sc.steps:,} steps" in text or f"{sc.steps:,}-step" in text, sc.name
        assert f"{sc.seeds} seed" in text, sc.name
    for kind, cap in SCALES["quick"].max_epochs.items():
        assert str(cap) in text, kind


def test_version(cli):
    proc = cli("--version")
    assert proc.returncode == 0
    assert proc.stdout.startswith("sensorimotor ")


# ---------------------------------------------------------------- bad input


def assert_nothing_written(folder, *keep):
    """Only the files the test made itself remain (no database, no temporary file)."""
    left = sorted(p.name for p in folder.iterdir())
    assert left == sorted(keep), left


@pytest.mark.parametrize("case", CLI_BAD_WORLDS)
def test_bad_world_file(cli, tmp_path, case):
    text, problem = BAD_WORLD_FILES[case]
    world = tmp_path / f"{case}.toml"
    world.write_text(text)
    proc = cli("generate", world, "--steps", "100", "--out", tmp_path / "db.npz", cwd=tmp_path)
    assert_one_line_error(proc, str(world), problem)
    assert_nothing_written(tmp_path, world.name)


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--steps", "0"], ["'--steps'", "greater than or equal to 1"]),
        (["--steps", "-5"], ["'--steps'", "greater than or equal to 1"]),
        (["--steps", "10000000000000"], ["'--steps'", "less than or equal to 100000000"]),
        (["--noise", "-0.5"], ["'--noise'", "greater than or equal to 0"]),
        (["--noise", "nan"], ["'--noise'", "Input should be"]),
    ],
)
def test_bad_option(cli, tmp_path, args, needles):
    proc = cli("generate", "square", *args, "--out", tmp_path / "db.npz", cwd=tmp_path)
    assert_one_line_error(proc, *needles)
    assert_nothing_written(tmp_path)


def test_more_steps_than_memory(cli, tmp_path):
    proc = cli(
        "generate", "square", "--steps", "100000000", "--rays", "1024", "--out", tmp_path / "db.npz"
    )
    assert_one_line_error(proc, "--steps 100,000,000", "memory")
    assert_nothing_written(tmp_path)


def test_unknown_world_name_lists_the_known_ones(cli, tmp_path):
    proc = cli("generate", "mars", "--steps", "10", cwd=tmp_path)
    assert_one_line_error(proc, "'mars'", "square", "rooms1", "rooms2")
    assert_nothing_written(tmp_path)


def test_missing_world_file(cli, tmp_path):
    proc = cli("generate", tmp_path / "nope.toml", "--steps", "10", cwd=tmp_path)
    assert_one_line_error(proc, "nope.toml", "not found")
    assert_nothing_written(tmp_path)


def test_output_folder_does_not_exist(cli, tmp_path):
    out = tmp_path / "no" / "such" / "db.npz"
    proc = cli("generate", "square", "--steps", "10", "--out", out, cwd=tmp_path)
    assert_one_line_error(proc, str(out), "does not exist")
    assert_nothing_written(tmp_path)


def test_output_under_a_regular_file(cli, tmp_path):
    (tmp_path / "somefile.txt").write_text("x")
    out = tmp_path / "somefile.txt" / "out.npz"
    proc = cli("generate", "square", "--steps", "10", "--out", out, cwd=tmp_path)
    assert_one_line_error(proc, str(out), "not a folder")
    assert_nothing_written(tmp_path, "somefile.txt")


def test_output_is_a_folder(cli, tmp_path):
    (tmp_path / "dir.npz").mkdir()
    proc = cli("generate", "square", "--steps", "10", "--out", tmp_path / "dir.npz")
    assert_one_line_error(proc, "dir.npz", "is a folder")
    assert_nothing_written(tmp_path / "dir.npz")


@pytest.mark.skipif(os.geteuid() == 0, reason="root writes into a read-only folder anyway")
def test_output_folder_not_writable(cli, tmp_path):
    folder = tmp_path / "ro"
    folder.mkdir()
    folder.chmod(0o555)
    try:
        proc = cli("generate", "square", "--steps", "10", "--out", folder / "db.npz")
        assert_one_line_error(proc, "db.npz", "not writable")
        assert_nothing_written(folder)
    finally:
        folder.chmod(0o755)


def test_progress_into_a_log_prints_the_first_line_then_at_most_every_log_every_s_and_the_last(
    monkeypatch, capsys
):
    cli_app = importlib.import_module("sensorimotor.cli.app")  # the module, not the Typer app

    clock = iter([0.0, 1.0, 2.0, 11.0, 12.0])  # seconds at each update
    monkeypatch.setattr(cli_app.time, "monotonic", lambda: next(clock, 99.0))
    monkeypatch.setattr(cli_app, "err_console", cli_app.Console(stderr=True, force_terminal=False))
    with cli_app.progress("work", total=5) as update:
        for i in range(1, 6):
            update(i, f"item {i}")
    lines = capsys.readouterr().err.splitlines()
    assert lines == ["work 1 of 5: item 1", "work 4 of 5: item 4", "work 5 of 5: item 5"]


def test_reproduce_help_names_every_registered_experiment():
    from sensorimotor.experiments import EXPERIMENTS

    proc = run_cli("reproduce", "--help")
    assert proc.returncode == 0
    text = " ".join(proc.stdout.split())
    for name in EXPERIMENTS:
        assert f"{name} (" in text, name


def test_generates_default_name_says_what_differs_from_the_papers_recording():
    from sensorimotor.cli.data import default_name

    paper = ("rooms1", 0, 5, 1.2, 10.0, 0.0, "absolute", 0.0, 0.0)
    assert default_name(*paper).name == "rooms1_s0.npz"
    noisy = default_name("rooms1", 0, 64, 6.283185, 8.0, 0.05, "relative", 0.01, 0.02)
    assert noisy.name == "rooms1_s0_rays64_fov6.28318_range8_noise0.05rel_dropout0.01_motornoise0.02.npz"
    assert default_name("rooms1", 0, 5, 1.2, 10.0, 0.05, "absolute", 0.0, 0.0) != default_name(*paper)
    assert default_name(*paper, "paper").name == "rooms1_s0.npz"
    assert default_name(*paper, "smooth").name == "rooms1_s0_smooth.npz"
    smooth_rays = default_name("rooms1", 0, 16, 1.2, 10.0, 0.0, "absolute", 0.0, 0.0, "smooth")
    assert smooth_rays.name == "rooms1_s0_rays16_smooth.npz"


def test_every_commands_help_renders_every_option_help_whole():
    """No help text is eaten as markup ("[train]" is a TOML table), for every command."""
    import typer.main
    from typer.testing import CliRunner

    from sensorimotor.cli import app

    def walk(command, path=()):
        subs = getattr(command, "commands", {})
        yield path, command
        for name, sub in subs.items():
            yield from walk(sub, (*path, name))

    runner = CliRunner()
    seen = 0
    for path, command in walk(typer.main.get_command(app)):
        result = runner.invoke(app, [*path, "--help"], terminal_width=400)
        assert result.exit_code == 0, (path, result.output)
        text = " ".join(result.output.split())
        for param in command.params:
            words = " ".join((getattr(param, "help", None) or "").split())
            assert words in text, (path, param.name, words)
            seen += "[" in words
    assert seen >= 1  # the sweep file's "[train], [space], [asha]" among them
