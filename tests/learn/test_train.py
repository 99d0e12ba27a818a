"""Training: the TBPTT stream layout, the paper's early stopping, learning, determinism, resume."""

from __future__ import annotations

import csv
import json
import math
import platform
import re
import signal
import subprocess
import sys
import time
from dataclasses import asdict

import numpy as np
import pytest
import torch

import sensorimotor.learn.train as train_mod
from conftest import assert_one_line_error
from sensorimotor.errors import InputError
from sensorimotor.learn.batches import stream_layout
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import train_epoch_recurrent
from sensorimotor.learn.evaluate import baselines, load_run, model_error, split_tensors
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.models import build_model
from sensorimotor.learn.runs import EarlyStopping
from sensorimotor.learn.train import train
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.sim.world import load_world

# --- the stream layout of truncated back-propagation through time -------------------------


@pytest.mark.parametrize(("n", "streams"), [(1280, 64), (1000, 64), (64, 64), (12345, 7)])
def test_stream_layout_sees_every_step_once_in_contiguous_streams(n, streams):
    index, mask = stream_layout(n, streams)
    seen = index[mask]
    assert sorted(seen.tolist()) == list(range(n))  # every step exactly once
    lengths = mask.sum(1)
    assert int(lengths.max() - lengths.min()) <= 1
    for k in range(streams):
        row = index[k, : lengths[k]]
        assert torch.equal(row, torch.arange(int(row[0]), int(row[0]) + len(row)))  # contiguous
        assert bool(mask[k, : lengths[k]].all())
        assert not bool(mask[k, lengths[k] :].any())
    starts = index[:, 0]
    assert bool((starts[1:] > starts[:-1]).all())  # streams in order, stream k follows k - 1


class StateSpy(torch.nn.Module):
    """Wraps a recurrent model and records the state handed to each call."""

    def __init__(self, model):
        super().__init__()
        self.model, self.seen, self.returned = model, [], []
        self.config = model.config

    def forward(self, s, m, state=None):
        self.seen.append(None if state is None else tuple(t.clone() for t in state))
        out = self.model(s, m, state)
        self.returned.append(tuple(t.detach().clone() for t in out[2]))
        return out


def test_recurrent_epoch_carries_detached_state_and_resets_each_epoch():
    spy = StateSpy(build_model("rec-sm", seed=0))
    opt = FusedAdam(spy.model.parameters())
    s, m = torch.rand(64 * 45 + 1, 5), torch.rand(64 * 45 + 1, 2)  # 45 steps a stream: 3 chunks
    for _epoch in range(2):
        start = len(spy.seen)
        train_epoch_recurrent(spy, opt, s, m, streams=64, horizon=20)
        calls = spy.seen[start:]
        assert len(calls) == 3  # chunks of 20, 20, 5
        assert calls[0] is None  # reset at the start of each epoch
        for prev, cur in zip(spy.returned[start:], calls[1:], strict=False):
            assert all(
                torch.equal(a, b) and not b.requires_grad for a, b in zip(prev, cur, strict=True)
            )


# --- early stopping ------------------------------------------------------------------------

SCRIPT = [1.0, 0.97, 0.94, 0.93, 0.92, 0.95, 0.91, 0.90, 0.96, 0.97, 0.98, 0.99, 0.99, 0.5]
# e0 improves (ref 1.0); e1 does not (0.97 >= 0.95); e2 improves (ref 0.94); e3..e12 stay above
# 0.95 * 0.94 = 0.893, so the 10th epoch without improvement is e12: stop there. Lowest: e7.


def test_early_stopping_rule_on_a_script():
    stopper = EarlyStopping(patience=10, min_ratio=0.95)
    improved = []
    for epoch, err in enumerate(SCRIPT):
        improved.append(stopper.update(epoch, err)[0])
        if stopper.should_stop:
            break
    assert epoch == 12
    assert improved[:3] == [True, False, True]
    assert not any(improved[3:])
    assert (stopper.best_epoch, stopper.lowest) == (7, 0.90)


def test_an_error_at_exactly_the_threshold_is_not_an_improvement():
    stopper = EarlyStopping(patience=10, min_ratio=0.95)
    stopper.update(0, 1.0)
    assert stopper.update(1, 0.95) == (False, True)  # "below 0.95 x", not "at most"; lowest yet
    assert stopper.waited == 1


def test_train_stops_at_the_scripted_epoch_and_keeps_the_best_weights(tmp_path, monkeypatch):
    db = tmp_path / "sq.npz"
    save_database(generate(load_world("square"), 3000, seed=0), db)
    snapshots = []

    def scripted(model, s, m):
        snapshots.append({k: v.clone() for k, v in model.state_dict().items()})
        return SCRIPT[len(snapshots) - 1]

    # the validation of either engine
    monkeypatch.setattr("sensorimotor.learn.engine.model_error", scripted)
    config = TrainConfig(model="s", seed=0, batch_size=64)
    result = train(db, tmp_path / "run", config)
    assert (result.epochs, result.best_epoch, result.stopped) == (13, 7, "early stopping")
    kept = torch.load(tmp_path / "run" / "model.pt", weights_only=True)
    assert all(torch.equal(kept[k], snapshots[7][k]) for k in kept)
    assert not all(torch.equal(kept[k], snapshots[12][k]) for k in kept)
    history = (tmp_path / "run" / "history.csv").read_text().splitlines()
    assert len(history) == 14  # header + 13 epochs


# --- learning ------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def square50k(tmp_path_factory):
    path = tmp_path_factory.mktemp("learn") / "square50k.npz"
    save_database(generate(load_world("square"), 50_000, seed=0), path)
    return path


def _test_error(run_dir, db_path):
    run, db = load_run(run_dir), load_database(db_path)
    s, m = split_tensors(db, "test")
    return model_error(run.model, s, m), baselines(db)["copy_last"]


def test_sm_beats_copy_last_by_a_clear_margin(square50k, tmp_path):
    train(square50k, tmp_path / "sm", TrainConfig(model="sm", seed=0, max_epochs=4))
    err, copy_last = _test_error(tmp_path / "sm", square50k)
    assert err < 0.5 * copy_last, (err, copy_last)


def test_rec_sm_beats_copy_last_by_a_clear_margin(square50k, tmp_path):
    # 50 k steps give only 31 TBPTT batches an epoch: patience is lifted so that it gets enough
    config = TrainConfig(model="rec-sm", seed=0, max_epochs=40, patience=1000)
    train(square50k, tmp_path / "rec", config)
    err, copy_last = _test_error(tmp_path / "rec", square50k)
    assert err < 0.5 * copy_last, (err, copy_last)


# --- determinism and resume ----------------------------------------------------------------


def _weights(run_dir):
    return torch.load(run_dir / "checkpoint.pt", weights_only=True)["model"]


@pytest.mark.parametrize("kind", ["sm", "rec-s"])
def test_same_seed_same_weights_and_resume_equals_uninterrupted(kind, square_db_path, tmp_path):
    cfg = TrainConfig(model=kind, seed=3, max_epochs=3)
    train(square_db_path, tmp_path / "a", cfg)
    train(square_db_path, tmp_path / "b", cfg)
    wa, wb = _weights(tmp_path / "a"), _weights(tmp_path / "b")
    assert all(torch.equal(wa[k], wb[k]) for k in wa)
    # the same bytes too: no temporary file name leaks into the archive
    assert (tmp_path / "a" / "model.pt").read_bytes() == (tmp_path / "b" / "model.pt").read_bytes()
    other = TrainConfig(model=kind, seed=4, max_epochs=3)
    train(square_db_path, tmp_path / "c", other)
    assert not all(torch.equal(wa[k], _weights(tmp_path / "c")[k]) for k in wa)
    # interrupted after 1 epoch, resumed to 3: the same weights as straight to 3
    train(square_db_path, tmp_path / "r", TrainConfig(model=kind, seed=3, max_epochs=1))
    train(square_db_path, tmp_path / "r", cfg, resume=True)
    wr = _weights(tmp_path / "r")
    assert all(torch.equal(wa[k], wr[k]) for k in wa)
    ha = (tmp_path / "a" / "history.csv").read_text().splitlines()
    hr = (tmp_path / "r" / "history.csv").read_text().splitlines()
    assert [ln.split(",")[:3] for ln in ha] == [ln.split(",")[:3] for ln in hr]


def test_resume_after_sigkill_matches_uninterrupted(square_db_path, tmp_path):
    args = ["train", "rec-s", "--data", str(square_db_path), "--seed", "1", "--max-epochs", "4"]
    proc = subprocess.Popen(
        [sys.executable, "-m", "sensorimotor", *args, "--out", str(tmp_path / "k")],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    ckpt = tmp_path / "k" / "checkpoint.pt"
    deadline = time.time() + 120
    while not ckpt.exists() and time.time() < deadline:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    resumed = subprocess.run(
        [sys.executable, "-m", "sensorimotor", *args, "--out", str(tmp_path / "k"), "--resume"],
        capture_output=True,
        text=True,
    )
    assert resumed.returncode == 0, resumed.stderr
    train(square_db_path, tmp_path / "u", TrainConfig(model="rec-s", seed=1, max_epochs=4))
    wk, wu = _weights(tmp_path / "k"), _weights(tmp_path / "u")
    assert all(torch.equal(wk[k], wu[k]) for k in wu)
    assert json.loads((tmp_path / "k" / "result.json").read_text())["epochs"] == 4


def test_a_kill_between_checkpoint_and_history_is_mended_on_resume(square_db_path, tmp_path):
    """checkpoint.pt holds epoch 1, history.csv only epoch 0 (the kill fell between their
    two writes): the resumed run finishes with the checkpoint's two epochs in history.csv."""
    cfg = TrainConfig(model="s", seed=0, max_epochs=2)
    train(square_db_path, tmp_path / "k", cfg)
    history = tmp_path / "k" / "history.csv"
    straight = history.read_text()
    history.write_text("".join(straight.splitlines(keepends=True)[:2]))
    (tmp_path / "k" / "result.json").unlink()
    result = train(square_db_path, tmp_path / "k", cfg, resume=True)
    assert history.read_text() == straight
    assert result.epochs == 2
    assert result.stopped == "max epochs"


def test_existing_run_needs_resume(square_db_path, tmp_path, cli):
    train(square_db_path, tmp_path / "a", TrainConfig(model="s", max_epochs=1))
    proc = cli("train", "s", "--data", square_db_path, "--out", tmp_path / "a")
    assert_one_line_error(proc, str(tmp_path / "a"), "--resume")


# --- bad input -----------------------------------------------------------------------------


def _bad_npz(path, **overrides):
    db = generate(load_world("square"), 2000, seed=0)
    arrays = {
        "sensors": db.sensors,
        "motors": db.motors,
        "poses": db.poses,
        "meta": np.array(json.dumps(db.meta)),
    }
    arrays.update(overrides)
    arrays = {k: v for k, v in arrays.items() if v is not None}
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


@pytest.mark.parametrize(
    ("case", "needle"),
    [
        ("missing", "not found"),
        ("truncated", "truncated"),
        ("text", "npz"),
        ("no_motors", "motors"),
        ("wrong_shape", "shape"),
        ("nan", "NaN"),
        ("inf", "NaN or inf"),
        ("tiny", "too small"),
    ],
)
def test_bad_data_is_refused_with_one_line(case, needle, tmp_path, cli):
    path = tmp_path / f"{case}.npz"
    if case == "truncated":
        good = _bad_npz(tmp_path / "good.npz")
        path.write_bytes(good.read_bytes()[:-500])
    elif case == "text":
        path.write_text("sensors,motors\n1,2\n")
    elif case == "no_motors":
        _bad_npz(path, motors=None)
    elif case == "wrong_shape":
        _bad_npz(path, sensors=np.zeros((2000, 4), np.float32))
    elif case in ("nan", "inf"):
        s = generate(load_world("square"), 2000, seed=0).sensors.copy()
        s[5, 2] = math.nan if case == "nan" else math.inf
        _bad_npz(path, sensors=s)
    elif case == "tiny":
        save_database(generate(load_world("square"), 300, seed=0), path)
    out = tmp_path / "run"
    proc = cli("train", "rec-sm", "--data", path, "--out", out)
    assert_one_line_error(proc, str(path), needle)
    assert not out.exists()  # nothing half-written


def test_unknown_model_is_refused(square_db_path, tmp_path, cli):
    proc = cli("train", "transformer", "--data", square_db_path, "--out", tmp_path / "r")
    assert_one_line_error(proc, "unknown model", "rec-sm")


@pytest.mark.parametrize(
    ("setting", "needle"),
    [
        ({"model": "lstm"}, "TrainConfig.model"),
        ({"batch_size": 0}, "TrainConfig.batch_size must be an integer >= 1, got 0"),
        ({"max_epochs": -1}, "TrainConfig.max_epochs"),
        ({"seed": 1.5}, "TrainConfig.seed"),
        ({"seed": 2**50}, "TrainConfig.seed must be at most 4294967295"),
        ({"lr": "1e-3"}, "TrainConfig.lr must be a number"),
        ({"lr": math.nan}, "TrainConfig.lr must be positive"),
        ({"min_ratio": 1.2}, "TrainConfig.min_ratio must be at most 1"),
        ({"max_minutes": 0}, "TrainConfig.max_minutes"),
        ({"device": "tpu"}, "unknown device 'tpu'"),
        ({"slow_dims": -1}, "TrainConfig.slow_dims must be an integer >= 0"),
        ({"model": "rec-sm", "slow_dims": 4}, "the slowness prior trains rec-sma's beliefs"),
        ({"model": "rec-sma", "slow_dims": 4097}, "TrainConfig.slow_dims must be at most 4096"),
        ({"model": "rec-sma", "slow_dims": 4, "slow_weight": 0}, "TrainConfig.slow_weight"),
    ],
)
def test_a_setting_that_cannot_train_is_refused_by_name(setting, needle):
    with pytest.raises(InputError, match=re.escape(needle)):
        TrainConfig(**setting)


def test_numpy_numbers_are_settings_too():
    config = TrainConfig(seed=np.int64(3), max_epochs=np.int32(2), lr=np.float32(0.5))
    assert json.dumps(asdict(config))  # config.json is JSON
    assert (config.seed, config.max_epochs, config.lr) == (3, 2, 0.5)


def test_corrupt_or_missing_checkpoint_is_refused(square_db_path, tmp_path, cli):
    run = tmp_path / "run"
    train(square_db_path, run, TrainConfig(model="s", max_epochs=1))
    (run / "model.pt").write_bytes(b"not a checkpoint")
    assert_one_line_error(cli("evaluate", run, "--data", square_db_path), "model.pt", "corrupt")
    (run / "model.pt").unlink()
    assert_one_line_error(cli("evaluate", run, "--data", square_db_path), "model.pt", "missing")
    (run / "checkpoint.pt").write_bytes(b"\x00" * 10)
    config = (run / "config.json").read_bytes()
    proc = cli(
        "train", "s", "--data", square_db_path, "--out", run, "--resume", "--max-epochs", "3"
    )
    assert_one_line_error(proc, "checkpoint.pt", "corrupt")
    assert (run / "config.json").read_bytes() == config  # a failed resume rewrites nothing
    assert_one_line_error(cli("evaluate", tmp_path / "nope", "--data", square_db_path), "not found")
    proc = cli("evaluate", square_db_path, "--data", square_db_path)  # a file, not a folder
    assert_one_line_error(proc, str(square_db_path), "is a file, not a run folder")


def test_resume_with_other_data_or_settings_says_what_changed(
    square_db_path, rooms1_db_path, tmp_path
):
    run = tmp_path / "run"
    train(square_db_path, run, TrainConfig(model="s", max_epochs=1))
    with pytest.raises(InputError, match="other data") as info:
        train(rooms1_db_path, run, TrainConfig(model="s", max_epochs=2), resume=True)
    assert str(rooms1_db_path) in str(info.value)
    assert str(square_db_path) in str(info.value)
    with pytest.raises(InputError, match=r"another train setting .*lr: 0\.001 -> 0\.01"):
        train(square_db_path, run, TrainConfig(model="s", max_epochs=2, lr=0.01), resume=True)
    with pytest.raises(InputError, match="seed: 0 -> 1"):
        train(square_db_path, run, TrainConfig(model="s", max_epochs=2, seed=1), resume=True)


def test_a_time_cap_counts_earlier_sessions_and_lifting_it_goes_on(square_db_path, tmp_path):
    run = tmp_path / "run"
    train(square_db_path, run, TrainConfig(model="s", max_epochs=1))
    spent = torch.load(run / "checkpoint.pt", weights_only=True)["seconds"]
    cap = TrainConfig(model="s", max_epochs=5, max_minutes=spent / 60 / 2)  # already used up
    res = train(square_db_path, run, cap, resume=True)
    assert (res.stopped, res.epochs) == ("time cap", 1)
    res = train(square_db_path, run, TrainConfig(model="s", max_epochs=3), resume=True)
    assert (res.stopped, res.epochs) == ("max epochs", 3)


def test_history_counts_the_training_time_over_sessions(square_db_path, tmp_path):
    train(square_db_path, tmp_path / "r", TrainConfig(model="s", max_epochs=2))
    result = train(
        square_db_path, tmp_path / "r", TrainConfig(model="s", max_epochs=3), resume=True
    )
    rows = list(csv.DictReader((tmp_path / "r" / "history.csv").read_text().splitlines()))
    elapsed = [float(r["elapsed"]) for r in rows]
    seconds = [float(r["seconds"]) for r in rows]
    assert len(rows) == 3
    assert elapsed == sorted(elapsed)
    assert elapsed[-1] >= sum(seconds) - 0.01  # each epoch's training, and its validation
    assert elapsed[-1] == pytest.approx(result.seconds, abs=1e-3)


def test_cli_max_minutes_caps_training(square_db_path, tmp_path, cli):
    out = tmp_path / "run"
    args = ("--max-minutes", "0.00001", "--max-epochs", "3")
    proc = cli("train", "s", "--data", square_db_path, "--out", out, *args)
    assert proc.returncode == 0, proc.stderr
    res = json.loads((out / "result.json").read_text())
    assert (res["stopped"], res["epochs"]) == ("time cap", 1)
    assert json.loads((out / "config.json").read_text())["train"]["max_minutes"] == 0.00001


def test_the_first_n_mod_streams_streams_are_the_longer_ones():
    _, mask = stream_layout(1000, 64)  # 1000 = 64 x 15 + 40
    lengths = mask.sum(1)
    assert lengths[:40].eq(16).all()
    assert lengths[40:].eq(15).all()


def test_a_run_file_in_the_way_is_found_before_anything_is_written(square_db_path, tmp_path, cli):
    run = tmp_path / "run"
    (run / "history.csv").mkdir(parents=True)
    proc = cli("train", "s", "--data", square_db_path, "--out", run, "--max-epochs", "1")
    assert_one_line_error(proc, "history.csv", "is a folder")
    assert [p.name for p in run.iterdir()] == ["history.csv"]


def test_damaged_weights_are_refused_not_loaded(square_db_path, tmp_path, cli):
    """torch does not check its archive's CRCs: a flipped byte would load as wrong weights."""
    run = tmp_path / "run"
    train(square_db_path, run, TrainConfig(model="sm", max_epochs=1))
    for name in ("model.pt", "checkpoint.pt"):
        data = bytearray((run / name).read_bytes())
        middle = len(data) // 2
        data[middle : middle + 8] = bytes(b ^ 0xFF for b in data[middle : middle + 8])
        (run / name).write_bytes(bytes(data))
    proc = cli("evaluate", run, "--data", square_db_path)
    assert_one_line_error(proc, "model.pt", "CRC")
    proc = cli("train", "sm", "--data", square_db_path, "--out", run, "--resume")
    assert_one_line_error(proc, "checkpoint.pt", "CRC")


def test_weights_of_another_model_or_not_finite_are_refused(square_db_path, tmp_path):
    s_run, sm_run = tmp_path / "s", tmp_path / "sm"
    train(square_db_path, s_run, TrainConfig(model="s", max_epochs=1))
    train(square_db_path, sm_run, TrainConfig(model="sm", max_epochs=1))
    (sm_run / "model.pt").write_bytes((s_run / "model.pt").read_bytes())
    with pytest.raises(InputError, match=r"model\.pt: weights do not fit.*Missing key"):
        load_run(sm_run)
    state = torch.load(s_run / "model.pt", weights_only=True)
    next(iter(state.values()))[0] = math.nan
    torch.save(state, s_run / "model.pt")
    with pytest.raises(InputError, match=r"model\.pt: non-finite weights in "):
        load_run(s_run)


_ONE_EPOCH = """
import hashlib, sys, torch
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.engine import train_epoch_recurrent
from sensorimotor.learn.fast.cpu import keep_freed_memory
from sensorimotor.learn.models import build_model
torch.set_num_threads(1)
if sys.argv[1] == "keep":
    assert keep_freed_memory() is True
g = torch.Generator().manual_seed(0)
s, m = torch.rand(2 * 64 * 20 + 1, 5, generator=g), torch.rand(2 * 64 * 20 + 1, 2, generator=g)
model = build_model("rec-sm", seed=3)
err = train_epoch_recurrent(model, FusedAdam(model.parameters()), s, m, 64, 20)
weights = b"".join(p.detach().numpy().tobytes() for p in model.parameters())
print(err, hashlib.sha256(weights).hexdigest())
"""


@pytest.mark.skipif(
    not (sys.platform.startswith("linux") and "glibc" in " ".join(platform.libc_ver())),
    reason="glibc only",
)
def test_keep_freed_memory_takes_effect_and_leaves_the_numbers_alone():
    def run(mode: str) -> str:  # a fresh process each: mallopt's setting is process-wide
        proc = subprocess.run(
            [sys.executable, "-c", _ONE_EPOCH, mode], capture_output=True, text=True, timeout=120
        )
        assert proc.returncode == 0, proc.stderr
        return proc.stdout

    assert run("default") == run("keep")


def test_train_takes_a_loaded_database_but_not_one_without_a_file(square_db_path, tmp_path):
    config = TrainConfig(model="s", max_epochs=1)
    loaded = train(load_database(square_db_path), tmp_path / "loaded", config)
    by_path = train(square_db_path, tmp_path / "by_path", config)
    assert loaded.best_val_error == by_path.best_val_error
    with pytest.raises(InputError, match=r"save_database\(db, path\) first"):
        train(generate(load_world("square"), 5_000, seed=0), tmp_path / "unsaved", config)
    with pytest.raises(InputError, match=r"\(test split\): training reads a whole database file"):
        train(load_database(square_db_path).take("test"), tmp_path / "split", config)
    assert not (tmp_path / "unsaved").exists()
    assert not (tmp_path / "split").exists()


def _subnormal_survives() -> bool:
    return float(torch.tensor(1e-39) * 1.0) != 0.0  # 1e-39 is subnormal in float32


@pytest.mark.parametrize("path", ["stack", "autograd loop"])
def test_training_flushes_subnormals_and_restores_the_mode(
    path, square_db_path, tmp_path, monkeypatch
):
    during = []

    def record(*_):
        during.append(_subnormal_survives())

    config = TrainConfig(model="s", max_epochs=1)
    if path == "autograd loop":
        monkeypatch.setattr(train_mod, "computes_models_py", lambda model: False)
    train(square_db_path, tmp_path / "run", config, on_epoch=record)
    assert during == [False]  # flushed while training
    assert _subnormal_survives()  # and as before once it returns


def test_a_kill_between_checkpoint_and_best_weights_is_mended_on_resume(square_db_path, tmp_path):
    """The first epoch's checkpoint written, its model.pt not yet: resume writes the best
    weights from the checkpoint and goes on (a sweep killed there refused to resume)."""
    config = TrainConfig(model="sm", max_epochs=1)
    train(square_db_path, tmp_path / "a", config)
    (tmp_path / "a" / "model.pt").unlink()
    (tmp_path / "a" / "result.json").unlink()
    result = train(square_db_path, tmp_path / "a", config, resume=True)  # nothing left to train
    assert result.epochs == 1
    saved = torch.load(tmp_path / "a" / "model.pt", weights_only=True)
    kept = torch.load(tmp_path / "a" / "checkpoint.pt", weights_only=True)["model"]
    assert all(torch.equal(saved[k], kept[k]) for k in kept)
