"""Evaluation: the paper's error, the baselines, carried state, and Table I from several runs."""

from __future__ import annotations

import json
import re
import shutil
import statistics

import numpy as np
import pytest
import torch

import sensorimotor.learn.evaluate as ev
from conftest import assert_one_line_error
from sensorimotor.errors import InputError
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.evaluate import (
    baselines,
    encode,
    evaluate_run,
    load_run,
    prediction_error,
    run_model,
    split_tensors,
)
from sensorimotor.learn.models import build_model
from sensorimotor.learn.train import train
from sensorimotor.sim.core import SensorLayout
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.sim.world import load_world, world_from_dict


def test_error_sums_over_sensors_and_averages_over_steps():
    sensors = torch.zeros(4, 5)
    sensors[1:, 0] = 1.0  # s_1..s_3 have sensor 0 at 1
    pred = torch.zeros(4, 5)  # predicts 0 everywhere: each step misses by 1 on one sensor
    assert prediction_error(pred, sensors) == pytest.approx(1.0)  # not 1/5: a sum, not a mean
    pred[0, 0] = 1.0  # step 0 now right
    assert prediction_error(pred, sensors) == pytest.approx(2 / 3)


def test_splits_are_scaled_by_the_databases_own_range():
    layout = SensorLayout(max_range=20.0)
    db = generate(load_world("rooms1"), 3000, seed=0, layout=layout)
    sensors, motors = split_tensors(db, "train")
    assert torch.equal(sensors, torch.from_numpy(db.take("train").sensors / np.float32(20.0)))
    assert 0.5 < float(sensors.max()) <= 1.0  # readings beyond 10 exist and stay within [0, 1]
    assert motors.shape == (len(sensors), 2)


def test_baselines_on_a_real_database(square_db_path):
    db = load_database(square_db_path)
    s, _ = split_tensors(db, "test")
    b = baselines(db)
    assert b["copy_last"] == pytest.approx(float(((s[1:] - s[:-1]) ** 2).sum(-1).mean()), rel=1e-6)
    train_mean = split_tensors(db, "train")[0].mean(0)
    assert b["mean"] == pytest.approx(float(((s[1:] - train_mean) ** 2).sum(-1).mean()), rel=1e-6)
    assert 0 < b["copy_last"] < b["mean"]


@pytest.mark.parametrize("kind", ["rec-s", "rec-sm"])
def test_carrying_state_over_the_split_equals_chunks_of_20(kind, monkeypatch):
    model = build_model(kind, seed=0)
    s, m = torch.rand(1003, 5), torch.rand(1003, 2)
    whole_pred, whole_z = run_model(model, s, m)
    state, preds = None, []
    with torch.no_grad():
        for i in range(0, len(s), 20):
            p, _, state = model(s[None, i : i + 20], m[None, i : i + 20], state)
            preds.append(p[0])
    torch.testing.assert_close(torch.cat(preds), whole_pred, rtol=1e-5, atol=1e-6)
    monkeypatch.setattr(ev, "CHUNK", 7)  # run_model's own chunking does not change the numbers
    p7, z7 = run_model(model, s, m)
    torch.testing.assert_close(p7, whole_pred, rtol=1e-5, atol=1e-6)
    torch.testing.assert_close(z7, whole_z, rtol=1e-5, atol=1e-6)
    # and the state matters: restarting every 20 steps gives other predictions
    restarted = torch.cat(
        [model(s[None, i : i + 20], m[None, i : i + 20])[0][0] for i in range(0, 1003, 20)]
    )
    assert not torch.allclose(restarted, whole_pred, atol=1e-4)


@pytest.fixture(scope="module")
def two_seeds(square_db_path, tmp_path_factory):
    root = tmp_path_factory.mktemp("runs")
    for seed in (0, 1):
        train(square_db_path, root / f"sm{seed}", TrainConfig(model="sm", seed=seed, max_epochs=2))
    train(square_db_path, root / "s0", TrainConfig(model="s", seed=0, max_epochs=2))
    return root


def test_evaluate_cli_writes_the_documented_json(
    two_seeds, square_db_path, rooms1_db_path, tmp_path, cli
):
    out = tmp_path / "ev.json"
    proc = cli(
        "evaluate",
        two_seeds / "sm0",
        "--data",
        square_db_path,
        "--data",
        rooms1_db_path,
        "--json",
        out,
    )
    assert proc.returncode == 0, proc.stderr
    res = json.loads(out.read_text())
    assert res["model"] == "sm"
    assert res["trained_on"] == "square"
    assert set(res["errors"]) == {"square", "rooms1"}
    assert set(res["baselines"]["rooms1"]) == {"mean", "copy_last"}
    run, db = load_run(two_seeds / "sm0"), load_database(rooms1_db_path)
    s, m = split_tensors(db, "test")
    assert res["errors"]["rooms1"] == pytest.approx(ev.model_error(run.model, s, m))
    assert "square" in proc.stdout
    assert "copy-last" in proc.stdout


def test_table_gives_mean_and_sd_over_seeds(two_seeds, square_db_path, tmp_path, cli):
    out = tmp_path / "t.json"
    runs = [two_seeds / "sm0", two_seeds / "sm1", two_seeds / "s0"]
    proc = cli("table", *runs, "--data", square_db_path, "--json", out)
    assert proc.returncode == 0, proc.stderr
    t = json.loads(out.read_text())
    rows = {r["model"]: r for r in t["tables"]["square"]}
    assert set(rows) == {"s", "sm"}
    values = [r["errors"]["square"] for r in t["runs"] if r["model"] == "sm"]
    cell = rows["sm"]["cells"]["square"]
    assert cell["n"] == 2
    assert cell["mean"] == pytest.approx(statistics.mean(values))
    assert cell["sd"] == pytest.approx(statistics.stdev(values))
    assert values[0] != values[1]  # two seeds, two models
    assert rows["s"]["cells"]["square"]["sd"] == 0.0
    assert t["paper_ordering_holds"]["square"]["square"] is None  # rec models missing
    assert "0.005576" in proc.stdout  # the paper's SM value beside ours


def test_table_puts_the_papers_numbers_only_beside_the_papers_worlds(
    two_seeds, square_db_path, tmp_path, cli
):
    corridor = world_from_dict({"name": "corridor", "size": 50, "walls": [[20, 0, 20, 30]]})
    corridor_db = tmp_path / "corridor.npz"
    save_database(generate(corridor, 5_000, seed=0), corridor_db)
    proc = cli("table", two_seeds / "sm0", "--data", square_db_path, "--data", corridor_db)
    assert proc.returncode == 0, proc.stderr
    header = next(line for line in proc.stdout.splitlines() if "corridor" in line)
    columns = [c.strip() for c in header.split("┃")[2:-1]]
    assert columns == ["square", "paper", "corridor"]  # no empty paper column for corridor
    assert "0.005576" in proc.stdout


def test_table_refuses_a_seed_given_twice(two_seeds, square_db_path, tmp_path, cli):
    copy = tmp_path / "sm0_copy"
    shutil.copytree(two_seeds / "sm0", copy)
    proc = cli("table", two_seeds / "sm0", copy, "--data", square_db_path)
    assert_one_line_error(proc, "sm0_copy", "same world, model and seed")


def test_table_refuses_seeds_of_one_row_trained_otherwise(two_seeds, square_db_path, tmp_path, cli):
    train(square_db_path, tmp_path / "sm2", TrainConfig(model="sm", seed=2, max_epochs=1))
    proc = cli("table", two_seeds / "sm0", tmp_path / "sm2", "--data", square_db_path)
    assert_one_line_error(proc, "sm2", "other settings", "max_epochs: 2 -> 1")


def test_table_refuses_seeds_of_one_row_trained_on_other_data(two_seeds, tmp_path, cli):
    other = tmp_path / "square_seed9.npz"
    save_database(generate(load_world("square"), 20_000, seed=9), other)
    train(other, tmp_path / "sm2", TrainConfig(model="sm", seed=2, max_epochs=2))
    proc = cli("table", two_seeds / "sm0", tmp_path / "sm2", "--data", other)
    assert_one_line_error(proc, "sm2", "other settings", "data sha256")


def test_paper_ordering_needs_rec_sm_below_sm_below_both_others():
    from sensorimotor.analysis.tables import paper_ordering_holds

    assert paper_ordering_holds({"rec-sm": 1, "sm": 2, "rec-s": 3, "s": 4}) is True
    assert paper_ordering_holds({"rec-sm": 1, "sm": 2, "rec-s": 4, "s": 3}) is True
    assert paper_ordering_holds({"rec-sm": 1, "sm": 2, "rec-s": 1.5, "s": 3}) is False  # SM > Rec-S
    assert paper_ordering_holds({"rec-sm": 2.5, "sm": 2, "rec-s": 3, "s": 4}) is False
    assert paper_ordering_holds({"rec-sm": 1, "sm": 2, "s": 4}) is None


def fake_results(trained_on: str, errors: dict[str, list[float]]) -> list[dict]:
    """evaluate_run results: model -> one Square error per seed."""
    return [
        {"trained_on": trained_on, "model": m, "seed": i, "errors": {"square": e}}
        for m, values in errors.items()
        for i, e in enumerate(values)
    ]


def test_table_keeps_training_worlds_apart_and_orders_by_the_means():
    from sensorimotor.analysis.tables import fmt_cell, table_from_results

    # spread chosen so that the sds are in the opposite order of the means
    square = {"rec-sm": [1.0, 1.2], "sm": [2.0, 2.0], "rec-s": [3.0, 3.0], "s": [4.0, 4.0]}
    rooms1 = {m: [10 * v for v in values] for m, values in square.items()}
    t = table_from_results(
        fake_results("square", square) + fake_results("rooms1", rooms1), {}, ["square"]
    )
    cells = {
        tw: {r["model"]: r["cells"]["square"] for r in rows} for tw, rows in t["tables"].items()
    }
    assert cells["square"]["rec-sm"]["mean"] == pytest.approx(1.1)
    assert cells["rooms1"]["rec-sm"]["mean"] == pytest.approx(11.0)  # not pooled with Square's
    assert cells["square"]["rec-sm"]["values"] == [1.0, 1.2]
    assert t["paper_ordering_holds"]["square"]["square"] is True  # by means; the sds: 0.14 > 0
    assert fmt_cell(cells["square"]["rec-sm"]) == "1.10000 ± 0.14142"
    assert fmt_cell(cells["square"]["sm"], digits=2) == "2.00 ± 0.00"


def test_evaluate_prints_each_baseline_under_its_own_column(two_seeds, square_db_path, cli):
    proc = cli("evaluate", two_seeds / "sm0", "--data", square_db_path)
    assert proc.returncode == 0, proc.stderr
    b = baselines(load_database(square_db_path))
    row = next(
        line
        for line in proc.stdout.splitlines()
        if "square" in line and re.search(r"\d\.\d{5}", line)
    )
    assert re.findall(r"\d+\.\d{5}", row)[1:] == [f"{b['mean']:.5f}", f"{b['copy_last']:.5f}"]


def test_runs_and_databases_may_be_paths_or_loaded(two_seeds, square_db_path):
    run, db = load_run(two_seeds / "sm0"), load_database(square_db_path)
    z = encode(run, db)
    np.testing.assert_array_equal(encode(str(two_seeds / "sm0"), str(square_db_path)), z)
    assert evaluate_run(two_seeds / "sm0", square_db_path) == evaluate_run(run, [db])
    with pytest.raises(ValueError, match="unknown split 'testing': use one of train, val, test"):
        encode(run, db, "testing")


def test_errors_name_an_in_memory_database_by_its_world(two_seeds):
    db = generate(load_world("square"), 20_000, seed=3, layout=SensorLayout(max_range=20.0))
    with pytest.raises(
        InputError,
        match=r"^the in-memory database of square: recorded with 5 rays .* range 20; run .* "
        r"trained on 5 rays .* range 10$",
    ):
        encode(two_seeds / "sm0", db)


def test_a_recurrent_pass_runs_on_one_thread_and_gives_the_threads_back(monkeypatch):
    seen: list[int] = []
    model = build_model("rec-sm", seed=0)
    forward = model.forward
    monkeypatch.setattr(
        model, "forward", lambda *a: seen.append(torch.get_num_threads()) or forward(*a)
    )
    s, m = torch.rand(50, 5), torch.rand(50, 2) - 0.5
    before = torch.get_num_threads()
    torch.set_num_threads(2)
    try:
        _, z = run_model(model, s, m)
        assert torch.get_num_threads() == 2
    finally:
        torch.set_num_threads(before)
    assert seen == [1]
    assert z.shape == (50, 10)


def test_a_model_that_does_not_beat_copying_the_last_reading_is_flagged():
    from sensorimotor.learn.evaluate import baseline_warnings

    base = {"square": {"mean": 0.25, "copy_last": 0.07}, "rooms1": {"mean": 0.4, "copy_last": 0.1}}
    lines = baseline_warnings("run", {"square": 0.77, "rooms1": 0.02}, base)
    assert len(lines) == 1
    assert lines[0].startswith("run on square: test error 0.77000 is not below copying")
    assert "11.0 times it" in lines[0]
    assert baseline_warnings("run", {"square": 0.069}, base) == []
