"""`sensorimotor sweep` without Ray: the sweep file read and checked, seeded random trials, a
local sweep killed and resumed, its table, figure and best command; Ray asked for but missing.
The sweep on Ray is in test_ray.py."""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image as mpimg
import pytest

from conftest import assert_one_line_error
from sensorimotor.errors import InputError
from sensorimotor.learn.runs import parse_settings
from sensorimotor.pipeline.sweep import read_sweep, run_sweep
from sensorimotor.sim.database import generate, save_database
from sensorimotor.sim.world import load_world

GRID = """data = "sq.npz"
[train]
model = "s"
max_epochs = 3
[space]
lr = [3e-4, 1e-3, 3e-3, 1e-2]
batch_size = [32, 64]
"""


@pytest.fixture(scope="module")
def folder(tmp_path_factory) -> Path:
    """A folder with a 5,000-step Square database and the 8-trial grid sweep beside it."""
    path = tmp_path_factory.mktemp("sweep")
    save_database(generate(load_world("square"), 5_000, seed=0), path / "sq.npz")
    (path / "grid.toml").write_text(GRID)
    return path


def _write(folder: Path, text: str, name: str = "bad.toml") -> Path:
    (folder / name).write_text(text)
    return folder / name


@pytest.mark.parametrize(
    ("text", "needle"),
    [
        ("data = [", "not valid TOML"),
        ('data = "sq.npz"\nepochs = 3\n[space]\nlr = [1e-3]', "unknown key 'epochs'"),
        (
            'data = "sq.npz"\nsearch = "bayes"\n[space]\nlr = [1e-3]',
            "search must be grid or random",
        ),
        ('data = "sq.npz"\n[space]', "[space] is empty"),
        ('data = "sq.npz"\n[space]\nwidth = [1, 2]', "'width' cannot be searched"),
        ('data = "sq.npz"\n[train]\nlr = 1e-3\n[space]\nlr = [1e-3]', "lr is both fixed"),
        ('data = "sq.npz"\n[train]\nspeed = 1\n[space]\nlr = [1e-3]', "'speed' is not a setting"),
        ('data = "sq.npz"\n[space]\nlr = []', "lr has no values"),
        ('data = "sq.npz"\n[space]\nlr = [1e-3, 1e-3]', "gives a value twice"),
        ('data = "sq.npz"\n[space]\nlr = {log_uniform = [1e-4, 1e-2]}', "lr must be a list"),
        ("[space]\nlr = [1e-3]", "no data"),
        ('data = "sq.npz"\n[space]\nbatch_size = [32, 0]', "trial_001 (batch_size=0)"),
        ('data = "sq.npz"\n[asha]\ngrace_period = 0\n[space]\nlr = [1e-3]', "grace_period"),
        ('data = "sq.npz"\nsearch = "random"\n[space]\nlr = [1e-3]', "trials must be"),
        (
            'data = "sq.npz"\nsearch = "random"\ntrials = 2\n[space]\nlr = {log_uniform = [0, 1]}',
            "0 < low < high",
        ),
        ('data = "sq.npz"\ntrials = 2\n[space]\nlr = [1e-3]', 'trials is for search = "random"'),
    ],
)
def test_a_bad_sweep_file_is_one_line_naming_it(folder, text, needle):
    path = _write(folder, text)
    with pytest.raises(InputError) as err:
        read_sweep(path)
    assert needle in str(err.value)
    assert str(path) in str(err.value)
    assert "\n" not in str(err.value)


def test_random_search_draws_the_same_trials_from_the_same_seed(folder):
    text = (
        'data = "sq.npz"\nsearch = "random"\ntrials = 6\nseed = {seed}\n[space]\n'
        "lr = {{log_uniform = [1e-4, 1e-2]}}\nhorizon = {{int_uniform = [5, 9]}}\n"
        "batch_size = [16, 32, 64]\n"
    )
    a = read_sweep(_write(folder, text.format(seed=1), "a.toml")).trials
    b = read_sweep(_write(folder, text.format(seed=1), "b.toml")).trials
    c = read_sweep(_write(folder, text.format(seed=2), "c.toml")).trials
    assert [t.values for t in a] == [t.values for t in b]
    assert [t.values for t in a] != [t.values for t in c]
    for t in a + c:
        assert 1e-4 <= t.values["lr"] <= 1e-2
        assert t.values["horizon"] in range(5, 10)
        assert t.values["batch_size"] in (16, 32, 64)
        assert t.config["lr"] == t.values["lr"]  # the drawn value is what trains
    assert len({t.values["lr"] for t in a}) == 6


def test_a_sweep_refuses_missing_data_a_used_folder_and_another_sweep(folder, tmp_path):
    missing = _write(folder, 'data = "nowhere.npz"\n[space]\nlr = [1e-3]', "missing.toml")
    with pytest.raises(InputError, match=r"nowhere\.npz"):
        run_sweep(missing, tmp_path / "x")
    assert not (tmp_path / "x").exists()  # nothing written before the data is checked
    out = tmp_path / "used"
    out.mkdir()
    (out / "sweep.json").write_text("{}")
    with pytest.raises(InputError, match="already holds a sweep; pass --resume"):
        run_sweep(folder / "grid.toml", out)
    with pytest.raises(InputError, match="another sweep"):
        run_sweep(folder / "grid.toml", out, resume=True)


def test_train_set_reads_settings_by_their_type():
    assert parse_settings(["lr=0.003", "batch_size=32"]) == {"lr": 0.003, "batch_size": 32}
    with pytest.raises(InputError, match="KEY one of lr"):
        parse_settings(["width=3"])
    with pytest.raises(InputError, match="batch_size must be an integer"):
        parse_settings(["batch_size=3.5"])


def test_asking_for_ray_without_it_is_one_line(cli, tmp_path, folder, monkeypatch):
    fake = tmp_path / "noray" / "ray"  # an installed-looking ray whose import fails
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("raise ImportError('No module named ray')\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(fake.parent), *sys.path])}
    args = ["sweep", str(folder / "grid.toml"), "--out", str(tmp_path / "s"), "--backend", "ray"]
    proc = subprocess.run(
        [sys.executable, "-m", "sensorimotor", *args], capture_output=True, text=True, env=env
    )
    assert_one_line_error(proc, "Ray is not installed", '".[ray]"')
    assert not (tmp_path / "s").exists()
    from sensorimotor.reproduce import reproduce

    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` fails in this process too
    with pytest.raises(InputError, match="Ray is not installed"):
        reproduce(tmp_path / "r", backend="ray")
    assert not (tmp_path / "r").exists()


def _rows(out: Path) -> list[dict]:
    with open(out / "sweep.csv", newline="") as f:
        return list(csv.DictReader(f))


def _val_errors(run: Path) -> list[str]:
    with open(run / "history.csv", newline="") as f:
        return [r["val_error"] for r in csv.DictReader(f)]


def test_a_local_sweep_killed_and_resumed_finishes_every_trial(folder, tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "sensorimotor", "sweep", str(folder / "grid.toml")]
    cmd += ["--out", str(out), "--workers", "2"]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.time() + 120
    while time.time() < deadline and not list((out / "runs").glob("*/checkpoint.pt")):
        time.sleep(0.02)
    assert proc.poll() is None, "finished before a checkpoint was seen"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    assert not (out / "sweep.csv").exists()
    resume = [*cmd[:-1], "1", "--resume"]  # one worker: in the command's own process
    done = subprocess.run(resume, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    rows = _rows(out)
    assert [r["trial"] for r in rows] == [f"trial_{i:03d}" for i in range(8)]
    assert {(r["lr"], r["batch_size"]) for r in rows} == {
        (lr, bs) for lr in ("0.0003", "0.001", "0.003", "0.01") for bs in ("32", "64")
    }
    for r in rows:  # every epoch once: a killed run went on from its checkpoint
        assert r["epochs"] == "3"
        assert r["stopped"] == "max epochs"
        errors = _val_errors(Path(r["run"]))
        assert len(errors) == 3
        assert float(r["best_val_error"]) == min(map(float, errors))
    best = min(rows, key=lambda r: float(r["best_val_error"]))
    md = (out / "sweep.md").read_text()
    assert md.index(best["trial"]) < min(md.index(r["trial"]) for r in rows if r is not best)
    image = mpimg.imread(out / "sweep.png")
    assert image.shape[0] > 300
    assert image.shape[1] > 2 * image.shape[0]
    # the printed command trains the best trial again: the same validation errors
    command = done.stdout.strip().splitlines()[-1].split()
    assert command[:2] == ["sensorimotor", "train"]
    command[command.index("--out") + 1] = str(tmp_path / "best")
    again = subprocess.run(
        [sys.executable, "-m", "sensorimotor", *command[1:]], capture_output=True, text=True
    )
    assert again.returncode == 0, again.stderr
    assert _val_errors(tmp_path / "best") == _val_errors(Path(best["run"]))


def test_a_bad_backend_or_address_is_refused_before_ray_starts(folder, tmp_path):
    from sensorimotor.jobs.ray_backend import _check_reachable
    from sensorimotor.reproduce import reproduce

    with pytest.raises(InputError, match="--backend: use local or ray, got 'dask'"):
        reproduce(tmp_path / "r", backend="dask")
    with pytest.raises(InputError, match="add --backend ray"):
        run_sweep(folder / "grid.toml", tmp_path / "s", address="127.0.0.1:6379")
    with pytest.raises(InputError, match=r"cannot reach a Ray cluster at 127\.0\.0\.1:1 "):
        _check_reachable("127.0.0.1:1")  # nothing listens on port 1: refused at once
    assert not (tmp_path / "r").exists()
    assert not (tmp_path / "s").exists()


def test_model_sizes_are_searched_and_set_by_the_best_command(folder, tmp_path):
    from sensorimotor.learn.evaluate import load_run
    from sensorimotor.learn.runs import model_config

    spec = _write(
        folder,
        'data = "sq.npz"\n[train]\nmodel = "s"\nmax_epochs = 1\npredictor_hidden = 32\n'
        "[space]\nz_sensors = [3, 10]\n",
        "sizes.toml",
    )
    assert [t.sizes for t in read_sweep(spec).trials] == [
        {"predictor_hidden": 32, "z_sensors": z} for z in (3, 10)
    ]
    result = run_sweep(spec, tmp_path / "out", workers=1, log=lambda _: None)
    model = load_run(tmp_path / "out" / "runs" / "trial_000").model
    assert model.config.z_sensors == 3
    assert model.config.predictor_hidden == 32
    assert "--set predictor_hidden=32" in result.best_command
    assert ("--set z_sensors=3" in result.best_command) == (result.rows[0]["z_sensors"] == 3)
    with pytest.raises(InputError, match="lstm_size must be an integer >= 1"):
        model_config("rec-sm", {"lstm_size": 0})
