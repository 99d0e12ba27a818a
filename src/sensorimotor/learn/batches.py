"""The order in which training sees the data: shuffled transitions (S, SM) and contiguous
streams (Rec-S, Rec-SM). An epoch's order depends on (seed, epoch) alone, so ``--resume``
repeats it and a seed trains the same alone or beside others."""

from __future__ import annotations

from collections.abc import Sequence

import torch


def epoch_generator(seed: int, epoch: int) -> torch.Generator:
    """The random generator of one seed's data order in one epoch."""
    return torch.Generator().manual_seed(seed * 1_000_003 + epoch)


def epoch_orders(n: int, seeds: Sequence[int], epoch: int) -> torch.Tensor:
    """Each seed's order of ``n`` transitions in one epoch, (K, n) indices:
    ``torch.randperm(n, generator=epoch_generator(seed, epoch))``, seed by seed."""
    return torch.stack([torch.randperm(n, generator=epoch_generator(s, epoch)) for s in seeds])


def stream_layout(n: int, streams: int) -> tuple[torch.Tensor, torch.Tensor]:
    """Cut ``n`` steps into ``streams`` contiguous streams: (index (streams, L), mask (streams, L)).

    Stream k holds steps ``index[k, :]`` in order; lengths differ by at most one (the first
    ``n % streams`` are one longer) and the shorter ones are padded at the end with mask False,
    so every step appears exactly once.
    """
    if n < streams:
        raise ValueError(f"{n} steps cannot fill {streams} streams")
    base, extra = divmod(n, streams)
    length = base + (extra > 0)
    lengths = torch.full((streams,), base)
    lengths[:extra] += 1
    starts = torch.cumsum(lengths, 0) - lengths
    offsets = torch.arange(length)
    mask = offsets[None, :] < lengths[:, None]  # (streams, L)
    index = torch.where(mask, starts[:, None] + offsets[None, :], 0)  # (streams, L)
    return index, mask
