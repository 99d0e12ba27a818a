"""The Ray backend: jobs as Ray tasks behave as the local workers' jobs (results, progress,
failures, Ctrl-C), `reproduce --backend ray` trains the local models, and a sweep on Ray
(ASHA) is killed and resumed. One local Ray (2 CPUs, no dashboard, a small object store) is
started in this process for the whole module; subprocesses join it with --address."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image as mpimg
import pytest

from conftest import alive
from sensorimotor.errors import InputError
from sensorimotor.jobs import ray_backend, workers
from sensorimotor.jobs.workers import Job, send_progress

ray = pytest.importorskip("ray")


@pytest.fixture(scope="module")
def cluster() -> str:
    """A local Ray in this process; its address, for subprocesses to join."""
    ray.init(num_cpus=2, include_dashboard=False, object_store_memory=80 * 2**20)
    # the tasks run this module's functions: send them by value (tests/ is not on the
    # workers' path)
    ray.cloudpickle.register_pickle_by_value(sys.modules[__name__])
    yield ray.get_runtime_context().gcs_address
    ray.cloudpickle.unregister_pickle_by_value(sys.modules[__name__])
    ray.shutdown()


def _square(name: str, x: int) -> int:
    send_progress(name, f"squaring {x}")
    if x < 0:
        raise InputError(f"cannot square {x} here")
    send_progress(name, "done")
    return x * x


def _then(name: str, result: int) -> list[Job]:
    """A follow-up job for each first-round job."""
    return [] if name.endswith("+") else [Job(f"{name}+", _square, (f"{name}+", result + 1))]


def _run(run_jobs, jobs_workers: int) -> tuple[dict, list, list]:
    lines: list[tuple[str, str]] = []
    jobs = [Job(n, _square, (n, x)) for n, x in (("a", 2), ("b", -1), ("c", 3))]
    results, failures = run_jobs(jobs, jobs_workers, lambda n, m: lines.append((n, m)), then=_then)
    named = [(f.name, type(f.error), str(f.error)) for f in failures]
    by_job = {n: [m for k, m in lines if k == n] for n in dict.fromkeys(k for k, _ in lines)}
    return results, named, sorted(by_job.items())


def test_jobs_on_ray_give_what_local_jobs_give(cluster):
    assert _run(ray_backend.run_jobs, 2) == _run(workers.run_jobs, 1)
    results, failures, _ = _run(ray_backend.run_jobs, 2)
    assert results == {"a": 4, "c": 9, "a+": 25, "c+": 100}
    assert failures == [("b", InputError, "cannot square -1 here")]


def _sleep_then_write(path: str) -> None:
    Path(f"{path}.pid").write_text(str(os.getpid()))
    send_progress(path, "started")
    time.sleep(60)  # a task the cancel missed is still alive when the test looks
    Path(path).write_text("finished")


def test_ctrl_c_cancels_the_runs_tasks(cluster, tmp_path):
    """Ctrl-C kills the processes of the run's tasks: every task that started is gone within
    seconds (however slowly a loaded machine delivered its first line), none finishes."""
    paths = [str(tmp_path / f"job{i}") for i in range(2)]

    def interrupt(_name, _message):
        raise KeyboardInterrupt

    jobs = [Job(p, _sleep_then_write, (p,)) for p in paths]
    with pytest.raises(KeyboardInterrupt):
        ray_backend.run_jobs(jobs, 2, interrupt)
    time.sleep(2)  # a queued task the cancel missed would start meanwhile
    pids = [int(Path(f"{p}.pid").read_text()) for p in paths if Path(f"{p}.pid").exists()]
    assert pids  # the interrupt came from a started task's line
    deadline = time.time() + 20
    while time.time() < deadline and any(map(alive, pids)):
        time.sleep(0.1)
    assert not any(map(alive, pids))
    assert not any(Path(p).exists() for p in paths)


@pytest.mark.slow  # a smoke reproduction of Square on Ray
def test_reproduce_on_ray_trains_what_local_jobs_train(cluster, tmp_path, one_thread):
    """`reproduce --backend ray` runs the pipeline's jobs as Ray tasks: its table is whole and
    every model it trained is, tensor for tensor, the one the same training job gives in this
    process (the local reference: the evaluation and the table are made from these weights
    alone, by the same code wherever it runs)."""
    import torch

    from sensorimotor.files import file_hash
    from sensorimotor.learn.runs import torch_load
    from sensorimotor.pipeline import paper
    from sensorimotor.reproduce import reproduce

    lines: list[str] = []
    out = tmp_path / "ray"
    reproduce(out, "smoke", worlds=["square"], workers=2, backend="ray", log=lines.append)
    assert any("square__rec-sm__s0: epoch   1" in line for line in lines)  # the same display
    table = json.loads((out / "table1.json").read_text())
    assert {r["model"] for r in table["tables"]["square"]} == set(paper.paper_kinds())
    rep = paper.Reproduction(tmp_path / "local", paper.SCALES["smoke"], 1, "cpu", 1, ("square",))
    rep.data = {"square": out / "data" / "square.npz"}
    jobs, trains, _ = paper._training_jobs(rep, {"square": file_hash(rep.data["square"])})
    assert sorted(m for runs in trains.values() for _, m, _ in runs) == sorted(paper.paper_kinds())
    for job in jobs:
        job.fn(*job.args)
    for run in (out / "runs").iterdir():
        ray_state = torch_load(run / "model.pt")
        local_state = torch_load(rep.out / "runs" / run.name / "model.pt")
        assert ray_state.keys() == local_state.keys()
        for key, tensor in ray_state.items():
            assert torch.equal(tensor, local_state[key]), (run.name, key)


SWEEP = """data = "sq.npz"
[train]
model = "s"
max_epochs = 2
[space]
lr = [1e-3, 1e-2]
batch_size = [32, 64]
[asha]
grace_period = 1
reduction_factor = 2
"""


@pytest.mark.slow  # four trials on Ray, twice started
def test_a_sweep_on_ray_killed_and_resumed(cluster, tmp_path):
    from sensorimotor.sim.database import generate, save_database
    from sensorimotor.sim.world import load_world

    save_database(generate(load_world("square"), 5_000, seed=0), tmp_path / "sq.npz")
    (tmp_path / "sweep.toml").write_text(SWEEP)
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "sensorimotor", "sweep", str(tmp_path / "sweep.toml")]
    cmd += ["--out", str(out), "--backend", "ray", "--address", cluster]
    proc = subprocess.Popen(
        cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.time() + 300
    while time.time() < deadline and not list((out / "runs").glob("*/checkpoint.pt")):
        time.sleep(0.02)
    assert proc.poll() is None, "finished before a checkpoint was seen"
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    done = subprocess.run([*cmd, "--resume"], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "restoring the Ray Tune experiment" in done.stderr
    assert done.stdout.startswith("sensorimotor train s --data")  # Tune's lines: on stderr
    with open(out / "sweep.csv", newline="") as f:
        rows = list(csv.DictReader(f))
    assert [r["trial"] for r in rows] == [f"trial_{i:03d}" for i in range(4)]
    for r in rows:
        with open(Path(r["run"]) / "history.csv", newline="") as f:
            epochs = [int(h["epoch"]) for h in csv.DictReader(f)]
        assert epochs == list(range(len(epochs)))  # every epoch once, resumed or not
        assert r["stopped"] == ("max epochs" if len(epochs) == 2 else "ASHA")
    assert any(r["stopped"] == "max epochs" for r in rows)
    assert "ASHA early termination" in (out / "sweep.md").read_text()
    assert mpimg.imread(out / "sweep.png").shape[1] > 600


def test_rl_agents_as_ray_tasks_are_those_trained_here(cluster, tmp_path, one_thread):
    """`rl --backend ray`: every agent a Ray task, the same rl.json to the byte."""
    pytest.importorskip("stable_baselines3")
    from sensorimotor.jobs.backend import run_all
    from sensorimotor.rl.runner import RLConfig, run_grid

    runs = Path(__file__).parents[2] / "docs" / "results" / "runs"
    tiny = {"n_steps": 32, "batch_size": 64, "n_epochs": 1, "learning_rate": 3e-4,
            "gamma": 0.99, "gae_lambda": 0.95, "ent_coef": 0.0}  # fmt: skip
    config = RLConfig("corner", "rooms1", ("raw",), 2, 64, str(runs), eval_every=64,
                      eval_episodes=2, n_envs=2, stats_steps=64, ppo=tiny)  # fmt: skip
    run_grid(config, tmp_path / "here")
    run_grid(
        config,
        tmp_path / "ray",
        run_agents=lambda todo: run_all(ray_backend.run_jobs, 2, todo),
    )
    assert (tmp_path / "ray" / "rl.json").read_bytes() == (
        tmp_path / "here" / "rl.json"
    ).read_bytes()
