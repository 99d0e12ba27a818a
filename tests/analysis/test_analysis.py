"""Scores on synthetic representations whose answer is known, the whole analysis on raw readings,
and the figures' panels and arrows."""

from __future__ import annotations

import json

import numpy as np
import pytest
from matplotlib.quiver import Quiver

from conftest import assert_one_line_error
from sensorimotor import analysis as an
from sensorimotor.analysis.plots import plot_clusters, plot_pca, plot_transfer
from sensorimotor.analysis.probes import KNN_K
from sensorimotor.errors import InputError
from sensorimotor.sim import events as ev
from sensorimotor.sim.core import SensorLayout, read_sensors
from sensorimotor.sim.database import generate, load_database, save_database
from sensorimotor.sim.world import load_world


@pytest.fixture(scope="module")
def square_test(square_db_path):
    db = load_database(square_db_path)
    return db.world, db.take("test")


def rare_event(n=5000, rate=0.05, seed=0):
    return np.random.default_rng(seed).random(n) < rate


# ---------------------------------------------------------------------------------------------
# Events against clusters


def test_event_scores_by_hand():
    labels = np.array([0, 0, 1, 1, 1, 2])
    event = np.array([1, 0, 1, 1, 0, 0], bool)
    # cluster 0: P 1/2, R 1/3, F1 0.4; cluster 1: P 2/3, R 2/3, F1 2/3; cluster 2: 0
    got = an.event_scores(labels, event)
    assert got["cluster"] == 1
    assert got["precision"] == pytest.approx(2 / 3)
    assert got["recall"] == pytest.approx(2 / 3)
    assert got["f1"] == pytest.approx(2 / 3)
    assert got["count"] == 3
    assert got["rate"] == pytest.approx(0.5)


def test_a_representation_equal_to_the_event_gives_f1_one():
    event = rare_event()
    noise = np.random.default_rng(1).normal(0, 0.01, len(event))
    z = np.column_stack([event.astype(float), noise])
    labels = an.assign_clusters(an.fit_kmeans(z, k=2, seed=0), z)
    got = an.event_scores(labels, event)
    assert got["f1"] == pytest.approx(1.0)
    assert got["precision"] == pytest.approx(1.0)
    assert got["recall"] == pytest.approx(1.0)


def test_random_clusters_give_a_low_f1():
    event = rare_event()
    z = np.random.default_rng(2).normal(size=(len(event), 10))
    labels = an.assign_clusters(an.fit_kmeans(z, k=20, seed=0), z)
    assert an.event_scores(labels, event)["f1"] < 0.15


def test_an_event_that_never_occurs():
    got = an.event_scores(np.arange(10) % 3, np.zeros(10, bool))
    assert got["cluster"] is None
    assert got["f1"] == 0.0
    assert got["count"] == 0


# ---------------------------------------------------------------------------------------------
# Probes


def test_probe_finds_a_target_the_representation_contains():
    rng = np.random.default_rng(0)
    behind = rng.uniform(0, 50, 4000)
    z = np.column_stack([rng.normal(size=4000), 0.1 * behind + rng.normal(0, 0.01, 4000)])
    assert an.probe_r2(z, behind, seed=0) > 0.99


def test_probe_on_a_random_representation_scores_about_zero():
    rng = np.random.default_rng(0)
    behind = rng.uniform(0, 50, 4000)
    z = rng.normal(size=(4000, 10))
    assert an.probe_r2(z, behind, seed=0) < 0.02


def test_memory_scores_use_only_the_steps_with_nothing_in_view():
    rng = np.random.default_rng(0)
    n = 6000
    nothing = rng.random(n) < 0.5
    behind = rng.uniform(0, 50, n)
    # z knows the distance behind only while nothing is in view
    z = np.where(nothing, behind, rng.uniform(0, 50, n))[:, None]
    labels = nothing.astype(int)
    got = an.memory_scores(z, labels, nothing, behind, seed=0)
    assert got["distance_behind_r2"] > 0.99
    assert got["nothing_clusters"] == 1
    assert got["nothing_cluster_ids"] == [1]
    assert got["n_nothing"] == int(nothing.sum())
    blind = an.memory_scores(rng.normal(size=(n, 3)), labels, nothing, behind, seed=0)
    assert blind["distance_behind_r2"] < 0.02


def test_position_scores_and_knn_mse():
    rng = np.random.default_rng(0)
    n = 3000
    poses = np.column_stack([rng.uniform(0, 50, n), rng.uniform(0, 50, n), rng.uniform(-3, 3, n)])
    exact = np.column_stack([poses[:, 0], poses[:, 1], np.cos(poses[:, 2]), np.sin(poses[:, 2])])
    got = an.position_scores(exact, poses, seed=0, world_size=(50, 50))
    for key in ("r2_x", "r2_y", "r2_cos_heading", "r2_sin_heading"):
        assert got[key] > 0.99, key
    assert got["knn_mse"] < 0.005
    assert got["knn_mse_chance"] == pytest.approx(1 / 3, rel=0.1)  # uniform in the unit square
    blind = an.position_scores(rng.normal(size=(n, 10)), poses, seed=0, world_size=(50, 50))
    assert blind["r2_x"] < 0.02
    assert blind["knn_mse"] == pytest.approx(blind["knn_mse_chance"], rel=0.1)


def _knn_sq_brute(z: np.ndarray, q: np.ndarray, k: int) -> np.ndarray:
    """Reference: each step's k nearest by full distance sort, the candidates at the distance
    where the k places run out each counted (places left) / (candidates)."""
    out = np.zeros(len(z))
    for i in range(len(z)):
        d = np.sqrt(((z - z[i]) ** 2).sum(axis=1))
        d[i] = np.inf
        cost = ((q - q[i]) ** 2).sum(axis=1)
        left = k
        for level in np.unique(d[np.isfinite(d)]):
            at = d == level
            take = min(left, at.sum())
            out[i] += take * cost[at].mean()
            left -= take
            if not left:
                break
    return out


def test_knn_mse_matches_a_brute_force_search_and_averages_identical_points():
    rng = np.random.default_rng(1)
    z = rng.normal(size=(120, 3))
    z[40:90] = z[40]  # 50 identical points, and pairs below
    z[100:110] = z[90:100]
    q = rng.uniform(0, 1, (120, 2))
    for k in (1, 5):
        got = an.knn_mse(z, q, (1, 1), k=k)["knn_mse"]
        assert got == pytest.approx(_knn_sq_brute(z, q, k).mean() / k, rel=1e-12)
    # identical points scattered in space: their neighbours are nowhere in particular, however
    # close in time (index) they lie
    z = np.zeros((400, 2))
    z[:50] = rng.normal(size=(50, 2))
    q = np.column_stack([np.linspace(0, 1, 400), np.zeros(400)])
    got = an.knn_mse(z, q, (1, 1))
    assert got["knn_mse"] == pytest.approx(_knn_sq_brute(z, q, KNN_K).mean() / KNN_K, rel=1e-12)
    assert got["knn_mse"] > 0.5 * got["chance"]


def test_knn_mse_subsamples_large_inputs():
    rng = np.random.default_rng(0)
    z = rng.normal(size=(500, 2))
    got = an.knn_mse(z, rng.uniform(0, 10, (500, 2)), (10, 10), max_points=200)
    assert got["points"] == 200


# ---------------------------------------------------------------------------------------------
# Determinism


def test_kmeans_and_pca_are_deterministic_for_a_seed():
    z = np.random.default_rng(0).normal(size=(3000, 10))
    a, b = an.fit_kmeans(z, seed=3), an.fit_kmeans(z, seed=3)
    np.testing.assert_array_equal(a.cluster_centers_, b.cluster_centers_)
    np.testing.assert_array_equal(an.assign_clusters(a, z), an.assign_clusters(b, z))
    np.testing.assert_array_equal(an.pca_2d(z, seed=3), an.pca_2d(z, seed=3))
    assert an.pca_2d(z).shape == (3000, 2)
    assert an.pca_2d(z[:, :1]).shape == (3000, 2)  # a 1-d representation is padded


def test_assign_refuses_another_dimension():
    km = an.fit_kmeans(np.random.default_rng(0).normal(size=(100, 4)), k=3)
    with pytest.raises(ValueError, match="4-d"):
        an.assign_clusters(km, np.zeros((5, 3)))


# ---------------------------------------------------------------------------------------------
# The whole analysis on raw readings, and transfer


def test_analyze_raw_readings(square_test):
    world, part = square_test
    z = an.scaled_readings(part.sensors)
    res = an.analyze_representation(z, part.sensors, part.poses, world, seed=0)
    m = json.loads(json.dumps(res.metrics))  # JSON-ready
    assert m["n_steps"] == len(part) == len(res.labels) == len(res.pc)
    assert m["k"] == 20
    assert len(m["clusters"]) == 20
    assert set(m["events"]) == {"corner", "nothing"}  # square has no free wall end
    assert sum(c["size"] for c in m["clusters"]) == len(part)
    # raw readings put every "nothing in view" step at one point: one cluster holds them all
    assert m["events"]["nothing"]["recall"] == pytest.approx(1.0)
    assert m["events"]["nothing"]["f1"] > 0.8
    assert m["memory"]["nothing_clusters"] == 1
    assert m["memory"]["distance_behind_r2"] < 0.05  # no memory in raw readings
    assert m["position"]["r2_x"] < 0.1
    assert len(res.cluster_titles()) == 20


def test_transfer_applies_clusters_fitted_on_another_world(square_test, rooms1_db_path):
    world, part = square_test
    source = an.analyze_representation(
        an.scaled_readings(part.sensors), part.sensors, part.poses, world, seed=0
    )
    rooms1 = load_database(rooms1_db_path)
    target = rooms1.take("test")
    z = an.scaled_readings(target.sensors)
    res = an.analyze_representation(
        z, target.sensors, target.poses, rooms1.world, kmeans=source.kmeans, pca=source.pca
    )
    assert res.metrics["transfer"] is True
    assert res.kmeans is source.kmeans
    assert "wall_end" in res.metrics["events"]
    np.testing.assert_array_equal(res.labels, source.kmeans.predict(z.astype(np.float64)))


# ---------------------------------------------------------------------------------------------
# Figures


def quivers(ax):
    return [c for c in ax.collections if isinstance(c, Quiver)]


def test_cluster_figure_has_one_panel_per_cluster_and_500_arrows_at_most(square_test):
    world, part = square_test
    labels = np.random.default_rng(0).integers(0, 20, len(part))
    labels[labels == 7] = 6  # an empty cluster draws an empty panel
    fig = plot_clusters(world, part.poses, labels, n_arrows=50, titles=[f"c{i}" for i in range(20)])
    axes = fig.axes
    assert len(axes) == 20
    for c, ax in enumerate(axes):
        (q,) = quivers(ax)
        assert min(50, int((labels == c).sum())) == q.N
        assert ax.get_title() == f"c{c}"
        assert any(line.get_gid() == "wall" for line in ax.lines)
    assert quivers(axes[7])[0].N == 0


def test_cluster_figure_of_a_few_clusters_and_transfer(square_test):
    world, part = square_test
    labels = np.arange(len(part)) % 20
    fig = plot_transfer(world, part.poses, labels, source="rooms1", clusters=[3, 5, 9])
    assert len(fig.axes) == 3
    assert "rooms1" in fig.get_suptitle()
    assert [quivers(ax)[0].N for ax in fig.axes] == [100, 100, 100]
    fig = plot_clusters(world, part.poses, labels, clusters=range(7))
    assert len(fig.axes) == 10  # 2 x 5 grid
    assert sum(ax.axison for ax in fig.axes) == 7


def test_a_transferred_cluster_that_no_step_falls_in_keeps_its_panel(square_test):
    world, part = square_test
    labels = np.arange(len(part)) % 18  # clusters 18 and 19 of 20 get no step of this world
    titles = [f"#{c}" for c in range(20)]
    fig = plot_transfer(world, part.poses, labels, source="rooms1", titles=titles)
    assert [ax.get_title() for ax in fig.axes] == titles
    drawn = [quivers(ax)[0].N if quivers(ax) else 0 for ax in fig.axes[-3:]]
    assert drawn == [(labels == 17).sum(), 0, 0]


def test_pca_figure(square_test):
    _, part = square_test
    pc = an.pca_2d(an.scaled_readings(part.sensors))
    ax = plot_pca(pc, part.sensors.min(axis=1))
    assert len(ax.figure.axes) == 2  # the map and its colour bar
    (points,) = [c for c in ax.collections if c.get_gid() == "pca"]
    assert len(points.get_offsets()) == len(part)
    assert len(plot_pca(pc, part.sensors.min(axis=1), colorbar=False).figure.axes) == 1


# ---------------------------------------------------------------------------------------------
# The `analyze` command


def test_cli_analyze_raw_writes_figures_and_metrics(cli, square_db_path, tmp_path):
    out = tmp_path / "raw_square"
    proc = cli("analyze", "raw", "--data", square_db_path, "--out", out)
    assert proc.returncode == 0, proc.stderr
    assert "corner in view" in proc.stdout
    assert "KNN-MSE" in proc.stdout
    assert sorted(p.name for p in out.iterdir()) == [
        "clusters.png",
        "clusters.svg",
        "metrics.json",
        "pca.npz",
        "pca.png",
        "pca.svg",
    ]
    assert (out / "clusters.svg").read_text().lstrip().startswith("<?xml")
    m = json.loads((out / "metrics.json").read_text())
    assert m["run"] == "raw"
    assert m["fit_analysis"] is None
    assert m["analysis"]["n_steps"] == len(load_database(square_db_path).take("test"))
    assert m["analysis"]["world"] == "square"


def test_analyze_transfer_fits_on_one_world_and_applies_to_another(
    square_db_path, rooms1_db_path, tmp_path
):
    res = an.analyze_files("raw", rooms1_db_path, tmp_path / "t", fit_data=square_db_path)
    names = sorted(p.name for p in (tmp_path / "t").iterdir())
    assert names == ["clusters.png", "clusters_fit.png", "metrics.json", "pca.npz", "pca.png"]
    m = res.metrics
    assert m["fit_analysis"]["world"] == "square"
    assert not m["fit_analysis"]["transfer"]
    assert m["analysis"]["world"] == "rooms1"
    assert m["analysis"]["transfer"]
    assert "wall_end" in m["analysis"]["events"]


def test_an_analysis_into_a_used_folder_leaves_none_of_the_earlier_files(
    square_db_path, rooms1_db_path, tmp_path
):
    out = tmp_path / "t"
    an.analyze_files("raw", rooms1_db_path, out, fit_data=square_db_path, svg=True)
    assert (out / "clusters_fit.svg").exists()
    res = an.analyze_files("raw", square_db_path, out)
    names = sorted(p.name for p in out.iterdir())
    assert names == ["clusters.png", "metrics.json", "pca.npz", "pca.png"]
    assert sorted(p.name for p in res.files) == names


def test_cli_analyze_passes_its_seed(square_db_path, tmp_path, cli):
    args = ("--data", square_db_path, "--out", tmp_path / "cli", "--seed", "3", "--no-svg")
    proc = cli("analyze", "raw", *args)
    assert proc.returncode == 0, proc.stderr
    an.analyze_files("raw", square_db_path, tmp_path / "lib3", seed=3)
    an.analyze_files("raw", square_db_path, tmp_path / "lib0", seed=0)
    labels = {
        d: np.load(tmp_path / d / "pca.npz", allow_pickle=False)["labels"]
        for d in ("cli", "lib3", "lib0")
    }
    assert not np.array_equal(labels["lib3"], labels["lib0"])  # the seed matters here
    np.testing.assert_array_equal(labels["cli"], labels["lib3"])


def test_cli_analyze_bad_input_is_one_line(cli, tmp_path):
    missing = tmp_path / "nope.npz"
    proc = cli("analyze", "raw", "--data", missing, "--out", tmp_path / "o")
    assert_one_line_error(proc, str(missing))


def test_analyze_refuses_bad_input_naming_the_file(square_db_path, tmp_path):
    with pytest.raises(InputError, match="no_run"):
        an.analyze_files(tmp_path / "no_run", square_db_path, tmp_path / "o")
    tiny = tmp_path / "tiny.npz"
    save_database(generate(load_world("square"), 150, seed=0), tiny)  # a 15-step test split
    with pytest.raises(InputError, match=f"{tiny}.*at least 20"):
        an.analyze_files("raw", tiny, tmp_path / "o")
    a_file = tmp_path / "file"
    a_file.write_text("")
    with pytest.raises(InputError, match=str(a_file)):
        an.analyze_files("raw", square_db_path, a_file)
    with pytest.raises(InputError, match="not found"):
        an.analyze_files("raw", square_db_path, tmp_path / "o", fit_data=tmp_path / "x.npz")


def test_an_output_in_the_way_is_found_before_anything_is_written(square_db_path, tmp_path):
    out = tmp_path / "o"
    (out / "metrics.json").mkdir(parents=True)
    with pytest.raises(InputError, match=r"metrics\.json: is a folder"):
        an.analyze_files("raw", square_db_path, out)
    assert [p.name for p in out.iterdir()] == ["metrics.json"]


def test_events_are_those_the_databases_own_lasers_see(tmp_path):
    world = load_world("rooms1")
    layout = SensorLayout(angles=(-1.5, -0.75, 0.0, 0.75, 1.5), max_range=12.0)
    path = tmp_path / "wide.npz"
    save_database(generate(world, 20_000, seed=2, layout=layout), path)
    events = an.analyze_files("raw", path, tmp_path / "o").metrics["analysis"]["events"]
    test = load_database(path).take("test")
    for name, in_view in (("corner", ev.corner_in_view), ("wall_end", ev.wall_end_in_view)):
        assert events[name]["count"] == in_view(world, test.poses, layout).sum() > 0
        assert events[name]["count"] > in_view(world, test.poses).sum()  # more than the paper's see
    assert events["nothing"]["count"] == ev.nothing_in_view(test.sensors, 12.0).sum()


def test_analyze_refuses_clusters_fitted_on_another_sensor_layout(square_db_path, tmp_path):
    other = tmp_path / "wide.npz"
    wide = SensorLayout((-1.0, -0.5, 0.0, 0.5, 1.0), 10.0)
    save_database(generate(load_world("square"), 5_000, seed=0, layout=wide), other)
    with pytest.raises(InputError, match="sensor layout"):
        an.analyze_files("raw", square_db_path, tmp_path / "o", fit_data=other)


def test_nothing_in_view_is_the_truth_on_noisy_data(tmp_path):
    world = load_world("square")
    path = tmp_path / "noisy.npz"
    save_database(generate(world, 20_000, seed=3, noise_std=0.5), path)
    events = an.analyze_files("raw", path, tmp_path / "o").metrics["analysis"]["events"]
    db = load_database(path)
    test = db.take("test")
    truth = ev.nothing_in_view(read_sensors(world, test.poses, db.layout)).sum()
    assert events["nothing"]["count"] == truth
    assert ev.nothing_in_view(test.sensors).sum() != truth  # the noisy readings would differ


def test_best_cluster_is_chosen_by_f1_not_by_precision():
    # cluster 0: one step, an event (precision 1, F1 0.18); cluster 1: 9 of 10 (F1 0.9)
    labels = np.array([0] + [1] * 10 + [2] * 10)
    event = np.array([1] + [1] * 9 + [0] + [0] * 10, bool)
    got = an.event_scores(labels, event)
    assert got["cluster"] == 1
    assert got["f1"] == pytest.approx(0.9)


def test_a_probe_is_scored_on_steps_it_was_not_fitted_on():
    # 80 random features for 200 steps: a fit scored on its own steps would reach R^2 ~ 0.8
    rng = np.random.default_rng(0)
    z, target = rng.normal(size=(200, 80)), rng.normal(size=200)
    assert an.probe_r2(z, target, seed=0) < 0.1


def test_heading_probes_are_not_swapped():
    rng = np.random.default_rng(0)
    poses = np.column_stack([rng.uniform(1, 49, (4000, 2)), rng.uniform(-np.pi, np.pi, 4000)])
    z = np.column_stack([np.cos(poses[:, 2]), rng.normal(size=4000)])  # knows cos only
    got = an.position_scores(z, poses, seed=0)
    assert got["r2_cos_heading"] > 0.99
    assert got["r2_sin_heading"] < 0.1


def test_the_analysis_refuses_readings_that_are_not_the_layouts(square_test):
    world, part = square_test
    z = an.scaled_readings(part.sensors)
    with pytest.raises(ValueError, match=r"sensors must be \(N, 5\)"):
        an.analyze_representation(z, part.sensors[:, :4], part.poses, world)
    with pytest.raises(ValueError, match="poses \\(N, 3\\)"):
        an.analyze_representation(z, part.sensors, part.poses[:, :2], world)


def test_the_corner_probe_reads_a_linear_code_and_ignores_noise():
    from sensorimotor.analysis.probes import probe_auc

    rng = np.random.default_rng(0)
    event = rng.random(4000) < 0.05
    coded = np.c_[event + 0.3 * rng.standard_normal(4000), rng.standard_normal((4000, 3))]
    noise = rng.standard_normal((4000, 4))
    assert probe_auc(coded, event) > 0.95
    assert abs(probe_auc(noise, event) - 0.5) < 0.1
    assert probe_auc(noise, np.zeros(4000, dtype=bool)) is None  # one class: no AUC


def test_a_recurrent_analysis_leaves_out_the_burn_in_and_a_memoryless_one_does_not(
    square_db_path, tmp_path
):
    """The first BURN_IN test steps of a recurrent model come from the zero state: left out of
    the clusters, the events and the figures, and said in metrics.json."""
    from sensorimotor.analysis.analyze import burn_in
    from sensorimotor.analysis.probes import BURN_IN
    from sensorimotor.learn.config import TrainConfig
    from sensorimotor.learn.evaluate import load_run
    from sensorimotor.learn.train import train

    test_steps = len(load_database(square_db_path).take("test"))
    for kind, expected in (("rec-s", BURN_IN), ("s", 0)):
        run = tmp_path / kind
        train(square_db_path, run, TrainConfig(model=kind, seed=0, max_epochs=1, threads=1))
        an.analyze_files(run, square_db_path, tmp_path / f"an_{kind}")
        metrics = json.loads((tmp_path / f"an_{kind}" / "metrics.json").read_text())
        assert metrics["burn_in"] == expected
        assert metrics["analysis"]["n_steps"] == test_steps - expected
        with np.load(tmp_path / f"an_{kind}" / "pca.npz", allow_pickle=False) as z:
            assert len(z["labels"]) == len(z["min_reading"]) == test_steps - expected
    rec = load_run(tmp_path / "rec-s")
    assert burn_in(rec, BURN_IN + 19) == 0  # too short to leave any out: all of it is analysed
    assert burn_in(rec, BURN_IN + 20) == BURN_IN
    assert burn_in("raw", 10_000) == 0
