"""Place probes: what a representation tells of the room and the position, fitted on one split
and scored on another after a burn-in."""

from __future__ import annotations

import json

import numpy as np
import pytest

from sensorimotor.analysis import analyze_files
from sensorimotor.analysis.probes import place_probes
from sensorimotor.sim.world import load_world


def _walk(n: int, seed: int):
    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.uniform(0, 50, n), rng.uniform(0, 50, n), rng.uniform(-3, 3, n)])
    world = load_world("rooms1")
    return poses, world.room_index(poses[:, 0], poses[:, 1])


def test_a_representation_that_holds_the_place_scores_the_ceiling_and_noise_scores_chance():
    (pf, rf), (p, r) = _walk(3000, 0), _walk(1000, 1)
    onehot = lambda rooms: np.eye(4)[rooms + 1]  # noqa: E731 (outside every room: a 4th column)
    rng = np.random.default_rng(2)
    knows = place_probes(
        np.column_stack([pf[:, :2], onehot(rf)]),
        pf,
        np.column_stack([p[:, :2], onehot(r)]),
        p,
        rf,
        r,
    )
    assert knows["room"]["balanced_accuracy"] == pytest.approx(1.0)
    assert knows["room"]["chance"] == pytest.approx(1 / 3)
    assert min(knows["position"]["r2"].values()) > 0.99
    assert knows["position"]["median_error"] < 0.5
    assert knows["knn_mse"]["value"] < 0.01 * knows["knn_mse"]["chance"]
    assert (knows["burn_in"], knows["scored_steps"], knows["fit_steps"]) == (200, 800, 2800)
    noise = place_probes(rng.normal(size=(3000, 10)), pf, rng.normal(size=(1000, 10)), p, rf, r)
    assert noise["room"]["balanced_accuracy"] < 0.45
    assert max(noise["position"]["r2"].values()) < 0.05
    assert noise["position"]["median_error"] > 10
    assert place_probes(pf, pf, p, p)["room"] is None  # a world without rooms
    with pytest.raises(ValueError, match="too few steps"):
        place_probes(pf[:100], pf[:100], p, p)


def test_analyze_writes_the_place_probes_into_metrics(rooms1_db_path, square_db_path, tmp_path):
    for data, rooms in ((rooms1_db_path, True), (square_db_path, False)):
        analyze_files("raw", data, tmp_path / data.stem)
        probes = json.loads((tmp_path / data.stem / "metrics.json").read_text())["probes"]
        assert (probes["room"] is not None) == rooms
        if rooms:
            assert 0 <= probes["room"]["balanced_accuracy"] <= 1
        assert set(probes["position"]["r2"]) == {"x", "y"}
        assert probes["position"]["median_error"] > 0


def test_analyze_prints_the_place_probes(rooms1_db_path, tmp_path):
    from conftest import run_cli

    proc = run_cli("analyze", "raw", "--data", rooms1_db_path, "--out", tmp_path / "a")
    assert proc.returncode == 0, proc.stderr
    text = " ".join(proc.stdout.split())
    assert "place probes (fitted on" in text
    assert "balanced accuracy (chance 0.333)" in text


def test_the_event_probe_fitted_on_one_split_reads_a_linear_code_on_another():
    from sensorimotor.analysis.probes import probe_auc

    rng = np.random.default_rng(1)

    def split(n: int, coded: bool):
        event = rng.random(n) < 0.1  # "a corner in view", rare as in the worlds
        signal = event + 0.3 * rng.standard_normal(n) if coded else rng.standard_normal(n)
        return np.c_[signal, rng.standard_normal((n, 7))], event

    (z_fit, e_fit), (z, e) = split(3000, True), split(1000, True)
    assert probe_auc(z, e, fit=(z_fit, e_fit)) > 0.95  # linearly decodable: near 1
    (z_fit, e_fit), (z, e) = split(3000, False), split(1000, False)
    assert abs(probe_auc(z, e, fit=(z_fit, e_fit)) - 0.5) < 0.08  # not decodable: near chance
    assert probe_auc(z, np.zeros(1000, dtype=bool), fit=(z_fit, e_fit)) is None  # one class
    with pytest.raises(ValueError, match="do not match"):
        probe_auc(z, e, fit=(z_fit[:, :3], e_fit))


def test_an_analysis_fits_its_event_probes_on_the_training_split(square_db_path, tmp_path):
    plain = analyze_files("raw", square_db_path, tmp_path / "a", probes=False)
    split = analyze_files("raw", square_db_path, tmp_path / "b", probes=False, event_probes=True)
    a, b = plain.metrics["analysis"]["events"], split.metrics["analysis"]["events"]
    assert {e["probe_fit"] for e in a.values()} == {"half of the steps"}
    assert {e["probe_fit"] for e in b.values()} == {"train split"}
    assert b["corner"]["probe_auc"] is not None
    assert 0.5 < b["corner"]["probe_auc"] <= 1.0  # the raw readings tell a corner, linearly
    assert a["corner"]["f1"] == b["corner"]["f1"]  # the clusters are the same
