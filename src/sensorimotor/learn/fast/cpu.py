"""Process settings that make CPU training faster without changing a number."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator

import torch


def keep_freed_memory() -> bool:
    """Keep freed memory in the process's heap instead of handing it back to the kernel.

    An LSTM step allocates and frees workspaces of a few MB; by default glibc maps each afresh
    and the kernel zero-fills its pages on first touch, a sizeable part of a recurrent step
    (``benchmarks/bench_train.py`` measures it). No effect on the numbers. Returns whether it
    took effect (glibc only; elsewhere a no-op).
    """
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6")
        m_trim_threshold, m_mmap_threshold = -1, -3
        return bool(
            libc.mallopt(m_mmap_threshold, 32 << 20) and libc.mallopt(m_trim_threshold, 1 << 30)
        )
    except (OSError, AttributeError):
        return False


@contextlib.contextmanager
def flush_subnormals() -> Iterator[None]:
    """Within the block, this thread's float arithmetic treats subnormal numbers (below
    1.2e-38 in float32) as zero; on leaving it, the mode it found is restored.

    Adam's moments of a weight whose gradient is 0 (a dead ReLU unit) decay geometrically
    through the subnormal range, and on some x86 CPUs every operation on a subnormal takes a
    slow path, so S and SM epochs slow down as training goes on (``docs/benchmarks.md``
    says by how much). Flushed, they do not; the weights stay the same bit for bit, as a number
    that small moves no weight in float32.
    """
    was = flushing()
    torch.set_flush_denormal(True)
    try:
        yield
    finally:
        torch.set_flush_denormal(was)


def flushing() -> bool:
    """Whether this thread flushes subnormals: 1e-39 (subnormal in float32) times 1 is 0."""
    return float(torch.tensor(1e-39) * 1.0) == 0.0
