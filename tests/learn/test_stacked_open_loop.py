"""Rec-SMA's stacked training (``fast.stacked_open_loop``): its loss and gradients against
autograd through ``models.py``, its epochs against the plain loop of ``engine``, seeds that do
not depend on the stack they train in, and the engine that validates each seed open loop."""

from __future__ import annotations

import pytest
import torch

from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import (
    AutogradEngine,
    FusedAdam,
    Member,
    StackedEngine,
    TrainData,
    train_epoch_recurrent,
)
from sensorimotor.learn.fast.stacked import StackedEncoders
from sensorimotor.learn.fast.stacked_open_loop import (
    forward_backward,
    train_epoch_stacked_open_loop,
)
from sensorimotor.learn.models import REC_SMA, ModelConfig, build_model
from sensorimotor.learn.slowness import slowness_prior
from sensorimotor.learn.train import trains_stacked

pytestmark = pytest.mark.usefixtures("one_thread")


def _data(n: int, seed: int = 1):
    g = torch.Generator().manual_seed(seed)
    return torch.rand(n + 1, 5, generator=g), torch.rand(n + 1, 2, generator=g)


@pytest.mark.parametrize(  # reads False: the ablation, zeros into the memory
    ("reads", "slow_dims"),
    [(True, 0), (False, 0), (True, 3)],  # 3: the slowness prior on z_s
)
def test_loss_and_gradients_equal_autograd_over_two_chunks(reads, slow_dims):
    config = ModelConfig(kind=REC_SMA, memory_motors=None if reads else False)
    seeds, (t, b, ahead, every) = (3, 0), (9, 4, 4, 3)
    models = [build_model(config, seed=sd) for sd in seeds]
    with torch.no_grad():  # z_s as wide in a window as a trained one's (1e-5 at the start):
        for model in models:  # the prior divides by that spread, so rounding grows as it shrinks
            model.sensor_out.weight.mul_(30 if slow_dims else 1)
    net = StackedEncoders.from_models(models)
    g = torch.Generator().manual_seed(2)
    state, states = None, [None] * len(seeds)
    for _ in range(2):  # the state and the last command carried into the second chunk
        xs = torch.rand(t, b, 5, generator=g) * 4 - 1
        xm = torch.rand(t + ahead - 1, b, 2, generator=g) * 4 - 2
        y = torch.rand(t + ahead - 1, b, 5, generator=g)
        w = (torch.rand(ahead, -(-t // every), b, generator=g) > 0.3).float()  # (A, T', B)
        state, sq, count = forward_backward(net, xs, xm, y, w, state, ahead, every, slow_dims, 0.7)
        assert count == w.sum()
        for k, model in enumerate(models):
            model.zero_grad()
            z, states[k] = model.encode(xs.transpose(0, 1), states[k], xm[:t].transpose(0, 1))
            states[k] = tuple(h.detach() for h in states[k])
            pred = model.ahead(z, xm.transpose(0, 1), ahead, every)  # (A, B, T', 5)
            target = torch.stack([y[j : j + t : every].transpose(0, 1) for j in range(ahead)])
            err = (pred - target).square().sum(-1) * w.transpose(1, 2)
            loss = err.sum() / w.sum()
            if slow_dims:
                loss = loss + 0.7 * slowness_prior(z, slow_dims)
            loss.backward()
            assert sq[k] == pytest.approx(float(err.sum().detach()), rel=1e-5)
            for grad, p in zip(net.grads, model.parameters(), strict=True):
                # the prior's gradient of a shift of z_s (sensor_out's bias) is 0 by
                # cancellation: rounding, to a fraction of the largest gradient
                atol = 1e-3 * float(p.grad.abs().max()) if slow_dims else 1e-6
                assert torch.allclose(grad[k].reshape(p.shape), p.grad, rtol=1e-4, atol=atol)
    motor_columns = net.grads[net.index["lstm.weight_ih_l0"]][:, :, -2:]  # m_{t-1}'s weights
    assert bool(motor_columns.abs().max() > 0) == reads  # the ablation's zeros teach them nothing


def test_stacked_epochs_follow_the_plain_loop_and_do_not_depend_on_the_stack():
    s, m = _data(4 * 256 + 300)  # a second, short chunk in every stream; the last steps padded
    c = TrainConfig.of(REC_SMA)
    settings = (c.batch_size, c.horizon, c.ahead, c.ahead_every)
    seeds = [4, 1, 6]

    def stacked(order):
        net = StackedEncoders.from_models([build_model(REC_SMA, seed=sd) for sd in order])
        errors = [train_epoch_stacked_open_loop(net, s, m, *settings) for _ in range(2)]
        return net, torch.stack(errors)  # (epochs, K)

    net, errors = stacked(seeds)
    for k, sd in enumerate(seeds):
        model = build_model(REC_SMA, seed=sd)
        opt = FusedAdam(model.parameters())
        plain = [train_epoch_recurrent(model, opt, s, m, *settings) for _ in range(2)]
        assert float(net.step) == float(opt.steps[0]) == 2 * 2  # 2 epochs of 2 chunks
        mine = net.load_into(k, build_model(REC_SMA))
        gap = torch.cat([(a - b).abs().flatten() for a, b in zip(
            model.parameters(), mine.parameters(), strict=True)]).detach()  # fmt: skip
        assert gap.quantile(0.99) < 1e-5  # float32 rounding after 4 Adam steps
        assert gap.max() < 4 * 1e-3
        assert errors[:, k].tolist() == pytest.approx(plain, rel=1e-4)
    for k, sd in enumerate(seeds):  # each seed alone: the same bits as in the stack
        net1, _ = stacked([sd])
        assert all(torch.equal(a[k], b[0]) for a, b in zip(net.params, net1.params, strict=True))


@pytest.mark.parametrize("slow_dims", [0, 4])
def test_the_stacked_engine_trains_and_validates_each_seed_as_autograd_does(slow_dims):
    assert trains_stacked(REC_SMA, "cpu")
    s, m = _data(4 * 256 + 50)
    val = _data(400, seed=7)
    config = TrainConfig.of(REC_SMA, slow_dims=slow_dims)
    data = TrainData(s, m, [val])

    def members():
        out = []
        for sd in (2, 5):
            model = build_model(REC_SMA, seed=sd)
            out.append(Member(sd, 0, model, FusedAdam(model.parameters(), lr=config.lr)))
        return out

    stacked, plain = StackedEngine(members(), data, config), AutogradEngine(members(), data, config)
    assert stacked.train_epoch(0) == pytest.approx(plain.train_epoch(0), rel=1e-4)
    # validation is the open-loop mean of each seed's model, brought up to date from the stack
    assert stacked.val_errors() == pytest.approx(plain.val_errors(), rel=1e-4)
