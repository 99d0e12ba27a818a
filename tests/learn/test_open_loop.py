"""Rec-SMA's training: the open-loop loss, its settings, and the runs it makes."""

from __future__ import annotations

import json

import pytest
import torch

from sensorimotor.errors import InputError
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import FusedAdam, train_epoch_recurrent
from sensorimotor.learn.evaluate import ahead_errors, load_run, split_tensors
from sensorimotor.learn.models import REC_SMA, build_model
from sensorimotor.learn.runs import apply_settings, check_run_dir
from sensorimotor.learn.train import train
from sensorimotor.sim.database import load_database


def _data(n: int = 300, seed: int = 0):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n + 1, 5, generator=g), torch.rand(n + 1, 2, generator=g)


@torch.no_grad()
def _by_hand(model, s, m, ahead: int) -> float:
    """The mean over every (t, k) with its target inside of the open-loop error, one stream."""
    _, z, _ = model(s[None, :-1], m[None, :-1])
    n = len(s) - 1
    total, count = 0.0, 0
    pred = model.ahead(z[:, : n - ahead + 1], m[None, :n], ahead)[:, 0]  # (K, T', 5)
    for k in range(ahead):
        err = ((pred[k] - s[k + 1 : k + 1 + pred.shape[1]]) ** 2).sum(-1)  # (T',)
        total, count = total + float(err.sum()), count + err.numel()
    for t in range(n - ahead + 1, n):  # the last starts: only the targets inside the split
        zt = z[:, t : t + 1]
        p = model.ahead(zt, m[None, t : t + n - t], n - t)[:, 0, 0]  # (n - t, 5)
        err = ((p - s[t + 1 : n + 1]) ** 2).sum(-1)
        total, count = total + float(err.sum()), count + err.numel()
    return total / count


def test_an_open_loop_epoch_reports_the_loss_over_every_step_and_k_inside_the_split():
    s, m = _data()
    model = build_model(REC_SMA, seed=0)
    expected = _by_hand(model, s, m, 4)
    frozen = FusedAdam(model.parameters(), lr=1e-30)  # the step leaves the weights as they are
    got = train_epoch_recurrent(model, frozen, s, m, streams=1, horizon=1000, ahead=4)
    assert got == pytest.approx(expected, rel=1e-5)


def test_the_validation_error_is_the_open_loop_errors_mean_and_k1_is_one_step():
    s, m = _data()
    model = build_model(REC_SMA, seed=1)
    errors = ahead_errors(model, s, m, 3)
    with torch.no_grad():
        pred, _, _ = model(s[None], m[None])
    one = ((pred[0, :-3] - s[1:-2]) ** 2).sum(-1).mean()  # the starts with all 3 targets inside
    assert errors.shape == (3,)
    assert float(errors[0]) == pytest.approx(float(one), rel=1e-5)


def test_open_loop_needs_a_transition_and_has_a_bound():
    with pytest.raises(InputError, match="predicts one step"):
        TrainConfig(model="rec-sm", ahead=4)
    with pytest.raises(InputError, match="at most"):
        TrainConfig(model=REC_SMA, ahead=10_000)
    with pytest.raises(InputError, match="ahead_every must be at most the horizon"):
        TrainConfig.of(REC_SMA, ahead_every=257)
    config = TrainConfig.of(REC_SMA)
    assert (config.horizon, config.ahead) == (256, 32)  # the kind's own, over the paper's
    assert TrainConfig.of(REC_SMA, ahead=1).ahead == 1  # a setting over the kind's
    assert TrainConfig.of("rec-sm") == TrainConfig(model="rec-sm")
    config, sizes = apply_settings(config, ["memory_motors=false", "ahead=8", "ahead_every=1"])
    assert (config.ahead, config.ahead_every) == (8, 1)  # the K = 1 ablation's two settings
    assert sizes.memory_motors is False
    with pytest.raises(InputError, match="true or false"):
        apply_settings(config, ["memory_motors=no"])


def test_adam_leaves_a_parameter_the_loss_does_not_reach_as_torchs_adam_does():
    torch.manual_seed(0)
    a, b = torch.nn.Linear(3, 2), torch.nn.Linear(3, 2)
    ref_a, ref_b = (torch.nn.Linear(3, 2) for _ in range(2))
    ref_a.load_state_dict(a.state_dict())
    ref_b.load_state_dict(b.state_dict())
    ours = FusedAdam([*a.parameters(), *b.parameters()])
    theirs = torch.optim.Adam([*ref_a.parameters(), *ref_b.parameters()])
    x = torch.rand(4, 3)
    for opt, layer in ((ours, a), (theirs, ref_a)):
        for _ in range(3):
            opt.zero_grad()
            layer(x).square().sum().backward()
            opt.step()
    ours_p, ref_p = [*a.parameters(), *b.parameters()], [*ref_a.parameters(), *ref_b.parameters()]
    for p, q in zip(ours_p, ref_p, strict=True):
        torch.testing.assert_close(p, q)
    assert all(float(step) == 0 for step in ours.steps[2:])  # b was never stepped


def test_rec_sma_trains_the_same_bytes_for_a_seed_and_resumes_a_run_of_an_older_config(
    square_db_path, tmp_path
):
    config = TrainConfig.of(REC_SMA, max_epochs=1, horizon=64, ahead=8, ahead_every=2)
    a = train(square_db_path, tmp_path / "a", config)
    b = train(square_db_path, tmp_path / "b", config)
    assert torch.equal(
        torch.cat([p.flatten() for p in load_run(a.run_dir).model.parameters()]),
        torch.cat([p.flatten() for p in load_run(b.run_dir).model.parameters()]),
    )
    run = load_run(a.run_dir)
    s, m = split_tensors(load_database(square_db_path), "val")
    assert a.best_val_error == pytest.approx(
        float(ahead_errors(run.model, s, m, 8).mean()), rel=1e-5
    )
    # a run written before ahead and transition_hidden existed ran at their defaults
    rec_sm = train(square_db_path, tmp_path / "old", TrainConfig(model="rec-sm", max_epochs=1))
    cfg = rec_sm.run_dir / "config.json"
    meta = json.loads(cfg.read_text())
    old = json.loads(cfg.read_text())
    del old["train"]["ahead"], old["train"]["ahead_every"], old["model"]["transition_hidden"]
    cfg.write_text(json.dumps(old))
    check_run_dir(rec_sm.run_dir, meta, resume=True)  # no "another setting" refusal
    meta["train"]["horizon"] = 30
    with pytest.raises(InputError, match="horizon: 20 -> 30"):
        check_run_dir(rec_sm.run_dir, meta, resume=True)
