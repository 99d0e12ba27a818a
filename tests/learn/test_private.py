"""learn/fast/private.py: each private PyTorch function and its public fallback agree, and the
whole training step runs on the fallbacks alone (a PyTorch without the private names)."""

from __future__ import annotations

import pytest
import torch

from sensorimotor.learn.batches import epoch_generator
from sensorimotor.learn.engine import train_epoch_feedforward
from sensorimotor.learn.fast import private
from sensorimotor.learn.fast.adam import FusedAdam
from sensorimotor.learn.fast.stacked import StackedEncoders, train_epoch_stacked
from sensorimotor.learn.models import build_model


@pytest.fixture
def public_only(monkeypatch):
    monkeypatch.setattr(private, "USE_PRIVATE", False)


def _rand(*shape, seed=0):
    return torch.randn(*shape, generator=torch.Generator().manual_seed(seed))


def test_the_private_functions_exist_in_this_pytorch():
    """The pinned PyTorch has them: the fast path is the one that runs (and is measured)."""
    assert private._FUSED_ADAM is not None
    assert private._FOREACH_ADD is not None
    assert private._THRESHOLD_BACKWARD is not None


def test_relu_grad_fallback_equals_the_private_kernel(monkeypatch):
    h = _rand(4, 64, 16).relu()  # a ReLU output: zeros and positives
    dy = _rand(4, 64, 16, seed=1)
    fast = private.relu_grad_(dy.clone(), h)
    monkeypatch.setattr(private, "USE_PRIVATE", False)
    public = private.relu_grad_(dy.clone(), h)
    assert torch.equal(fast, public)
    assert torch.equal(public, dy * (h > 0))  # autograd's ReLU backward, by hand


def test_add_fallback_equals_the_private_kernel(monkeypatch):
    a = [torch.zeros(()), torch.ones(3)]
    b = [t.clone() for t in a]
    private.add_(a, 1)
    monkeypatch.setattr(private, "USE_PRIVATE", False)
    private.add_(b, 1)
    assert all(torch.equal(x, y) for x, y in zip(a, b, strict=True))


@pytest.mark.parametrize("use_private", [True, False])
def test_fused_adam_matches_torch_optim_adam_with_or_without_private_kernels(
    use_private, monkeypatch
):
    monkeypatch.setattr(private, "USE_PRIVATE", use_private)
    ours, ref = build_model("sm", seed=0), build_model("sm", seed=0)
    opt, ref_opt = FusedAdam(ours.parameters()), torch.optim.Adam(ref.parameters(), lr=1e-3)
    xs, xm, y = _rand(64, 5), _rand(64, 2, seed=1), _rand(64, 5, seed=2)
    for _ in range(5):
        for model, o in ((ours, opt), (ref, ref_opt)):
            loss = (model(xs, xm)[0] - y).square().sum(-1).mean()
            o.zero_grad()
            loss.backward()
            o.step()
    for p, q in zip(ours.parameters(), ref.parameters(), strict=True):
        torch.testing.assert_close(p, q, rtol=1e-5, atol=1e-7)


def test_a_stacked_epoch_on_the_fallbacks_trains_the_same_weights(public_only):
    """The stack's Adam and ReLU backward through public operations: the seeds still train as
    with autograd, to float32 rounding (the private kernels' own test is in test_stacked)."""
    g = torch.Generator().manual_seed(0)
    s, m = torch.rand(64 * 20 + 1, 5, generator=g), torch.rand(64 * 20 + 1, 2, generator=g)
    net = StackedEncoders.from_models([build_model("sm", seed=3)])
    train_epoch_stacked(net, s, m, [3], 0, 64)
    alone = build_model("sm", seed=3)
    train_epoch_feedforward(alone, FusedAdam(alone.parameters()), s, m, 64, epoch_generator(3, 0))
    stacked = net.load_into(0, build_model("sm", seed=0))
    for p, q in zip(stacked.parameters(), alone.parameters(), strict=True):
        torch.testing.assert_close(p, q, rtol=1e-4, atol=1e-5)
