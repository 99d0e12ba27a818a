"""Stacked training: K seeds of S and SM at once give, bit for bit, what each seed gives alone
in a stack of one, down to early stopping, run folders and resume; and, to float32 rounding,
what the reference loop of train.py (nn.Module, autograd, FusedAdam) gives. The recurrent
models' own LSTM is tested in test_stacked_lstm.py."""

from __future__ import annotations

import json

import pytest
import torch

import sensorimotor.learn.fast.check as check
import sensorimotor.learn.models as models_mod
import sensorimotor.learn.train as train_mod
from conftest import assert_one_line_error
from sensorimotor.errors import InputError
from sensorimotor.learn.batches import epoch_generator
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import train_epoch_feedforward
from sensorimotor.learn.evaluate import load_run, model_error, split_tensors
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.fast.stacked import StackedEncoders, train_epoch_stacked
from sensorimotor.learn.models import KINDS, ModelConfig, build_model, paper_kinds
from sensorimotor.learn.runs import run_name
from sensorimotor.learn.train import train, train_runs, train_seeds
from sensorimotor.sim.database import load_database

pytestmark = pytest.mark.usefixtures("one_thread")

STACKED = paper_kinds()  # the kinds the stacked passes compute


def _equal(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def _close(a: dict | list, b: dict | list, tol: float = 1e-5) -> bool:
    """Tensors that agree to float32 rounding grown over training, relative to the largest
    element of b: 99 % within tol, none further than 1e-2 (Adam can move a weight whose
    gradient is nearly zero by up to its learning rate, 1e-3, a step)."""
    if isinstance(a, dict):
        if a.keys() != b.keys():
            return False
        a, b = list(a.values()), [b[k] for k in a]
    gap = torch.cat([(x - y).abs().flatten() for x, y in zip(a, b, strict=True)])
    scale = max(float(torch.cat([y.abs().flatten() for y in b]).max()), 1e-30)
    return float(gap.quantile(0.99)) < tol * scale and float(gap.max()) < 1e-2 * scale


# --- the hand-written backward pass and one epoch ------------------------------------------


@pytest.mark.parametrize("kind", ["s", "sm"])
@pytest.mark.parametrize("batch", [64, 37])  # 37: the last, partial batch of an epoch
def test_gradients_equal_autograd(kind, batch):
    seeds = [3, 1, 4]
    models = [build_model(kind, seed=sd) for sd in seeds]
    net = StackedEncoders.from_models(models)
    g = torch.Generator().manual_seed(0)
    xs, xm, y = (torch.rand(3, batch, d, generator=g) for d in (5, 2, 5))
    sq_sum = torch.zeros(3, 1, 1)
    with torch.no_grad():
        net.forward_backward(xs, xm if kind == "sm" else None, y, sq_sum)
    for k, model in enumerate(models):
        pred, _, _ = model(xs[k], xm[k])
        loss = ((pred - y[k]) ** 2).sum(-1).mean()
        loss.backward()
        mine = net._per_seed(net.grads, k)
        for (name, p), gk in zip(model.named_parameters(), mine, strict=True):
            # the products run in other orientations than autograd's (stacked.matmul)
            assert (gk - p.grad).abs().max() <= 1e-6 * p.grad.abs().max(), name
        assert torch.allclose(sq_sum[k, 0, 0] / batch, loss.detach(), rtol=1e-6)


@pytest.mark.parametrize("kind", ["s", "sm"])
def test_stacked_epochs_agree_with_the_plain_loop_and_do_not_depend_on_the_stack(kind):
    g = torch.Generator().manual_seed(1)
    n = 64 * 40 + 37  # a partial last batch
    s, m = torch.rand(n + 1, 5, generator=g), torch.rand(n + 1, 2, generator=g)
    seeds = [5, 2, 7]

    def stacked(order):
        net = StackedEncoders.from_models([build_model(kind, seed=sd) for sd in order])
        errors = [train_epoch_stacked(net, s, m, order, e, 64) for e in range(3)]
        return net, torch.stack(errors)  # (epochs, K)

    net, errors = stacked(seeds)
    for k, sd in enumerate(seeds):
        model = build_model(kind, seed=sd)
        opt = FusedAdam(model.parameters())
        plain = [
            train_epoch_feedforward(model, opt, s, m, 64, epoch_generator(sd, e)) for e in range(3)
        ]
        alone = net.load_into(k, build_model(kind))
        assert _close(model.state_dict(), alone.state_dict())
        state = net.optimizer_state(k)
        assert state["steps"] == opt.steps
        assert _close(state["exp_avg"], opt.exp_avg)
        assert _close(state["exp_avg_sq"], opt.exp_avg_sq)
        assert torch.allclose(
            errors[:, k].double(), torch.tensor(plain, dtype=torch.float64), rtol=1e-4
        )
    # each seed alone, and the stack in another order: the same numbers
    for k, sd in enumerate(seeds):
        net1, _ = stacked([sd])
        assert all(torch.equal(a[k], b[0]) for a, b in zip(net.params, net1.params, strict=True))
    net2, _ = stacked(seeds[::-1])
    assert all(torch.equal(a, b.flip(0)) for a, b in zip(net.params, net2.params, strict=True))


@pytest.fixture
def relu_edited_to_tanh(monkeypatch):
    """models.py as a user might edit it: every ReLU a Tanh (which the stack does not know)."""
    check.computes_models_py.cache_clear()
    monkeypatch.setattr(torch.nn, "ReLU", torch.nn.Tanh)
    yield
    check.computes_models_py.cache_clear()


def test_the_stack_computes_what_models_py_computes():
    assert all(check.computes_models_py(kind) for kind in STACKED)
    assert train_mod.trains_stacked("sm", "cpu")
    # a memory that reads the commands, with its open-loop head: fast.stacked_open_loop
    assert all(check.computes_models_py(k) for k in KINDS if KINDS[k].motor_memory)


def test_other_sizes_and_the_ablation_train_stacked_once_checked(
    square_db_path, tmp_path, monkeypatch
):
    configs = [
        ModelConfig("sm", z_sensors=6, ff_hidden=(8, 16)),
        ModelConfig("rec-sm", lstm_size=12, lstm_layers=2),
        ModelConfig("rec-sma", memory_motors=False),  # the ablation: zeros into the memory
    ]
    assert all(train_mod.trains_stacked(c, "cpu") for c in configs)
    engines = []
    epochs = train_mod._epochs
    monkeypatch.setattr(
        train_mod, "_epochs", lambda *a: engines.append(a[3].__name__) or epochs(*a)
    )
    config = TrainConfig(model="sm", max_epochs=1)
    train_runs(square_db_path, [(0, tmp_path / "a")], config, model=configs[0])
    assert engines == ["StackedEngine"]
    assert load_run(tmp_path / "a").model.config.z_sensors == 6


def test_a_model_edited_in_models_py_trains_as_edited_with_autograd(
    relu_edited_to_tanh, square_db_path, tmp_path
):
    assert not any(check.computes_models_py(kind) for kind in STACKED)
    assert not train_mod.trains_stacked("sm", "cpu")
    config = TrainConfig(model="sm", max_epochs=1)
    (result,) = train_seeds(square_db_path, tmp_path, config, seeds=[0])
    # the same epoch by hand, autograd through the edited module: the weights saved
    model = build_model("sm", seed=0)
    s, m = split_tensors(load_database(square_db_path), "train")
    train_epoch_feedforward(model, FusedAdam(model.parameters()), s, m, 64, epoch_generator(0, 0))
    assert _equal(load_run(result.run_dir).model.state_dict(), model.state_dict())
    # the one loop chooses the autograd engine for it, whichever way it is called
    (again,) = train_runs(square_db_path, [(0, tmp_path / "again")], config)
    assert _equal(load_run(again.run_dir).model.state_dict(), model.state_dict())


def _clipped_relu(monkeypatch):
    """ReLU capped at 2: the layers' types pass, a fresh model on the data's range agrees."""
    monkeypatch.setattr(check, "_known_layers", lambda module: True)
    monkeypatch.setattr(torch.nn, "ReLU", lambda: torch.nn.Hardtanh(0.0, 2.0))


def _state_ignored(monkeypatch):
    """A recurrent encoder that starts every chunk from zero: one chunk alone agrees."""
    encode = models_mod.SensorimotorEncoder.encode
    monkeypatch.setattr(
        models_mod.SensorimotorEncoder,
        "encode",
        lambda self, x, state=None, motors=None: encode(self, x, None, motors),
    )


@pytest.mark.parametrize(
    ("edit", "kinds"), [(_clipped_relu, STACKED), (_state_ignored, ("rec-s", "rec-sm"))]
)
def test_the_check_sees_edits_that_one_fresh_step_would_not(edit, kinds, monkeypatch):
    check.computes_models_py.cache_clear()
    edit(monkeypatch)
    try:
        assert not any(check.computes_models_py(kind) for kind in kinds)
    finally:
        check.computes_models_py.cache_clear()


def test_the_check_refuses_a_layer_it_does_not_know_even_where_it_agrees(monkeypatch):
    # a ReLU clipped far beyond any activation: equal numbers on every input the check tries
    monkeypatch.setattr(torch.nn, "ReLU", lambda: torch.nn.Hardtanh(0.0, 1e9))
    check.computes_models_py.cache_clear()
    try:
        assert not check._known_layers(build_model("sm", seed=0))
        assert not check.computes_models_py("sm")
    finally:
        check.computes_models_py.cache_clear()


def test_the_autograd_fallback_trains_what_the_stack_trains(square_db_path, tmp_path, monkeypatch):
    config = TrainConfig(model="sm", max_epochs=1)  # float32 drift grows over more epochs
    stacked = train(square_db_path, tmp_path / "stacked", config)
    monkeypatch.setattr(train_mod, "computes_models_py", lambda model: False)
    plain = train(square_db_path, tmp_path / "plain", config)
    assert plain.best_val_error == pytest.approx(stacked.best_val_error, rel=1e-4)
    a, b = (load_run(r.run_dir).model.state_dict() for r in (plain, stacked))
    assert _close(a, b, tol=1e-4)  # 250 steps on real data: 3e-5 seen


@pytest.mark.parametrize("rows", [8, 600])  # 600: a tall batch, its weight gradient transposed
def test_a_chain_applied_twice_adds_the_gradients_of_both(rows):
    # Rec-SMA's head applies the predictor and the transition at every k (add=True)
    model = build_model("sm", seed=0)
    net = StackedEncoders.from_models([model])
    g = torch.Generator().manual_seed(0)
    xs = [torch.randn(1, rows, 15, generator=g) for _ in range(2)]
    names = [n for n, _ in model.named_parameters() if n.startswith("predictor.")]
    for name in names:
        net.grads[net.index[name]].fill_(0.0)
    for x in xs:
        hs = net._forward(net.layers, "predictor", x)
        dy = torch.linspace(-1, 1, hs[-1].numel()).view_as(hs[-1])
        net._backward(net.layers, net.grads, "predictor", hs, dy, add=True)
    sum(
        (model.predictor(x[0]) * torch.linspace(-1, 1, rows * 5).view(rows, 5)).sum() for x in xs
    ).backward()
    params = dict(model.named_parameters())
    for name in names:
        mine, theirs = net.grads[net.index[name]][0].reshape(params[name].shape), params[name].grad
        assert torch.allclose(mine, theirs, rtol=1e-4, atol=1e-5), name
        assert theirs.abs().max() > 0


def test_select_and_concat_keep_each_seed_state():
    nets = [StackedEncoders.from_models([build_model("sm", seed=sd)]) for sd in (0, 1, 2)]
    g = torch.Generator().manual_seed(2)
    s, m = torch.rand(64 * 5 + 1, 5, generator=g), torch.rand(64 * 5 + 1, 2, generator=g)
    for sd, net in enumerate(nets):
        train_epoch_stacked(net, s, m, [sd], 0, 64)
    both = StackedEncoders.concat(nets)
    both.select([2, 0])
    for k, sd in enumerate((2, 0)):
        assert all(
            torch.equal(a[k], b[0]) for a, b in zip(both.params, nets[sd].params, strict=True)
        )
        assert all(
            torch.equal(a[k], b[0])
            for a, b in zip(both.exp_avg_sq, nets[sd].exp_avg_sq, strict=True)
        )
    assert float(both.step) == 5.0


# --- run folders: early stopping, evaluation, format ---------------------------------------


@pytest.mark.parametrize("kind", ["s", "sm"])
def test_each_stacked_seed_is_its_solo_run_down_to_early_stopping(kind, square_db_path, tmp_path):
    # patience 1 and a 10 % bar: seeds stop early, at epochs of their own
    config = TrainConfig(model=kind, patience=1, min_ratio=0.9, max_epochs=30)
    seeds = [0, 1, 2, 3]
    results = train_seeds(square_db_path, tmp_path, config, seeds)
    stops = set()
    for seed, result in zip(seeds, results, strict=True):
        folder = tmp_path / run_name("square", kind, seed)
        best = torch.load(folder / "model.pt", weights_only=True)
        ckpt = torch.load(folder / "checkpoint.pt", weights_only=True)
        assert result.run_dir == folder
        assert result.stopped == "early stopping"
        # the seed alone, in a stack of one: the same bits (the reference loop of train.py
        # agrees to rounding, which grows over epochs: test_stacked_epochs_agree_with_the_plain_loop)
        (solo,) = train_seeds(square_db_path, tmp_path / "solo", config, [seed])
        assert solo.epochs == result.epochs
        assert [r.val_error for r in solo.history] == [r.val_error for r in result.history]
        solo_dir = tmp_path / "solo" / folder.name
        assert _equal(torch.load(solo_dir / "model.pt", weights_only=True), best)
        solo_ckpt = torch.load(solo_dir / "checkpoint.pt", weights_only=True)
        assert _equal(solo_ckpt["model"], ckpt["model"])
        stops.add(result.epochs)
    assert len(stops) > 1, "the seeds should stop at different epochs for this test to bite"


def test_a_stack_across_databases_trains_each_seed_as_alone(
    square_db_path, rooms1_db_path, tmp_path
):
    # seed 0 on both worlds (same data order, other data) and seed 1 on Square, in one stack
    config = TrainConfig(model="sm", patience=1, min_ratio=0.9, max_epochs=6)
    runs = [
        (square_db_path, 0, tmp_path / "a"),
        (rooms1_db_path, 0, tmp_path / "b"),
        (square_db_path, 1, tmp_path / "c"),
    ]
    results = train_runs([d for d, _, _ in runs], [(sd, out) for _, sd, out in runs], config)
    assert results[0].history[0].val_error != results[1].history[0].val_error
    for (data, seed, out), result in zip(runs, results, strict=True):
        (solo,) = train_runs(data, [(seed, out.with_name(out.name + "_solo"))], config)
        assert [r.val_error for r in solo.history] == [r.val_error for r in result.history]
        assert solo.epochs == result.epochs
        mine, alone = (torch.load(d / "model.pt", weights_only=True) for d in (out, solo.run_dir))
        assert _equal(mine, alone)
        made = json.loads((out / "config.json").read_text())
        assert made["data"]["path"] == str(data)
    assert len({r.epochs for r in results}) > 1, "seeds should stop apart for this to bite"


def test_a_stack_refuses_databases_of_other_sizes_and_recurrent_models(square_db_path, tmp_path):
    from sensorimotor.sim.database import generate, save_database
    from sensorimotor.sim.world import load_world

    small = tmp_path / "small.npz"
    save_database(generate(load_world("square"), 10_000, seed=0), small)
    runs = [(0, tmp_path / "a"), (0, tmp_path / "b")]
    with pytest.raises(ValueError, match="one length"):
        train_runs([square_db_path, small], runs, TrainConfig(model="s", max_epochs=1))
    with pytest.raises(ValueError, match="one database"):
        train_runs([square_db_path, small], runs, TrainConfig(model="rec-s", max_epochs=1))
    with pytest.raises(InputError, match="twice"):
        train_runs(square_db_path, runs, TrainConfig(model="s", max_epochs=1))


def test_stacked_run_folders_are_single_seed_run_folders(square_db_path, tmp_path):
    config = TrainConfig(model="sm", max_epochs=2)
    train_seeds(square_db_path, tmp_path / "stack", config, [4, 7])
    train(square_db_path, tmp_path / "solo", TrainConfig(model="sm", seed=7, max_epochs=2))
    stacked, solo = tmp_path / "stack" / "square__sm__s7", tmp_path / "solo"
    assert sorted(p.name for p in stacked.iterdir()) == sorted(p.name for p in solo.iterdir())
    assert json.loads((stacked / "config.json").read_text()) == json.loads(
        (solo / "config.json").read_text()
    )
    header = (solo / "history.csv").read_text().splitlines()[0]
    assert (stacked / "history.csv").read_text().splitlines()[0] == header
    a, b = (torch.load(d / "checkpoint.pt", weights_only=True) for d in (stacked, solo))
    assert a.keys() == b.keys()
    assert _equal(a["model"], b["model"])
    for name in ("exp_avg", "exp_avg_sq", "steps"):
        assert all(
            torch.equal(x, y)
            for x, y in zip(a["optimizer"][name], b["optimizer"][name], strict=True)
        )
    ra, rb = (json.loads((d / "result.json").read_text()) for d in (stacked, solo))
    assert {k: v for k, v in ra.items() if k != "seconds"} == {
        k: v for k, v in rb.items() if k != "seconds"
    }
    # evaluate reads it as any run, with the same test error
    db = load_database(square_db_path)
    s, m = split_tensors(db, "test")
    run_a, run_b = load_run(stacked), load_run(solo)
    assert run_a.config["train"]["seed"] == 7
    assert model_error(run_a.model, s, m) == model_error(run_b.model, s, m)


# --- resume --------------------------------------------------------------------------------


class Killed(Exception):
    pass


def _history(folder):
    return [ln.split(",")[:5] for ln in (folder / "history.csv").read_text().splitlines()]


def test_resume_after_a_kill_between_two_seeds_equals_uninterrupted(square_db_path, tmp_path):
    config = TrainConfig(model="s", max_epochs=4)
    seeds = [0, 1, 2]
    train_seeds(square_db_path, tmp_path / "straight", config, seeds)

    def kill(seed, record, stopper):  # seed 0 has written epoch 2, seeds 1 and 2 only epoch 1
        if (seed, record.epoch) == (0, 2):
            raise Killed

    with pytest.raises(Killed):
        train_seeds(square_db_path, tmp_path / "killed", config, seeds, on_epoch=kill)
    epochs = {
        sd: torch.load(
            tmp_path / "killed" / run_name("square", "s", sd) / "checkpoint.pt", weights_only=True
        )["epoch"]
        for sd in seeds
    }
    assert epochs == {0: 2, 1: 1, 2: 1}
    seen = []
    train_seeds(
        square_db_path,
        tmp_path / "killed",
        config,
        seeds,
        resume=True,
        on_epoch=lambda sd, r, st: seen.append((sd, r.epoch)),
    )
    assert seen[:2] == [(1, 2), (2, 2)]  # the lagging seeds catch up first, then all go on
    assert sorted(seen[2:]) == [(0, 3), (1, 3), (2, 3)]
    for sd in seeds:
        a = tmp_path / "straight" / run_name("square", "s", sd)
        b = tmp_path / "killed" / run_name("square", "s", sd)
        ca, cb = (torch.load(d / "checkpoint.pt", weights_only=True) for d in (a, b))
        assert _equal(ca["model"], cb["model"])
        assert _equal(
            torch.load(a / "model.pt", weights_only=True),
            torch.load(b / "model.pt", weights_only=True),
        )
        assert _history(a) == _history(b)


def test_resume_with_a_lifted_epoch_cap_equals_straight(square_db_path, tmp_path):
    seeds = [0, 1]
    train_seeds(square_db_path, tmp_path / "a", TrainConfig(model="sm", max_epochs=4), seeds)
    train_seeds(square_db_path, tmp_path / "b", TrainConfig(model="sm", max_epochs=2), seeds)
    results = train_seeds(
        square_db_path, tmp_path / "b", TrainConfig(model="sm", max_epochs=4), seeds, resume=True
    )
    assert [r.epochs for r in results] == [4, 4]
    for sd in seeds:
        a, b = (tmp_path / d / run_name("square", "sm", sd) for d in ("a", "b"))
        ca, cb = (torch.load(d / "checkpoint.pt", weights_only=True) for d in (a, b))
        assert _equal(ca["model"], cb["model"])
        assert _history(a) == _history(b)


def test_scripted_validation_stops_one_seed_and_leaves_the_other(
    square_db_path, tmp_path, monkeypatch
):
    """Seed 0's validation never improves after epoch 0: it stops after 3 epochs (patience 2)
    and leaves the stack; seed 1's always improves: it runs to the cap, its weights untouched."""
    models: list[int] = []  # id of each seed's model, in the order first validated: 0, then 1

    def scripted(model, s, m):
        if id(model) not in models:
            models.append(id(model))
        scripted.calls += 1
        return 1.0 if models.index(id(model)) == 0 else 0.5**scripted.calls

    scripted.calls = 0
    # the validation of either engine
    monkeypatch.setattr("sensorimotor.learn.engine.model_error", scripted)
    config = TrainConfig(model="s", patience=2, max_epochs=5)
    results = train_seeds(square_db_path, tmp_path / "x", config, [0, 1])
    monkeypatch.undo()
    assert (results[0].stopped, results[0].epochs, results[0].best_epoch) == (
        "early stopping",
        3,
        0,
    )
    assert (results[1].stopped, results[1].epochs) == ("max epochs", 5)
    assert len(models) == 2
    for sd, epochs in ((0, 3), (1, 5)):  # the same weights as each seed trained alone
        alone = TrainConfig(model="s", seed=sd, patience=100, max_epochs=epochs)
        train(square_db_path, tmp_path / f"alone{sd}", alone)
        a = torch.load(tmp_path / "x" / f"square__s__s{sd}" / "checkpoint.pt", weights_only=True)
        b = torch.load(tmp_path / f"alone{sd}" / "checkpoint.pt", weights_only=True)
        assert a["epoch"] == epochs - 1
        assert _equal(a["model"], b["model"])


# --- the command line ----------------------------------------------------------------------


def test_cli_trains_one_folder_per_seed(square_db_path, tmp_path, cli):
    out = tmp_path / "runs"
    args = ["train", "sm", "--seeds", "0,1", "--data", square_db_path, "--out", out]
    proc = cli(*args, "--max-epochs", "2")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["square__sm__s0", "square__sm__s1"]
    for sd in (0, 1):
        run = load_run(out / f"square__sm__s{sd}")
        assert run.config["train"]["seed"] == sd
        assert json.loads((run.path / "result.json").read_text())["epochs"] == 2
    assert_one_line_error(cli(*args, "--max-epochs", "2"), "--resume")


@pytest.mark.parametrize(
    ("seeds", "needle"),
    [("", "at least one"), ("0,a", "'a' is not an integer"), ("1,2,1", "seed 1 is given twice")],
)
def test_cli_refuses_bad_seeds(seeds, needle, square_db_path, tmp_path, cli):
    out = tmp_path / "runs"
    proc = cli("train", "s", "--seeds", seeds, "--data", square_db_path, "--out", out)
    assert_one_line_error(proc, "--seeds", needle)
    assert not out.exists()


def test_cli_seeds_of_a_recurrent_model_train_in_one_stack(square_db_path, tmp_path, cli):
    out = tmp_path / "runs"
    args = ["train", "rec-s", "--seeds", "2,5", "--data", square_db_path, "--out", out]
    proc = cli(*args, "--max-epochs", "1")
    assert proc.returncode == 0, proc.stderr
    assert sorted(p.name for p in out.iterdir()) == ["square__rec-s__s2", "square__rec-s__s5"]
    assert load_run(out / "square__rec-s__s5").config["train"]["seed"] == 5
    alone = TrainConfig(model="rec-s", seed=5, max_epochs=1)
    train(square_db_path, tmp_path / "alone", alone)
    a = torch.load(out / "square__rec-s__s5" / "model.pt", weights_only=True)
    b = torch.load(tmp_path / "alone" / "model.pt", weights_only=True)
    assert _equal(a, b)


def test_cli_header_says_a_model_of_other_sizes_trains_stacked(square_db_path, tmp_path, cli):
    args = ["train", "rec-s", "--seeds", "0,1", "--data", square_db_path, "--out", tmp_path]
    proc = cli(*args, "--set", "lstm_size=12", "--max-epochs", "1")
    assert proc.returncode == 0, proc.stderr
    assert "(seeds 0,1, stacked)" in proc.stderr.splitlines()[0]
    assert load_run(tmp_path / "square__rec-s__s1").model.config.lstm_size == 12
