"""Adam as ``torch.optim.Adam(fused=True)`` computes it, minus its per-step Python work."""

from __future__ import annotations

from collections.abc import Iterable

import torch

from sensorimotor.learn.fast.private import adam_, add_


class FusedAdam:
    """Adam (betas 0.9, 0.999, eps 1e-8, no weight decay) over a model's parameters.

    With a few thousand weights a step is bound by per-call overhead, and the stock optimiser's
    bookkeeping costs about as much as the model's backward pass. This calls the same fused
    kernel directly on lists built once (``private.adam_``). A test checks it matches
    ``torch.optim.Adam`` exactly.
    """

    def __init__(
        self,
        params: Iterable[torch.Tensor],
        lr: float = 1e-3,
        betas: tuple[float, float] = (0.9, 0.999),
        eps: float = 1e-8,
    ):
        self.params = [p for p in params if p.requires_grad]
        self.lr, self.betas, self.eps = lr, betas, eps
        self.exp_avg = [torch.zeros_like(p) for p in self.params]
        self.exp_avg_sq = [torch.zeros_like(p) for p in self.params]
        self.steps = [torch.zeros((), dtype=torch.float32, device=p.device) for p in self.params]
        self.graphs: dict = {}  # CUDA graphs of steps with these parameters (fast.cuda_graphs)

    def zero_grad(self) -> None:
        for p in self.params:
            p.grad = None

    @torch.no_grad()
    def step(self) -> None:
        grads = [p.grad for p in self.params]
        lists = (self.params, grads, self.exp_avg, self.exp_avg_sq, self.steps)
        if any(g is None for g in grads):  # one the loss did not reach is left as it is,
            keep = [i for i, g in enumerate(grads) if g is not None]  # as torch's Adam leaves it
            lists = tuple([x[i] for i in keep] for x in lists)
        add_(lists[-1], 1)
        adam_(*lists, self.lr, self.betas, self.eps)

    def state_dict(self) -> dict:
        return {"exp_avg": self.exp_avg, "exp_avg_sq": self.exp_avg_sq, "steps": self.steps}

    def load_state_dict(self, state: dict) -> None:
        for name in ("exp_avg", "exp_avg_sq", "steps"):
            for dst, src in zip(getattr(self, name), state[name], strict=True):
                dst.copy_(src)
