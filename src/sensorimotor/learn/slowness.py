"""A slowness prior on the sensory representation (``TrainConfig.slow_dims``, rec-sma):
slow feature analysis's temporal coherence, the robotic priors' first, added to the loss.

Where the robot turns faster than it changes place, the slowest features of its history are
the place; the prediction loss alone does not ask z_s for them. The prior asks z_s's first D
dimensions to change slowly within each training window, as a ratio (scale-free, so a
feature that shrinks earns nothing) with its spread held up by a hinge (so a feature cannot
meet it by collapsing to where the ratio's floor decides). The pilots that chose this form
are in ``docs/results/memory/README.md``, "A slowness prior".
"""

from __future__ import annotations

import torch

FLOOR = 1e-8  # added to a window's variance: the ratio stays finite for a constant feature
LEAST_STD = 0.1  # a slow dimension's least spread within a window (the free ones: 0.3-0.8)


def window_variance(z: torch.Tensor) -> torch.Tensor:
    """Each dimension's variance within a stream's window of z (..., B, T, D), averaged over
    the B streams -> (..., D)."""
    return z.var(dim=-2, unbiased=False).mean(-2)


def slowness(z: torch.Tensor, floor: float = FLOOR) -> torch.Tensor:
    """How fast the features z (..., B, T, D) change within each of B streams' windows: each
    dimension's mean squared step over its variance within a stream (averaged over streams,
    plus ``floor``), averaged over the dimensions -> (...,)."""
    steps = (z[..., 1:, :] - z[..., :-1, :]).square().mean((-3, -2))  # (..., D)
    return (steps / (window_variance(z) + floor)).mean(-1)


def spread_hinge(z: torch.Tensor) -> torch.Tensor:
    """How far each dimension's standard deviation within the windows of z (..., B, T, D)
    falls below ``LEAST_STD``, squared and averaged over the dimensions -> (...,)."""
    return torch.relu(LEAST_STD - window_variance(z).sqrt()).square().mean(-1)


def slowness_prior(z: torch.Tensor, dims: int) -> torch.Tensor:
    """The prior on the first ``dims`` dimensions of the beliefs z (..., B, T, 10) of one
    chunk: ``slowness`` plus ``spread_hinge`` -> (...,), one value per seed of a stack."""
    slow = z[..., :dims]
    return slowness(slow) + spread_hinge(slow)


def prior_gradient(z: torch.Tensor, dims: int, weight: float) -> torch.Tensor:
    """d (weight x ``slowness_prior``) / d z for beliefs z (..., B, T, 10), each leading index
    (a seed of a stack) its own prior: what the hand-written passes add to the loss's gradient
    of z_s (``fast.stacked_open_loop``)."""
    with torch.enable_grad():
        leaf = z.detach().requires_grad_()
        (grad,) = torch.autograd.grad(weight * slowness_prior(leaf, dims).sum(), leaf)
    return grad
