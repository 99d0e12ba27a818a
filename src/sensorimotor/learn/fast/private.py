"""Every private PyTorch function the project calls, each beside a public fallback.

Private functions (a leading underscore, or ``torch.ops.aten``) are not a stable API: a new
PyTorch may rename or drop them. Each is looked up once, here; where the lookup fails, or
where ``USE_PRIVATE`` is False (tests switch it), the fallback below it runs instead: public
operations, the same arithmetic in the same order, so the numbers do not change beyond
float32 rounding (tests compare the two).
"""

from __future__ import annotations

import torch

USE_PRIVATE = True  # False: the public fallbacks everywhere (tests compare the two)

_FUSED_ADAM = getattr(torch, "_fused_adam_", None)
_FOREACH_ADD = getattr(torch, "_foreach_add_", None)
try:
    _THRESHOLD_BACKWARD = torch.ops.aten.threshold_backward.grad_input
except (AttributeError, RuntimeError):  # pragma: no cover - a PyTorch without it
    _THRESHOLD_BACKWARD = None


def adam_(
    params: list[torch.Tensor],
    grads: list[torch.Tensor],
    exp_avg: list[torch.Tensor],
    exp_avg_sq: list[torch.Tensor],
    steps: list[torch.Tensor],
    lr: float,
    betas: tuple[float, float] = (0.9, 0.999),
    eps: float = 1e-8,
) -> None:
    """One Adam step of every tensor in place, each at its own step count (already counted):

        m <- b1 m + (1 - b1) g      v <- b2 v + (1 - b2) g^2
        p <- p - lr / (1 - b1^t) * m / (sqrt(v) / sqrt(1 - b2^t) + eps)

    ``torch._fused_adam_`` (what ``torch.optim.Adam(fused=True)`` calls) does it in one kernel
    over all the lists; the fallback in public operations, tensor by tensor."""
    if USE_PRIVATE and _FUSED_ADAM is not None:
        _FUSED_ADAM(  # lists as given: a step is bound by per-call overhead
            params,
            grads,
            exp_avg,
            exp_avg_sq,
            [],
            steps,
            lr=lr,
            beta1=betas[0],
            beta2=betas[1],
            weight_decay=0.0,
            eps=eps,
            amsgrad=False,
            maximize=False,
        )
        return
    b1, b2 = betas
    with torch.no_grad():
        for p, g, m, v, t in zip(params, grads, exp_avg, exp_avg_sq, steps, strict=True):
            step = float(t)
            m.lerp_(g, 1 - b1)
            v.mul_(b2).addcmul_(g, g, value=1 - b2)
            denom = (v.sqrt() / (1 - b2**step) ** 0.5).add_(eps)
            p.addcdiv_(m, denom, value=-lr / (1 - b1**step))


def add_(tensors: list[torch.Tensor], value: float) -> None:
    """Add ``value`` to every tensor in place: ``torch._foreach_add_`` in one call, or a loop."""
    if USE_PRIVATE and _FOREACH_ADD is not None:
        _FOREACH_ADD(tensors, value)
        return
    for t in tensors:
        t.add_(value)


def relu_grad_(dy: torch.Tensor, h: torch.Tensor) -> torch.Tensor:
    """dy zeroed where the ReLU output h is not positive, in place, and returned: autograd's
    ReLU backward (``aten.threshold_backward``) writing into dy, or ``masked_fill_``."""
    if USE_PRIVATE and _THRESHOLD_BACKWARD is not None:
        return _THRESHOLD_BACKWARD(dy, h, 0, grad_input=dy)
    return dy.masked_fill_(h <= 0, 0.0)
