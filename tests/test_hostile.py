"""A corpus of hostile inputs and faults, one family of the hardening issue at a time: every
one ends in one line and exit 2 (or an InputError from the library), or in the data kept
intact. New file kinds add their inputs here."""

from __future__ import annotations

import errno
import json
import os
import re
import subprocess
import sys

import numpy as np
import pytest
import torch

from conftest import assert_one_line_error, run_cli
from sensorimotor.analysis.probes import position_scores, probe_r2
from sensorimotor.errors import InputError
from sensorimotor.files import atomic_path, folder_lock, strict_json, write_json_atomic
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.train import train
from sensorimotor.sim.core import read_sensors
from sensorimotor.sim.database import Database, generate, load_database, save_database
from sensorimotor.sim.world import load_world


@pytest.fixture(scope="module")
def trained(tmp_path_factory, square_db_path):
    """A finished S run (2 epochs) to be damaged by the tests, copied fresh for each."""
    out = tmp_path_factory.mktemp("trained") / "run"
    train(square_db_path, out, TrainConfig(model="s", max_epochs=2))
    return out


@pytest.fixture
def run(trained, tmp_path):
    import shutil

    dest = tmp_path / "run"
    shutil.copytree(trained, dest)
    return dest


def _resume(cli, run, square_db_path):
    return cli(
        "train", "s", "--data", square_db_path, "--out", run, "--max-epochs", "3", "--resume"
    )


# 1. A trained run can be lost ---------------------------------------------------------------


def test_a_second_process_on_the_same_run_folder_is_refused(cli, run, square_db_path):
    with folder_lock(run, "run folder"):  # as a training process holds it
        proc = _resume(cli, run, square_db_path)
    assert_one_line_error(proc, str(run), "another process is writing this run folder")


def test_resume_without_checkpoint_keeps_the_trained_model(cli, run, square_db_path):
    (run / "checkpoint.pt").unlink()
    before = (run / "model.pt").read_bytes()
    proc = _resume(cli, run, square_db_path)
    assert_one_line_error(proc, "checkpoint.pt is missing", "replace the trained model.pt")
    assert (run / "model.pt").read_bytes() == before


def test_resume_without_config_is_refused(cli, run, square_db_path):
    (run / "config.json").unlink()
    proc = _resume(cli, run, square_db_path)
    assert_one_line_error(proc, "no config.json")
    assert not (run / "config.json").exists()  # nothing written


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (lambda c: c.update(epoch=-5), "epoch must be an integer >= 0"),
        (lambda c: c["optimizer"]["exp_avg"].__setitem__(0, torch.zeros(3)), "exp_avg[0]"),
        (lambda c: c["history"][0].update(val_error="x"), "not a number"),
        (lambda c: c["history"].pop(), "epochs 0..1"),
    ],
)
def test_a_hand_edited_checkpoint_is_refused_before_anything_is_written(
    edit, needle, cli, run, square_db_path
):
    ckpt = torch.load(run / "checkpoint.pt", weights_only=True)
    edit(ckpt)
    with open(run / "checkpoint.pt", "wb") as f:
        torch.save(ckpt, f)
    files = {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()}
    proc = _resume(cli, run, square_db_path)
    assert_one_line_error(proc, "corrupt checkpoint", needle)
    assert {p.name: p.read_bytes() for p in run.iterdir() if p.is_file()} == files


# 2. A wrong number reported as right ----------------------------------------------------------


def test_readings_of_another_world_than_the_meta_names_are_refused(tmp_path):
    db = generate(load_world("square"), 3_000, seed=0)
    meta = {**db.meta, "world": load_world("rooms1").to_dict()}
    poses = db.poses.copy()
    poses[:, :2] = np.clip(poses[:, :2], 1, 49)  # inside rooms1 too; the walls differ
    save_database(Database(db.sensors, db.motors, poses, meta), tmp_path / "lie.npz")
    with pytest.raises(InputError, match="not those of the world its meta names"):
        load_database(tmp_path / "lie.npz")


@pytest.mark.parametrize(
    ("column", "row_value", "needle"),
    [
        ("motors", (0, 1e30), "motors (d)"),
        ("motors", (1, 40.0), "motors (r)"),
        ("poses", (2, 4.0), "poses (heading)"),
    ],
)
def test_motor_commands_and_headings_are_range_checked(column, row_value, needle, tmp_path):
    db = generate(load_world("square"), 500, seed=0)
    arrays = {"sensors": db.sensors, "motors": db.motors.copy(), "poses": db.poses.copy()}
    col, value = row_value
    arrays[column][7, col] = value
    save_database(Database(**arrays, meta=db.meta), tmp_path / "bad.npz")
    with pytest.raises(InputError, match=re.escape(f"{needle} of row 7 is out of range")):
        load_database(tmp_path / "bad.npz")


def test_training_that_diverges_stops_with_one_line_and_keeps_the_last_good_epoch(
    square_db_path, tmp_path
):
    out = tmp_path / "run"
    with pytest.raises(InputError, match="training diverged at epoch"):
        train(square_db_path, out, TrainConfig(model="sm", lr=1e30, max_epochs=3))
    assert not (out / "result.json").exists()
    if (out / "checkpoint.pt").exists():  # an epoch before the divergence was fine
        ckpt = torch.load(out / "checkpoint.pt", weights_only=True)
        assert all(torch.isfinite(t).all() for t in ckpt["model"].values())


def test_a_robot_that_never_moves_is_refused_by_the_analysis_in_one_line(tmp_path, cli):
    world = load_world("square")
    n = 4_000
    rng = np.random.default_rng(0)
    poses = np.tile(np.array([[25.0, 25.0, 0.0]]), (n, 1))
    sensors = read_sensors(world, poses).astype(np.float32)
    motors = np.stack([rng.uniform(0, 1, n), rng.uniform(-0.5, 0.5, n)], 1).astype(np.float32)
    meta = {"world": world.to_dict(), "seed": 0}
    save_database(Database(sensors, motors, poses.astype(np.float32), meta), tmp_path / "still.npz")
    out = tmp_path / "a"
    proc = cli("analyze", "raw", "--data", tmp_path / "still.npz", "--out", out, "--no-svg")
    assert_one_line_error(proc, "still.npz", "1 distinct value(s), fewer than the 20 clusters")
    assert not (out / "metrics.json").exists()


def test_a_target_that_does_not_vary_has_no_r2_rather_than_a_perfect_one():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(400, 10))
    assert np.isnan(probe_r2(z, np.full(400, 25.0)))
    assert probe_r2(z, z[:, 0] * 2 + 1) > 0.99  # a target that varies still scores
    poses = np.stack([np.full(400, 25.0), rng.uniform(0, 50, 400), np.zeros(400)], 1)
    scores = position_scores(z, poses)
    assert scores["r2_x"] is None
    assert scores["r2_cos_heading"] is None
    assert isinstance(scores["r2_y"], float)


def test_json_out_refuses_numbers_that_are_not_numbers(tmp_path):
    with pytest.raises(InputError, match=r"errors.rooms1 is inf"):
        strict_json({"errors": {"square": 0.1, "rooms1": float("inf")}}, tmp_path / "r.json")
    with pytest.raises(InputError, match=r"\[1\] is nan"):
        write_json_atomic(tmp_path / "r.json", [0.0, float("nan")])
    assert not (tmp_path / "r.json").exists()


# 3. Files that are not what they seem -----------------------------------------------------------


def test_an_output_that_is_a_symlink_or_a_device_is_refused_not_replaced(tmp_path, cli):
    target = tmp_path / "precious.npz"
    target.write_bytes(b"keep me")
    link = tmp_path / "link.npz"
    link.symlink_to(target)
    proc = cli("generate", "square", "--steps", "500", "--out", link)
    assert_one_line_error(proc, "symbolic link")
    assert link.is_symlink()
    assert target.read_bytes() == b"keep me"
    proc = cli("generate", "square", "--steps", "500", "--out", "/dev/null")
    assert_one_line_error(proc, "/dev/null", "a device, not a regular file")


def test_a_fifo_or_an_endless_file_as_input_is_refused_without_reading_it(tmp_path, cli):
    fifo = tmp_path / "world.toml"
    os.mkfifo(fifo)
    proc = cli("generate", fifo, "--steps", "500", "--out", tmp_path / "db.npz", timeout=60)
    assert_one_line_error(proc, "a FIFO, not a world file")
    proc = cli("generate", "/dev/zero", "--steps", "500", "--out", tmp_path / "db.npz", timeout=60)
    assert_one_line_error(proc, "/dev/zero", "not a world file")
    fifo_db = tmp_path / "db.npz"
    os.mkfifo(fifo_db)
    with pytest.raises(InputError, match="a FIFO, not a database"):
        load_database(fifo_db)


def _write_on_a_full_disk(path) -> None:
    with atomic_path(path) as tmp:
        tmp.write_text("half")
        raise OSError(errno.ENOSPC, "No space left on device")


def test_a_full_disk_leaves_nothing_half_written(tmp_path):
    path = tmp_path / "out.json"
    with pytest.raises(InputError, match=r"out.json: cannot write \(no space left on the device\)"):
        _write_on_a_full_disk(path)
    assert list(tmp_path.iterdir()) == []


def test_temporaries_of_a_killed_process_are_cleaned_by_the_next_write(tmp_path):
    dead = subprocess.run(
        [sys.executable, "-c", "import os; print(os.getpid())"], capture_output=True, text=True
    )
    pid = int(dead.stdout)
    stale = tmp_path / f".db.npz.{pid}.abc123.tmp.npz"
    stale.write_bytes(b"left by kill -9")
    ours = tmp_path / f".db.npz.{os.getpid()}.xyz789.tmp.npz"  # a live writer's: kept
    ours.write_bytes(b"in progress")
    save_database(generate(load_world("square"), 200, seed=0), tmp_path / "db.npz")
    assert not stale.exists()
    assert ours.exists()


# 4. Tracebacks where one line is promised -----------------------------------------------------


def test_deeply_nested_world_files_and_run_configs_are_one_line(
    tmp_path, cli, run, square_db_path
):
    world = tmp_path / "deep.toml"
    world.write_text("size = 50\nwalls = " + "[" * 5000 + "]" * 5000 + "\n")
    proc = cli("generate", world, "--steps", "500", "--out", tmp_path / "db.npz")
    assert_one_line_error(proc, str(world), "nested")
    (run / "config.json").write_text("[" * 100_000 + "]" * 100_000)
    proc = cli("evaluate", run, "--data", square_db_path)
    assert_one_line_error(proc, "config.json", "nested")


def test_a_name_too_long_for_the_file_system_is_one_line(tmp_path, cli):
    proc = cli("generate", "square", "--steps", "500", "--out", tmp_path / ("w" * 300 + ".npz"))
    assert_one_line_error(proc, "cannot write there")


@pytest.mark.parametrize(
    "sizes", [{"lstm_size": -3}, {"predictor_hidden": 10**9}, {"z_sensors": 2.5}]
)
def test_absurd_model_sizes_in_a_run_config_are_one_line(sizes, cli, run, square_db_path):
    config = json.loads((run / "config.json").read_text())
    config["model"].update(sizes)
    (run / "config.json").write_text(json.dumps(config))
    proc = cli("evaluate", run, "--data", square_db_path)
    assert_one_line_error(proc, "config.json", "corrupt run config", next(iter(sizes)))


# 5. A world the checks accept but cannot run ---------------------------------------------------


def test_finding_a_start_in_a_world_of_many_walls_stays_small(tmp_path):
    """10,000 short walls: the start search measures blocks of points (it once needed 13 GB)."""
    import resource

    rng = np.random.default_rng(0)
    x, y = rng.uniform(5, 995, 10_000), rng.uniform(5, 995, 10_000)
    walls = np.stack([x, y, x + 0.5, y], 1).round(3).tolist()
    path = tmp_path / "many.toml"
    path.write_text(f'name = "many"\nsize = 1000\nwalls = {walls}\n')
    before = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    assert len(load_world(path).walls) == 10_000
    grown_mb = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - before) / 1024
    assert grown_mb < 1_000


def test_a_world_name_too_long_to_name_files_is_refused_by_the_world_file(tmp_path, cli):
    path = tmp_path / "long.toml"
    path.write_text(f'name = "{"w" * 300}"\nsize = 50\nwalls = []\n')
    proc = cli("generate", path, "--steps", "500")
    assert_one_line_error(proc, str(path), "1 to 100 letters")


def test_an_analysis_cut_short_leaves_no_metrics_of_an_earlier_one(
    square_db_path, tmp_path, monkeypatch
):
    from sensorimotor.analysis import analyze as analyze_mod

    out = tmp_path / "a"
    analyze_mod.analyze_files("raw", square_db_path, out, svg=False)
    assert (out / "metrics.json").exists()

    def disk_full(path, obj):
        raise InputError(f"{path}: cannot write (no space left on the device)")

    monkeypatch.setattr(analyze_mod, "write_json_atomic", disk_full)
    with pytest.raises(InputError, match="no space left"):
        analyze_mod.analyze_files("raw", square_db_path, out, svg=False, seed=1)
    assert not (out / "metrics.json").exists()  # the figures alone: an analysis to redo


# the file kinds of the map, the sweep, the world import and RL ------------------------------


@pytest.mark.parametrize("kind", ["sweep", "map_yaml", "map_image"])
def test_the_newer_file_kinds_refuse_a_fifo_and_a_deep_nest_in_one_line(kind, tmp_path, cli):
    from sensorimotor.pipeline.sweep import read_sweep
    from sensorimotor.sim.rosmap import read_image, read_map_yaml

    read = {"sweep": read_sweep, "map_yaml": read_map_yaml, "map_image": read_image}[kind]
    fifo = tmp_path / "input"
    os.mkfifo(fifo)
    with pytest.raises(InputError, match="a FIFO, not a"):
        read(fifo)
    if kind == "sweep":
        deep = tmp_path / "deep.toml"
        deep.write_text('data = "x.npz"\n[space]\nlr = ' + "[" * 5000 + "]" * 5000 + "\n")
        proc = cli("sweep", deep, "--out", tmp_path / "s")
        assert_one_line_error(proc, str(deep), "nested")
        assert not (tmp_path / "s").exists()


def test_an_agent_result_that_is_not_json_is_one_line_and_kept(tmp_path):
    pytest.importorskip("stable_baselines3")
    from sensorimotor.rl.runner import RLConfig, load_agent

    path = tmp_path / "raw__s0" / "result.json"
    path.parent.mkdir()
    path.write_text("[" * 100_000 + "]" * 100_000)
    config = RLConfig("corner", "rooms1", ("raw",), 1, 64)
    with pytest.raises(InputError, match="nested too deeply to be a result of an agent"):
        load_agent(path, config)
    assert path.read_text().startswith("[[[")  # what a user trained is never overwritten


# every command, by structure: the input door, the folder lock, the bounded options -------------
# The commands and their parameters are read from the typer app, so a new command inherits these
# tests: its path options get the hostile files, its output folder the held lock, its numbers
# the hostile values. Commands run in this process (``cli.run``, what ``main`` runs), each case
# under an alarm: one line, exit 2, within 10 s.

PATH_STRINGS = ("world", "worlds", "run")  # str parameters that take a path too (a world file)


def _commands():
    """(name words, click command) of every command of the app, sub-apps included."""
    import typer.main

    from sensorimotor.cli import app

    def walk(cmd, words):
        if hasattr(cmd, "commands"):
            for name, sub in sorted(cmd.commands.items()):
                yield from walk(sub, (*words, name))
        else:
            yield words, cmd

    return list(walk(typer.main.get_command(app), ()))


def _annotation(param):
    return param.type_descriptor.annotation


def _is_path(param) -> bool:
    from pathlib import Path

    ann = _annotation(param)
    return (
        ann is Path
        or ann == list[Path]
        or (ann is str and param.name in PATH_STRINGS)
        or (ann == list[str] and param.name in PATH_STRINGS)
    )


def _writes(cmd) -> dict:
    return getattr(cmd.callback, "__writes__", None)


def _flag(param) -> str | None:
    return param.opts[0] if param.param_type_name == "option" else None


def _outputs(cmd) -> set[str]:
    w = _writes(cmd) or {}
    return {w.get("folder")} - {None} | set(w.get("files", ()))


def _input_cases():
    for words, cmd in _commands():
        for param in cmd.params:
            if _is_path(param) and param.name not in _outputs(cmd):
                for kind in ("fifo", "dev_zero_link", "folder", "missing"):
                    yield pytest.param(
                        words, param.name, kind, id=f"{'-'.join(words)}-{param.name}-{kind}"
                    )


def _in_process(args, limit: float = 10.0) -> tuple[int, str, float]:
    """``sensorimotor ARGS`` run in this process (``run_cli``) within ``limit`` seconds: exit
    status, stderr, seconds."""
    import time

    start = time.perf_counter()
    proc = run_cli(*args, timeout=limit)
    return proc.returncode, proc.stderr, time.perf_counter() - start


def _assert_one_line(rc: int, err: str, *needles: str) -> None:
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert rc == 2, (rc, err)
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.fixture(scope="module")
def baseline(trained, square_db_path, tmp_path_factory):
    """A valid value of each required parameter, by name (a new command's new required
    parameter needs one here), and the outputs in a fresh folder."""
    # what the commands import, imported once: the 10 s are the command's, not the imports'
    import sensorimotor.analysis.map.mapping
    import sensorimotor.learn.train
    import sensorimotor.pipeline.sweep
    import sensorimotor.rl.runner
    import sensorimotor.sim.rosbag  # noqa: F401

    return {
        "model": "s",
        "task": "corner",
        "run": "raw",
        "world": "square",
        "worlds": "square",
        "data": square_db_path,
        "run_dir": trained,
        "run_dirs": trained,
        "bag": tmp_path_factory.mktemp("none") / "no.bag",  # read after --world
        "log": tmp_path_factory.mktemp("none") / "no.rawlog",  # read after --world
        "spec": tmp_path_factory.mktemp("none") / "no.toml",  # read after the lock
    }


SUFFIX = {
    "generate": ".npz",
    "import-bag": ".npz",
    "import-rawlog": ".npz",
    "random": ".toml",
    "import": ".toml",
}


def _argv(words, cmd, values: dict, tmp_path, override: dict) -> list:
    """The command's arguments: ``override``, else the baseline for each required parameter,
    outputs in ``tmp_path``."""
    outputs = _outputs(cmd)
    w = _writes(cmd) or {}
    positional, options = [], []
    for param in cmd.params:
        if param.name in override:
            value = override[param.name]
        elif param.name in outputs:
            folder = param.name == w.get("folder")
            value = tmp_path / ("out" if folder else f"out{SUFFIX.get(words[-1], '.png')}")
            if param.name == "json_out":
                value = tmp_path / "out.json"
        elif param.required:
            assert param.name in values, f"{' '.join(words)}: no baseline for {param.name}"
            value = values[param.name]
        else:
            continue
        flag = _flag(param)
        (options if flag else positional).extend([flag, value] if flag else [value])
    return [*words, *positional, *options]


def _hostile(kind: str, tmp_path):
    path = tmp_path / "hostile" / "input.npz"
    path.parent.mkdir()
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dev_zero_link":
        path.symlink_to("/dev/zero")
    elif kind == "folder":
        path.mkdir()
    return path


@pytest.mark.parametrize(("words", "name", "kind"), list(_input_cases()))
def test_every_path_a_command_reads_goes_through_the_door(words, name, kind, baseline, tmp_path):
    """A FIFO, a link to /dev/zero, a folder and a missing file in each input parameter: one
    line naming it, exit 2, at once, and nothing written."""
    cmd = dict(_commands())[words]
    path = _hostile(kind, tmp_path)
    args = _argv(words, cmd, baseline, tmp_path, {name: path})
    rc, err, _ = _in_process(args)
    _assert_one_line(rc, err, str(path))
    assert not (tmp_path / "out").exists()
    assert not list(tmp_path.glob("out.*"))


def test_every_command_declares_what_it_writes():
    """``@writes`` on every command (``cli.app.writes``), naming each of its output parameters:
    a command that writes a folder locks it, a new command cannot skip the lock unseen."""
    for words, cmd in _commands():
        w = _writes(cmd)
        assert w is not None, f"{' '.join(words)}: no @writes(...) (cli.app.writes)"
        names = {p.name for p in cmd.params}
        assert _outputs(cmd) <= names, (words, w)
        for p in cmd.params:
            if p.name in ("out", "json_out"):
                assert p.name in _outputs(cmd), (words, p.name)


READ_BEFORE_IMPORTS = {  # parameter -> what its refusal says of a missing path
    "data": "database (.npz) not found",
    "fit_data": "database (.npz) not found",
    "run": "run folder not found",
    "run_dir": "run folder not found",
    "run_dirs": "run folder not found",
}


def test_every_database_and_run_a_command_reads_is_refused_before_the_imports(
    baseline, tmp_path
):
    """``@reads`` (``cli.app.reads``) names every database and run-folder parameter of every
    command, and a missing one is refused in one line, exit 2, before torch is imported
    (seconds): run in a fresh interpreter, every such command one after another."""
    cases = []
    for words, cmd in _commands():
        declared = getattr(cmd.callback, "__reads__", {})
        for param in cmd.params:
            if param.name in READ_BEFORE_IMPORTS:
                assert param.name in declared, f"{' '.join(words)}: {param.name} not in @reads"
                missing = str(tmp_path / f"missing_{param.name}")
                args = _argv(words, cmd, baseline, tmp_path, {param.name: missing})
                line = f"error: {missing}: {READ_BEFORE_IMPORTS[param.name]}"
                cases.append(([str(a) for a in args], line))
    assert len(cases) >= 12  # train, evaluate x2, table x2, analyze x3, map x3, plots x2
    script = (
        "import json, sys\n"
        "from sensorimotor.cli import run\n"
        "for argv, _ in json.loads(sys.argv[1]):\n"
        "    assert run(argv) == 2, argv\n"
        "assert 'torch' not in sys.modules, 'torch imported before the refusal'\n"
    )
    proc = subprocess.run(
        [sys.executable, "-c", script, json.dumps(cases)], capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert lines == [line for _, line in cases]
    assert not (tmp_path / "out").exists()


def _folder_writers():
    for words, cmd in _commands():
        if (_writes(cmd) or {}).get("folder"):
            yield pytest.param(words, id="-".join(words))


@pytest.mark.parametrize("words", list(_folder_writers()))
def test_every_folder_a_command_writes_is_locked(words, baseline, tmp_path, capsys):
    """A second process writing the same folder (its lock held, as the first holds it) is
    refused at once with train's refusal, and nothing is written."""
    cmd = dict(_commands())[words]
    out = tmp_path / "out"
    out.mkdir()
    args = _argv(words, cmd, baseline, tmp_path, {})
    with folder_lock(out, "output folder" if words != ("train",) else "run folder"):
        rc, err, _ = _in_process(args)
    _assert_one_line(rc, err, str(out), "another process is writing this", "folder")
    assert list(out.iterdir()) == []  # the lock's file is the holder's, removed with it


def _numeric_cases():
    for words, cmd in _commands():
        for param in cmd.params:
            ann = _annotation(param)
            if ann in (int, float, list[int], list[float]):
                yield pytest.param(words, param, id=f"{'-'.join(words)}-{param.name}")


@pytest.mark.parametrize(("words", "param"), list(_numeric_cases()))
def test_every_numeric_option_is_bounded_stated_and_checked_as_parsed(words, param, capsys):
    """Each number has a least and a greatest value, stated in --help; 0, -1, nan, inf and
    1e9 are accepted within them or refused in one line as the options are parsed, before
    any work (the command is parsed, not run)."""
    import typer.main

    from sensorimotor.cli import app

    assert param.min is not None, f"{words} {param.name}: no least value"
    assert param.max is not None, f"{words} {param.name}: no greatest value"
    group = typer.main.get_command(app)
    cmd = dict(_commands())[words]
    required = [p for p in cmd.params if p.required and p is not param]
    for value in ("0", "-1", "nan", "inf", "1e9", "1000000000"):
        args = [_flag(param), value] if _flag(param) else [value]
        for p in required:  # placeholders: only parsed
            args = ([_flag(p), "x"] if _flag(p) else ["x"]) + args
        sub = group
        for word in words[:-1]:
            sub = sub.commands[word]
        refusal = None
        try:
            ctx = sub.commands[words[-1]].make_context(words[-1], list(args))
        except Exception as err:  # what it is is checked below
            refusal = err
        if refusal is not None:  # refused as parsed: a usage error of one line
            assert hasattr(refusal, "format_message"), (words, value, refusal)
            assert "\n" not in refusal.format_message().strip(), (words, value)
            continue
        got = ctx.params[param.name]
        got = got if not isinstance(got, list | tuple) else got[0]
        assert param.min <= got <= param.max, (words, param.name, value, got)
    rc, _, _ = _in_process([*words, "--help"])
    assert rc == 0


def test_help_states_every_bound(capsys):
    from sensorimotor.cli import run

    capsys.readouterr()
    assert run(["world", "random", "--help"]) == 0
    out = capsys.readouterr().out
    assert "1<=x<=40" in out
    assert "0<=x<=200" in out
    assert run(["sweep", "--help"]) == 0
    assert "[train], [space], [asha]" in " ".join(capsys.readouterr().out.split())


# the second pass's families, each by its case ----------------------------------------------------


def test_a_ros2_bag_folder_whose_files_are_not_regular_is_refused_before_it_is_opened(
    tmp_path, capsys
):
    bag = tmp_path / "bag"
    bag.mkdir()
    (bag / "metadata.yaml").write_text("rosbag2_bagfile_information: {}\n")
    os.mkfifo(bag / "bag_0.db3")
    out = tmp_path / "db.npz"
    rc, err, _ = _in_process(["import-bag", bag, "--out", out])
    _assert_one_line(rc, err, "bag_0.db3", "a FIFO, not a file of a ROS 2 bag")
    (bag / "bag_0.db3").unlink()
    (bag / "bag_0.db3").symlink_to("/dev/zero")
    rc, err, _ = _in_process(["import-bag", bag, "--out", out])
    _assert_one_line(rc, err, "bag_0.db3", "a device")
    assert not out.exists()


def _map_yaml(tmp_path, image: str, origin: str = "[0.0, 0.0, 0.0]"):
    yaml = tmp_path / "map.yaml"
    yaml.write_text(f"image: {image}\nresolution: 0.05\norigin: {origin}\n")
    return yaml


@pytest.mark.parametrize("image", ["fifo", "dev_zero", "folder", "huge_png", "huge_pgm"])
def test_the_image_a_map_names_goes_through_the_door_and_its_pixels_are_bounded(
    image, tmp_path, capsys
):
    import struct
    import zlib

    path = tmp_path / "map.png"
    if image == "fifo":
        os.mkfifo(path)
    elif image == "dev_zero":
        path.symlink_to("/dev/zero")
    elif image == "folder":
        path.mkdir()
    elif image == "huge_png":  # 20,000 x 20,000 announced: refused from the header, not decoded
        ihdr = struct.pack(">IIBBBBB", 20_000, 20_000, 8, 0, 0, 0, 0)
        chunk = b"IHDR" + ihdr
        path.write_bytes(
            b"\x89PNG\r\n\x1a\n"
            + struct.pack(">I", len(ihdr))
            + chunk
            + struct.pack(">I", zlib.crc32(chunk))
        )
    else:
        path = tmp_path / "map.pgm"
        path.write_bytes(b"P5 20000 20000 255\n" + bytes(100))
    out = tmp_path / "w.toml"
    rc, err, seconds = _in_process(
        ["world", "import", _map_yaml(tmp_path, path.name), "--out", out]
    )
    _assert_one_line(rc, err, str(path))
    if image.startswith("huge"):
        assert "pixels" in err
    assert seconds < 5
    assert not out.exists()


def test_a_map_origin_nested_deep_is_one_line(tmp_path, capsys):
    yaml = _map_yaml(tmp_path, "map.pgm", "[" * 5000 + "]" * 5000)
    rc, err, _ = _in_process(["world", "import", yaml, "--out", tmp_path / "w.toml"])
    _assert_one_line(rc, err, "map.yaml:3", "a list within a list")


@pytest.mark.parametrize("kind", ["grid", "random"])
def test_a_sweep_of_a_billion_trials_is_refused_before_its_grid_is_built(
    kind, tmp_path, capsys, square_db_path
):
    spec = tmp_path / "sweep.toml"
    if kind == "grid":  # 1,000^3 combinations
        values = ", ".join(str(2**i) for i in range(1_000))
        body = f"[space]\nbatch_size = [{values}]\nhorizon = [{values}]\npatience = [{values}]\n"
    else:
        body = 'search = "random"\ntrials = 1000000000\n[space]\nlr = [0.1, 0.2]\n'
    spec.write_text(f'data = "{square_db_path}"\n{body}')
    rc, err, seconds = _in_process(["sweep", spec, "--out", tmp_path / "s"])
    _assert_one_line(rc, err, str(spec), "1,000")
    assert seconds < 5
    assert not (tmp_path / "s").exists()


def test_a_sweep_whose_data_is_a_fifo_is_refused_through_the_door(tmp_path, capsys):
    fifo = tmp_path / "data.npz"
    os.mkfifo(fifo)
    spec = tmp_path / "sweep.toml"
    spec.write_text(f'data = "{fifo}"\n[space]\nlr = [0.1, 0.2]\n')
    rc, err, _ = _in_process(["sweep", spec, "--out", tmp_path / "s"])
    _assert_one_line(rc, err, str(fifo), "a FIFO, not a database")


@pytest.mark.parametrize(
    "args",
    [
        ["world", "random", "--name", "square"],
        ["world", "random", "--name", "Rooms2"],
        ["world", "import", "map.yaml", "--name", "rooms1"],
    ],
)
def test_a_built_in_worlds_name_is_refused_up_front(args, tmp_path, capsys):
    out = tmp_path / "w.toml"
    rc, err, _ = _in_process([*args, "--out", out])
    _assert_one_line(rc, err, "the name of a built-in world")
    assert not out.exists()


def test_an_rl_out_that_is_a_file_or_a_read_only_folder_is_one_line(tmp_path, capsys):
    pytest.importorskip("stable_baselines3")
    taken = tmp_path / "taken"
    taken.write_text("mine")
    args = ["rl", "corner", "--features", "pose", "--seeds", "1", "--steps", "64"]
    rc, err, _ = _in_process([*args, "--out", taken])
    _assert_one_line(rc, err, str(taken), "not a folder")
    assert taken.read_text() == "mine"
    if os.geteuid() != 0:  # root writes anywhere
        locked = tmp_path / "ro"
        locked.mkdir(mode=0o500)
        rc, err, _ = _in_process([*args, "--out", locked])
        _assert_one_line(rc, err, str(locked))


def test_angles_far_out_wrap_at_once_and_near_ones_keep_their_bits():
    import math

    from sensorimotor.sim.core import wrap_angle

    for a in (1e300, -1e300, 1e18, 123456.789):
        assert -math.pi < wrap_angle(a) <= math.pi
    assert math.isnan(wrap_angle(math.inf))
    for a in (3.5, -3.5, 7.0, -7.0, 9.42, math.pi, -math.pi):
        want = a
        while want > math.pi:
            want -= 2 * math.pi
        while want <= -math.pi:
            want += 2 * math.pi
        assert wrap_angle(a) == want  # the same bits as the loop it replaces


def test_a_simulated_database_whose_motors_do_not_move_it_is_refused(tmp_path, capsys):
    db = generate(load_world("square"), 2_000, seed=0)
    motors = db.motors.copy()
    motors[:, 0] = -5.0  # every forward command -5: the poses moved forward
    save_database(Database(db.sensors, motors, db.poses, db.meta), tmp_path / "lie.npz")
    rc, err, _ = _in_process(
        ["analyze", "raw", "--data", tmp_path / "lie.npz", "--out", tmp_path / "a"]
    )
    _assert_one_line(rc, err, "lie.npz", "its motors do not move it")
    save_database(db, tmp_path / "true.npz")
    assert len(load_database(tmp_path / "true.npz")) == 2_000


def test_a_recording_of_impossible_odometry_and_commands_drops_and_counts_them(tmp_path):
    pytest.importorskip("rosbags")
    import math

    from sensorimotor.sim.bagcodec import unit_yaw, write_bag
    from sensorimotor.sim.rosbag import BagTopics, import_bag

    assert math.isnan(unit_yaw(0.0, 0.0, 0.0, 0.0))  # (0, 0, 0, 0): no heading
    db = generate(load_world("square"), 600, seed=1)
    poses, motors = db.poses.astype(np.float64), db.motors.astype(np.float64)
    poses[100, 2] = np.nan  # a quaternion of NaN: not of unit norm
    poses[200, 0] = 1e300  # finite in float64, infinite in float32
    poses[300, 0] += 1e6  # a jump there and back in a tenth of a second
    motors[400, 0] = 1e30  # /cmd_vel of 1e30 m/s
    bag = write_bag(Database(db.sensors, motors, poses, db.meta), tmp_path / "bad", cmd=True)
    got = import_bag(bag, BagTopics(cmd="/cmd_vel"))
    c = got.meta["source"]["counts"]
    assert (c["odom_bad_quaternion"], c["odom_not_finite"], c["odom_jumps"]) == (1, 1, 1)
    assert c["rows_too_fast"] == 1
    assert np.isfinite(got.poses).all()
    assert np.abs(got.motors[:, 0]).max() <= 1.0 + 1e-6
    assert np.abs(got.poses[:, :2]).max() <= 50


def test_the_records_a_stage_reads_back_go_through_the_door(tmp_path):
    """A cache's key, a trial's result: none or unparsable is made again; a FIFO in its place
    is refused, never read (it would block for ever)."""
    from sensorimotor.files import read_json_if_any
    from sensorimotor.jobs.cache import read_key

    assert read_json_if_any(tmp_path / "none.json", "stage record") is None
    (tmp_path / "bad.json").write_text("{" * 10)
    assert read_key(tmp_path / "bad.json") is None
    (tmp_path / "ok.json").write_text('{"key": "abc"}')
    assert read_key(tmp_path / "ok.json") == "abc"
    os.mkfifo(tmp_path / "fifo.json")
    with pytest.raises(InputError, match="a FIFO, not a stage record"):
        read_key(tmp_path / "fifo.json")
