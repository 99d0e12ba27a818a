"""The hand-written LSTM of Rec-S and Rec-SM: its tanh, its gradients against autograd through
nn.LSTM, its epochs against the nn.LSTM loop of train.py, and seeds that do not depend on the
stack they train in, down to early stopping."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import train_epoch_recurrent
from sensorimotor.learn.evaluate import model_error
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.fast.stacked import StackedEncoders
from sensorimotor.learn.fast.stacked_lstm import (
    forward_backward,
    sequence_errors,
    tanh_array,
    train_epoch_stacked_recurrent,
)
from sensorimotor.learn.models import build_model
from sensorimotor.learn.runs import run_name
from sensorimotor.learn.train import train, train_seeds

pytestmark = pytest.mark.usefixtures("one_thread")


def test_tanh32_is_tanh_to_float32_rounding():
    x = np.concatenate([np.linspace(-20, 20, 400_001), [0.0, 1e-8, -1e-8, 7.9, 8.0, 1e4, -1e4]])
    x = x.astype(np.float32)
    mine = tanh_array(x).astype(np.float64)
    ref = np.tanh(x.astype(np.float64))
    assert np.abs(mine - ref).max() < 5e-7
    assert np.abs(mine).max() <= 1.0
    assert np.array_equal(tanh_array(-x), -tanh_array(x))
    assert np.isnan(tanh_array(np.array([np.nan], dtype=np.float32))[0])  # as nn.LSTM: it spreads


def _stacked_state(per_seed):
    """[(h, c) (layers, B, H) per seed] -> [(h, c) (K, B, H) per layer]."""
    layers = per_seed[0][0].shape[0]
    return [
        (torch.stack([h[i] for h, _ in per_seed]), torch.stack([c[i] for _, c in per_seed]))
        for i in range(layers)
    ]


@pytest.mark.parametrize("kind", ["rec-s", "rec-sm"])
@pytest.mark.parametrize("padded", [False, True])
def test_gradients_equal_autograd_through_nn_lstm(kind, padded):
    seeds, T, B = [3, 1, 4], 20, 16
    models = [build_model(kind, seed=sd) for sd in seeds]
    net = StackedEncoders.from_models(models)
    g = torch.Generator().manual_seed(0)
    xs, xm, y = (torch.rand(T, B, d, generator=g) for d in (5, 2, 5))
    weight = (torch.rand(T, B, generator=g) > 0.3).float() if padded else None
    start = [
        tuple(0.3 * torch.randn(3, B, 32, generator=g) for _ in range(2)) for _ in seeds
    ]  # a carried state, per seed (h, c)
    sq_sum = torch.zeros(len(seeds))
    with torch.no_grad():
        state = forward_backward(
            net, xs, xm if kind == "rec-sm" else None, y, weight, _stacked_state(start), sq_sum
        )
    for k, model in enumerate(models):
        pred, _, (h, c) = model(xs.transpose(0, 1), xm.transpose(0, 1), start[k])  # (B, T, 5)
        err = ((pred - y.transpose(0, 1)) ** 2).sum(-1)  # (B, T)
        w = torch.ones_like(err) if weight is None else weight.T
        loss = (err * w).sum() / w.sum()
        loss.backward()
        for (name, p), mine in zip(
            model.named_parameters(), net._per_seed(net.grads, k), strict=True
        ):
            scale = p.grad.abs().max()
            assert (mine - p.grad).abs().max() <= 1e-5 * scale, name
        assert torch.allclose(sq_sum[k], (err * w).sum().detach(), rtol=1e-5)
        for layer in range(3):
            assert torch.allclose(state[layer][0][k], h[layer].detach(), atol=1e-6)
            assert torch.allclose(state[layer][1][k], c[layer].detach(), atol=1e-6)


@pytest.mark.parametrize("kind", ["rec-s", "rec-sm"])
def test_stacked_epochs_follow_the_lstm_loop_and_do_not_depend_on_the_stack(kind):
    g = torch.Generator().manual_seed(1)
    n = 64 * 20 * 4 + 37  # streams of unequal length: the last chunk is padded
    s, m = torch.rand(n + 1, 5, generator=g), torch.rand(n + 1, 2, generator=g)
    seeds = [5, 2, 7, 0, 9]

    def stacked(order):
        net = StackedEncoders.from_models([build_model(kind, seed=sd) for sd in order])
        errors = [train_epoch_stacked_recurrent(net, s, m, 64, 20) for _ in range(3)]
        return net, torch.stack(errors)  # (epochs, K)

    net, errors = stacked(seeds)
    for k, sd in enumerate(seeds):
        model = build_model(kind, seed=sd)
        opt = FusedAdam(model.parameters())
        plain = [train_epoch_recurrent(model, opt, s, m, 64, 20) for _ in range(3)]
        assert float(net.step) == float(opt.steps[0]) == 3 * 5  # 3 epochs of 4 + 1 chunks
        mine = net.load_into(k, build_model(kind))
        gap = torch.cat([(a - b).abs().flatten() for a, b in zip(
            model.parameters(), mine.parameters(), strict=True)]).detach()  # fmt: skip
        # float32 rounding after 15 Adam steps: tiny for nearly every weight; Adam can turn it
        # into up to lr a step for a weight whose gradient is nearly zero
        assert gap.quantile(0.99) < 1e-5
        assert gap.max() < 15 * 1e-3
        assert torch.allclose(errors[:, k].double(), torch.tensor(plain).double(), rtol=1e-4)
    for k, sd in enumerate(seeds):  # each seed alone: the same numbers as in the stack
        net1, _ = stacked([sd])
        assert all(torch.equal(a[k], b[0]) for a, b in zip(net.params, net1.params, strict=True))


def test_each_recurrent_seed_stops_as_it_does_alone(square_db_path, tmp_path):
    # patience 1 and a 10 % bar: seeds stop early, at epochs of their own
    config = TrainConfig(model="rec-sm", patience=1, min_ratio=0.9, max_epochs=12)
    seeds = [0, 1, 2]
    results = train_seeds(square_db_path, tmp_path / "stack", config, seeds)
    stops = set()
    for seed, result in zip(seeds, results, strict=True):
        alone = train(square_db_path, tmp_path / f"alone{seed}", TrainConfig(**{
            **config.__dict__, "seed": seed}))  # fmt: skip
        assert result.run_dir == tmp_path / "stack" / run_name("square", "rec-sm", seed)
        assert (result.stopped, result.epochs, result.best_epoch) == (
            alone.stopped,
            alone.epochs,
            alone.best_epoch,
        )
        assert [r.val_error for r in result.history] == [r.val_error for r in alone.history]
        a = torch.load(result.run_dir / "model.pt", weights_only=True)
        b = torch.load(alone.run_dir / "model.pt", weights_only=True)
        assert all(torch.equal(a[name], b[name]) for name in a)
        stops.add(result.epochs)
    assert len(stops) > 1, "the seeds should stop at different epochs for this test to bite"


@pytest.mark.parametrize("kind", ["rec-s", "rec-sm"])
def test_validation_of_a_stack_is_model_error_of_each_seed(kind):
    g = torch.Generator().manual_seed(3)
    s, m = torch.rand(1000, 5, generator=g), torch.rand(1000, 2, generator=g)
    seeds = (6, 1, 8)
    models = [build_model(kind, seed=sd) for sd in seeds]
    net = StackedEncoders.from_models(models)
    ref = [model_error(model, s, m) for model in models]
    for chunk in (4096, 96):  # one padded chunk; the state carried over ten, the last short
        mine = sequence_errors(net, s, m, chunk=chunk)
        assert mine == pytest.approx(ref, rel=1e-5)
        for k, sd in enumerate(seeds):  # each seed alone: the same bits
            alone = StackedEncoders.from_models([build_model(kind, seed=sd)])
            assert sequence_errors(alone, s, m, chunk=chunk) == [mine[k]]
    assert len(set(mine)) == 3
    with pytest.raises(ValueError, match="multiple of 16"):
        sequence_errors(net, s, m, chunk=97)
