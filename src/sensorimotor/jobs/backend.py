"""Where many jobs run: worker processes on this machine (``workers``) or Ray tasks on a
cluster (``ray_backend``), behind one door. ``reproduce``, ``sweep`` and ``rl`` take the same
``--backend local|ray --address --workers`` options and check them here."""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import contextmanager
from functools import partial
from typing import Any

from sensorimotor.errors import InputError
from sensorimotor.jobs import workers as local
from sensorimotor.jobs.workers import Job, raise_first

BACKENDS = ("local", "ray")
GPU_SHARE = 0.25  # of a GPU, held by each Ray task of a CUDA job (tiny models)


def check_backend(backend: str, address: str | None, workers: int | None) -> None:
    """Refuse an unknown backend, an address without Ray, fewer than one worker."""
    if backend not in BACKENDS:
        raise InputError(f"--backend: use {' or '.join(BACKENDS)}, got {backend!r}")
    if address is not None and backend != "ray":
        raise InputError("--address joins a Ray cluster: add --backend ray")
    if workers is not None and workers < 1:
        raise InputError(f"--workers must be at least 1, got {workers}")


@contextmanager
def job_runner(
    backend: str, address: str | None = None, workers: int | None = None, gpus: float = 0.0
) -> Iterator[tuple[Callable, int]]:
    """``(run_jobs, workers)`` of the backend, ``workers.run_jobs``'s signature: worker
    processes here (every core unless ``workers``), or Ray tasks on the cluster at ``address``
    (or on one started here for the block; every CPU of the cluster unless ``workers``)."""
    check_backend(backend, address, workers)
    if backend == "local":
        yield local.run_jobs, local.default_workers() if workers is None else workers
        return
    from sensorimotor.jobs import ray_backend

    with ray_backend.ray_session(address, workers) as cpus:
        yield partial(ray_backend.run_jobs, gpus=gpus), cpus if workers is None else workers


def run_all(
    run_jobs: Callable, workers: int, jobs: list[tuple[str, Callable, tuple]], on_progress=None
) -> dict[str, Any]:
    """Run ``(name, function, arguments)`` jobs; their results by name, or the first failure
    raised, named (an InputError stays one line)."""
    results, failures = run_jobs([Job(*job) for job in jobs], workers, on_progress)
    raise_first(failures)
    return results
