"""`sensorimotor reproduce`: one command end to end, cached, resumable after a kill."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import matplotlib.image as mpimg
import pytest

from conftest import alive, assert_one_line_error

STAGES = ("data", "train", "evaluate", "analyze", "report")


def _command(out: Path, *extra: str) -> list[str]:
    """`reproduce --scale smoke` into ``out`` with two workers, as a subprocess command line."""
    smoke = ["reproduce", "--scale", "smoke", "--out", str(out), "--workers", "2"]
    return [sys.executable, "-m", "sensorimotor", *smoke, *extra]


def _reproduce(out: Path, *extra: str, timeout: float = 900) -> subprocess.CompletedProcess:
    return subprocess.run(
        _command(out, *extra),
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def _as_in_a_terminal() -> None:
    """SIGINT as a terminal's foreground command has it: a suite started in the background of a
    non-interactive shell inherits it ignored, and Python then never raises KeyboardInterrupt."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start_until_a_checkpoint(out: Path, stderr, worlds: str | None = None) -> subprocess.Popen:
    """Start the smoke reproduction (of ``worlds``, default all) in its own process group;
    return once a training has written its first checkpoint, with the run still going."""
    proc = subprocess.Popen(
        _command(out, *(("--worlds", worlds) if worlds else ())),
        stdout=subprocess.DEVNULL,
        stderr=stderr,
        text=True,
        start_new_session=True,
        preexec_fn=_as_in_a_terminal,
    )
    deadline = time.time() + 300
    while time.time() < deadline and not list((out / "runs").glob("*/checkpoint.pt")):
        time.sleep(0.05)
    assert proc.poll() is None, "finished before a checkpoint was seen"
    return proc


def _table_numbers(out: Path) -> dict:
    t = json.loads((out / "table1.json").read_text())
    return {
        tw: {r["model"]: {w: c["values"] for w, c in r["cells"].items()} for r in rows}
        for tw, rows in t["tables"].items()
    }


@pytest.fixture(scope="module")
def smoke(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("reproduce") / "smoke"
    proc = _reproduce(out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return out


@pytest.mark.slow  # the whole pipeline, end to end
def test_smoke_report_has_every_stage_and_a_full_table(smoke):
    md = (smoke / "report.md").read_text()
    html = (smoke / "report.html").read_text()
    for stage in STAGES:
        assert f"| {stage} |" in md, stage
    t = json.loads((smoke / "table1.json").read_text())
    assert sorted(t["tables"]) == ["rooms1", "rooms2", "square"]
    for rows in t["tables"].values():
        numbers = [c["mean"] for r in rows for c in r["cells"].values()]
        assert len(numbers) == 12  # 4 models x 3 test worlds
        assert all(0 < x < 10 for x in numbers)
    assert md.count("### Trained on") == 3
    assert "**Note.** A smoke test of the pipeline" in md  # its verdicts mean nothing
    assert "<b>Note.</b> A smoke test of the pipeline" in html
    # every image of the Markdown report exists and loads; the HTML embeds them all
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    assert len(images) >= 10
    for rel in images:
        img = mpimg.imread(smoke / rel)
        assert img.ndim == 3
        assert img.shape[0] > 50
    assert html.count("data:image/png;base64,") == len(images)
    assert 'src="figures' not in html  # self-contained


@pytest.mark.slow  # the whole pipeline, end to end
def test_rerun_uses_the_cache_and_a_deleted_stage_is_redone_alone(smoke):
    before = _table_numbers(smoke)
    stamp = {p: p.stat().st_mtime_ns for p in (smoke / "runs").rglob("model.pt")}
    proc = _reproduce(smoke)
    assert proc.returncode == 0, proc.stderr[-3000:]
    timings = json.loads((smoke / "timings.json").read_text())
    assert timings["train"]["jobs"] == 0
    assert timings["train"]["cached"] == 12
    assert timings["evaluate"]["jobs"] == 0
    assert timings["analyze"]["jobs"] == 0
    assert {p: p.stat().st_mtime_ns for p in stamp} == stamp  # no training happened
    # delete one evaluation, one analysis and one run folder: exactly those are redone, to the
    # same numbers (the retrained run is the same bytes, so its kept evaluation still holds)
    (smoke / "eval" / "rooms1__sm__s0.json").unlink()
    shutil.rmtree(smoke / "analysis" / "square__s__s0")
    shutil.rmtree(smoke / "runs" / "rooms2__rec-s__s0")
    proc = _reproduce(smoke)
    assert proc.returncode == 0, proc.stderr[-3000:]
    timings = json.loads((smoke / "timings.json").read_text())
    assert (timings["train"]["jobs"], timings["evaluate"]["jobs"], timings["analyze"]["jobs"]) == (
        1,
        1,
        1,
    )
    assert _table_numbers(smoke) == before


@pytest.mark.slow  # the whole pipeline, end to end
def test_square_alone_killed_during_training_resumes_to_the_same_table_one(smoke, tmp_path):
    """`--worlds square`, killed during training and run again: the paper's own Table I
    (trained on Square, tested on all three worlds) without training on the other two, the
    same numbers as the full reproduction's."""
    out = tmp_path / "square"
    proc = _start_until_a_checkpoint(out, stderr=subprocess.DEVNULL, worlds="square")
    proc.send_signal(signal.SIGKILL)  # the parent only: workers must die with it
    proc.wait()
    time.sleep(1.0)
    assert not (out / "report.md").exists()
    again = _reproduce(out, "--worlds", "square")
    assert again.returncode == 0, again.stderr[-3000:]
    assert {p.name.split("__")[0] for p in (out / "runs").iterdir()} == {"square"}
    assert sorted(p.stem for p in (out / "data").glob("*.npz")) == ["rooms1", "rooms2", "square"]
    assert _table_numbers(out) == {"square": _table_numbers(smoke)["square"]}
    assert "Table I ordering (trained on Square)" in (out / "report.md").read_text()


@pytest.mark.slow  # the whole pipeline, end to end
def test_ctrl_c_stops_every_worker_at_once_and_says_how_to_go_on(tmp_path):
    out = tmp_path / "interrupted"
    proc = _start_until_a_checkpoint(out, stderr=subprocess.PIPE, worlds="square")
    os.killpg(proc.pid, signal.SIGINT)  # as a terminal's Ctrl-C: the parent and its workers
    t0 = time.time()
    _, err = proc.communicate(timeout=60)
    assert time.time() - t0 < 15, err[-2000:]  # not after the queued trainings
    assert proc.returncode == 130, err[-2000:]
    assert err.strip().splitlines()[-1].startswith("interrupted: "), err[-2000:]
    assert "Traceback" not in err, err[-4000:]
    deadline = time.time() + 5  # an exited child may linger a moment before it is reaped
    while time.time() < deadline and alive(proc.pid, group=True):
        time.sleep(0.1)
    assert not alive(proc.pid, group=True), "a process of the run outlived it"


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["--scale", "huge"], "unknown scale"),
        (["--seeds", "0"], "--seeds"),
        (["--workers", "0"], "--workers"),
        (["--device", "tpu"], "unknown device"),
        (["--worlds", "square,maze"], "--worlds: use any of square, rooms1, rooms2"),
        (["--worlds", ","], "--worlds"),
        (["--experiment", "maze"], "--experiment: use any of"),
    ],
)
def test_bad_options_are_refused(args, needle, tmp_path, cli):
    proc = cli("reproduce", "--out", tmp_path / "o", *args)
    assert_one_line_error(proc, needle)
    assert not (tmp_path / "o").exists()  # refused before anything is made


def test_output_folder_that_is_a_file_is_refused(tmp_path, cli):
    target = tmp_path / "report.txt"
    target.write_text("not a folder")
    proc = cli("reproduce", "--scale", "smoke", "--out", target)
    assert_one_line_error(proc, str(target), "is a file")


@pytest.mark.slow  # the whole pipeline, end to end
def test_a_failing_worker_names_its_run_and_finished_runs_are_kept(smoke, tmp_path):
    out = tmp_path / "copy"
    shutil.copytree(smoke, out)
    bad = out / "data" / "rooms2.npz"
    bad.write_bytes(bad.read_bytes()[:1000])  # truncated: rooms2's trainings must fail
    stamp = {p: p.stat().st_mtime_ns for p in (out / "runs").rglob("model.pt")}
    proc = _reproduce(out)
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    last = proc.stderr.strip().splitlines()[-1]
    assert last.startswith("error: run rooms2__")
    assert last.count("rooms2__") == 1  # the run named once
    assert "rooms2.npz" in last
    assert {p: p.stat().st_mtime_ns for p in stamp} == stamp  # nothing finished was lost
    bad.unlink()  # the data stage makes it again, byte for byte
    proc = _reproduce(out)
    assert proc.returncode == 0, proc.stderr[-3000:]
    timings = json.loads((out / "timings.json").read_text())
    assert timings["train"]["jobs"] == 0
    assert _table_numbers(out) == _table_numbers(smoke)


@pytest.mark.slow  # the whole pipeline, end to end
def test_a_bad_database_in_a_stack_across_worlds_fails_only_its_runs(tmp_path):
    from sensorimotor.errors import InputError
    from sensorimotor.files import file_hash
    from sensorimotor.pipeline.stages import train_job
    from sensorimotor.sim.database import generate, save_database
    from sensorimotor.sim.world import load_world

    good, bad = tmp_path / "square.npz", tmp_path / "rooms2.npz"
    save_database(generate(load_world("square"), 3000, seed=0), good)
    save_database(generate(load_world("rooms2"), 3000, seed=0), bad)
    bad.write_bytes(bad.read_bytes()[:1000])
    runs = [
        (str(good), 0, str(tmp_path / "square__s__s0"), file_hash(good)),
        (str(bad), 0, str(tmp_path / "rooms2__s__s0"), file_hash(bad)),
        (str(bad), 1, str(tmp_path / "rooms2__s__s1"), file_hash(bad)),
    ]
    config = {"model": "s", "device": "cpu", "max_epochs": 1, "patience": 10}
    with pytest.raises(InputError, match=r"^rooms2__s__s0 \(and 1 more runs\): .*rooms2\.npz"):
        train_job(runs, config)
    assert (tmp_path / "square__s__s0" / "model.pt").exists()  # trained, kept for the retry
    assert not (tmp_path / "rooms2__s__s0").exists()


# --- cache keys: a stage is redone when anything it is made from changes -------------------


def test_a_database_is_keyed_by_its_size_and_a_run_by_its_scales_patience():
    from sensorimotor.pipeline.paper import SCALES, _train_config
    from sensorimotor.pipeline.stages import data_key

    keys = {data_key(w, sc.steps) for w in ("square", "rooms1") for sc in SCALES.values()}
    assert len(keys) == 2 * len(SCALES)
    assert _train_config(SCALES["quick"], "s", "cpu")["patience"] == SCALES["quick"].patience == 50
    assert _train_config(SCALES["quick"], "rec-sm", "cpu")["max_epochs"] == 80


def test_a_kept_run_is_retrained_when_its_data_settings_or_model_sizes_change(
    square_db_path, tmp_path
):
    from sensorimotor.files import file_hash
    from sensorimotor.learn.config import TrainConfig
    from sensorimotor.learn.train import train
    from sensorimotor.pipeline.stages import run_matches

    config = {"model": "s", "max_epochs": 1}
    run = train(square_db_path, tmp_path / "run", TrainConfig(**config)).run_dir
    sha = file_hash(square_db_path)
    assert run_matches(run, sha, config)
    assert not run_matches(run, "other data", config)
    assert not run_matches(run, sha, {**config, "max_epochs": 2})
    made = json.loads((run / "config.json").read_text())
    made["model"]["z_sensors"] = 3  # trained when models.py gave z_s 3 dimensions
    (run / "config.json").write_text(json.dumps(made))
    assert not run_matches(run, sha, config)


def test_a_kept_analysis_is_redone_when_the_metrics_change(tmp_path, monkeypatch):
    import sensorimotor.analysis as analysis
    from sensorimotor.pipeline.paper import _analysis_job_of

    dest = tmp_path / "raw__square"
    target = ("raw__square", "raw", "db.npz", None, str(dest))
    job = _analysis_job_of(target, {"db.npz": "abc"})
    dest.mkdir()
    (dest / "metrics.json").write_text("{}")
    (dest / "stage.json").write_text(json.dumps({"key": job.args[-1]}))
    assert _analysis_job_of(target, {"db.npz": "abc"}) is None  # kept
    assert _analysis_job_of(target, {"db.npz": "abd"}) is not None  # other data
    monkeypatch.setattr(analysis, "METRICS_VERSION", analysis.METRICS_VERSION + 1)
    assert _analysis_job_of(target, {"db.npz": "abc"}) is not None  # other metrics


def test_a_kept_evaluation_is_redone_when_its_model_or_data_change(tmp_path):
    import sensorimotor.pipeline.paper as rp

    rep = rp.Reproduction(tmp_path, rp.SCALES["smoke"], 1, "cpu", 1)
    rep.data = {w: tmp_path / f"{w}.npz" for w in rp.WORLDS}
    run = rep.run_dir("square", "s", 0)
    run.mkdir(parents=True)
    (run / "model.pt").write_bytes(b"weights")
    job = rp._eval_job_of(rep, "square", "s", 0, "abc")
    path = rp._eval_path(rep, run.name)
    path.parent.mkdir()
    path.write_text(json.dumps({"key": job.args[-1], "result": {}}))
    assert rp._eval_job_of(rep, "square", "s", 0, "abc") is None  # kept
    assert rp._eval_job_of(rep, "square", "s", 0, "abd") is not None  # other data
    (run / "model.pt").write_bytes(b"retrained")
    assert rp._eval_job_of(rep, "square", "s", 0, "abc") is not None  # other model


def test_a_transfer_fits_on_the_training_world_and_applies_to_another(tmp_path):
    import sensorimotor.pipeline.paper as rp

    rep = rp.Reproduction(tmp_path, rp.SCALES["smoke"], 1, "cpu", 1)
    rep.data = {w: tmp_path / f"{w}.npz" for w in rp.WORLDS}
    for world in rp.TRANSFER_FROM:
        own, *transfers = rp._analysis_targets(rep, world, "rec-sm", 0)
        assert own[3] is None
        assert {t[2] for t in transfers} == {str(rep.data[w]) for w in rp.WORLDS if w != world}
        assert all(t[3] == str(rep.data[world]) for t in transfers)
    assert len(rp._analysis_targets(rep, "square", "rec-s", 0)) == 1


def test_a_crash_in_a_job_is_not_reported_as_bad_input():
    from sensorimotor.errors import InputError
    from sensorimotor.jobs.workers import JobFailure, raise_first

    with pytest.raises(RuntimeError, match="run square__s__s0 failed") as info:
        raise_first([JobFailure("square__s__s0", ZeroDivisionError("x"))], "run ", print)
    assert not isinstance(info.value, InputError)
    assert isinstance(info.value.__cause__, ZeroDivisionError)


def _section(md: str, world: str) -> str:
    return md.split(f"### Trained on {world}\n")[1].split("\n#")[0]


@pytest.mark.slow  # the whole pipeline, end to end
def test_the_reports_numbers_are_the_tables_and_the_transfers(smoke):
    from sensorimotor.analysis.claims import cluster_f1

    md = (smoke / "report.md").read_text()
    t = json.loads((smoke / "table1.json").read_text())
    for name in ("mean", "copy_last"):
        row = f"| baseline: {name.replace('_', '-')} | " + " | ".join(
            f"{t['baselines'][w][name]:.5f}" for w in t["worlds"]
        )
        assert md.count(row + " |") == 3, row  # once in each training world's Table I
    assert "[0.03735]" in _section(md, "square")  # the paper's numbers: Square-trained only
    for world in ("rooms1", "rooms2"):
        assert "[" not in _section(md, world), world
    told_apart = 0
    for folder in sorted((smoke / "transfer").iterdir()):
        m = json.loads((folder / "metrics.json").read_text())
        fit, applied = m["fit_analysis"], m["analysis"]
        head = f"| {fit['world']} → {applied['world']} |"
        row = next(line for line in md.splitlines() if line.startswith(head))
        for e in ("corner", "wall_end", "nothing"):
            c = fit["events"].get(e, {}).get("cluster")
            if c is None:
                continue
            there = cluster_f1(applied, c, e)
            text = "none there" if there != there else f"{there:.2f}"
            assert f"#{c}: {fit['events'][e]['f1']:.2f} → {text}" in row, (row, e)
            told_apart += abs(there - fit["events"][e]["f1"]) >= 0.005
    assert told_apart > 0


@pytest.mark.slow  # the whole pipeline, end to end
def test_the_report_opens_on_its_summary_and_stays_small(smoke):
    md = (smoke / "report.md").read_text()
    sections = [line for line in md.splitlines() if line.startswith("## ")]
    assert sections[0] == "## Summary"
    summary = md.split("## Summary\n")[1].split("\n## ")[0]
    assert "| the paper's claim | verdict |" in summary
    assert "(paper 0.03735," in summary  # S-encoder on Square beside the paper's value
    assert sections[-1] == "## How this report was made"  # settings and timings last
    assert (smoke / "report.html").stat().st_size < 5e6
