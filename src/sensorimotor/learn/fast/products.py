"""Batched products over stacked seeds, each in the orientation the BLAS is fast at.

Each seed has its own matrices: tensors carry a leading seed axis K. A BLAS (MKL) can be
several times slower on a tall product with few columns, (1280, 128) x (128, 10) say, than on
its transpose (``benchmarks/bench_train.py`` measures the whole step). So a product narrower
than ``NARROW`` columns is computed as its transpose, and the result is a transposed view; the
caller never sees the difference but in the strides.
"""

from __future__ import annotations

import torch

ALIGN_ROWS = 16  # gathered rows padded to a multiple of this: 64-byte aligned seed slabs
NARROW = 16  # a product with fewer columns than this runs as its transpose (see matmul)
TALL = 512  # from this many rows on, a weight gradient runs as its transpose (weight_grad)


def matmul(a: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """a @ b for (K, M, n) x (K, n, N)."""
    if b.shape[-1] < NARROW <= a.shape[-2]:
        return torch.bmm(b.mT, a.mT).mT
    return torch.bmm(a, b)


def linear(h: torch.Tensor, w: torch.Tensor, b: torch.Tensor) -> torch.Tensor:
    """b + h W^T, as F.linear: h (K, B, in), w (K, out, in), b (K, 1, out)."""
    if w.shape[-2] < NARROW <= h.shape[-2]:
        return torch.baddbmm(b.mT, w, h.mT).mT
    return torch.baddbmm(b, h, w.mT)


def weight_grad(dy: torch.Tensor, h: torch.Tensor, out: torch.Tensor, add: bool = False) -> None:
    """out (K, out, in) = dy^T h (``add``: out += dy^T h), for dy (K, B, out) and h (K, B, in).
    Over a tall B (a recurrent chunk's 1,280 steps) the product with fewer rows is the faster
    one, and the copy into out costs little."""
    if h.shape[-1] < NARROW <= dy.shape[-1] or (h.shape[-2] >= TALL and h.shape[-1] < dy.shape[-1]):
        g = torch.bmm(h.mT, dy).mT
        if add:
            out.add_(g)
        else:
            out.copy_(g)
    elif add:
        out.add_(torch.bmm(dy.mT, h))
    else:
        torch.bmm(dy.mT, h, out=out)
