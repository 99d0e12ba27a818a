"""The slowness prior (``learn.slowness``): what it measures, its gradient for a stack of
seeds, and that training with it makes the chosen dimensions of z_s slower."""

from __future__ import annotations

import json
import math

import pytest
import torch

from conftest import assert_one_line_error
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.engine import FusedAdam, train_epoch_recurrent
from sensorimotor.learn.models import REC_SMA, build_model
from sensorimotor.learn.slowness import (
    LEAST_STD,
    prior_gradient,
    slowness,
    slowness_prior,
    spread_hinge,
)

pytestmark = pytest.mark.usefixtures("one_thread")


def _waves(periods: list[float], b: int = 3, t: int = 256) -> torch.Tensor:
    """Sines of the given periods (in steps), one a dimension, in b streams: (b, t, D)."""
    steps = (
        torch.arange(t, dtype=torch.float64)[None, :, None] + 17 * torch.arange(b)[:, None, None]
    )
    return torch.sin(2 * math.pi * steps / torch.tensor(periods, dtype=torch.float64))


def test_a_slower_feature_scores_lower_whatever_its_scale():
    slow, fast = slowness(_waves([200.0])), slowness(_waves([20.0]))
    assert slow < fast / 50  # the mean squared step goes as the frequency squared
    assert slowness(0.03 * _waves([200.0])) == pytest.approx(float(slow), rel=1e-4)  # to FLOOR
    # a constant within each window (a latched value) earns nothing: its ratio is the floor's
    latched = torch.arange(3.0)[:, None, None].expand(3, 256, 1) + 1e-3 * torch.randn(3, 256, 1)
    assert slowness(latched) > 1.0


def test_the_hinge_holds_the_spread_up_and_lets_a_wide_feature_be():
    wide, narrow = _waves([64.0]), 0.01 * _waves([64.0])  # std 0.71 and 0.0071
    assert spread_hinge(wide) == 0
    expected = (LEAST_STD - float(narrow.var(dim=1, unbiased=False).mean().sqrt())) ** 2
    assert float(spread_hinge(narrow)) == pytest.approx(expected, rel=1e-9)


def test_the_prior_reads_only_its_dimensions_and_each_seed_of_a_stack_alone():
    g = torch.Generator().manual_seed(0)
    z = torch.randn(2, 4, 30, 10, generator=g)  # (K seeds, B, T, 10)
    grad = prior_gradient(z, 3, 0.5)
    assert grad[..., 3:].abs().max() == 0
    assert grad[..., :3].abs().max() > 0
    for k in range(2):
        alone = z[k].clone().requires_grad_()
        (0.5 * slowness_prior(alone, 3)).backward()
        torch.testing.assert_close(grad[k], alone.grad)


def test_training_with_the_prior_slows_its_dimensions_and_not_the_others():
    g = torch.Generator().manual_seed(1)
    s, m = torch.rand(4 * 256 * 3 + 1, 5, generator=g), torch.rand(4 * 256 * 3 + 1, 2, generator=g)
    c = TrainConfig.of(REC_SMA)

    def trained(slow_dims: int) -> torch.Tensor:
        model = build_model(REC_SMA, seed=0)
        opt = FusedAdam(model.parameters(), lr=c.lr)
        for _ in range(4):
            train_epoch_recurrent(
                model, opt, s, m, c.batch_size, c.horizon, c.ahead, c.ahead_every,
                slow_dims=slow_dims, slow_weight=10.0,
            )  # fmt: skip
        with torch.no_grad():
            z, _ = model.encode(s[None, :256], None, m[None, :256])  # (1, 256, 10)
        return torch.stack([slowness(z[..., i : i + 1]) for i in range(10)])

    with_prior, without = trained(4), trained(0)
    assert with_prior[:4].mean() < 0.5 * without[:4].mean()
    assert with_prior[4:].mean() > 0.5 * without[4:].mean()


def test_cli_records_the_prior_and_refuses_more_dimensions_than_z_s(square_db_path, tmp_path, cli):
    args = ["train", "rec-sma", "--data", square_db_path, "--max-epochs", "1"]
    proc = cli(*args, "--out", tmp_path / "wide", "--set", "slow_dims=11")
    assert_one_line_error(proc, "slow_dims", "z_s has 10 dimensions")
    assert not (tmp_path / "wide").exists()
    proc = cli(*args, "--out", tmp_path / "run", "--set", "slow_dims=4", "--set", "slow_weight=0.5")
    assert proc.returncode == 0, proc.stderr
    train = json.loads((tmp_path / "run" / "config.json").read_text())["train"]
    assert (train["slow_dims"], train["slow_weight"]) == (4, 0.5)
