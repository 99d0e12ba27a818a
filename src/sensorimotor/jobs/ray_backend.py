"""The worker pool on Ray: the same ``run_jobs`` as ``workers.run_jobs``, each job a Ray task.

Past one machine, the jobs of ``reproduce`` (and a sweep's trials) run on a Ray cluster
instead of local worker processes: each job becomes a task holding one CPU (and a GPU fraction
when it trains on CUDA), placed by Ray on any node. What does not change: a job is a plain
top-level function with picklable arguments; its progress (``workers.send_progress``) reaches the same
display, here through a small actor the tasks write to and the driver drains; a failing job
comes back as the exception it raised, named by its job; Ctrl-C cancels this run's tasks
(killing their processes: every file is written whole and renamed, so a rerun goes on). Files
are read and written by path, so the output folder must be on a file system every node sees.

Ray is an optional extra (``pip install -e ".[ray]"``), imported only when asked for.
"""

from __future__ import annotations

import socket
import time
import traceback
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

from sensorimotor.errors import InputError
from sensorimotor.jobs import workers as local
from sensorimotor.jobs.workers import Job, JobFailure

MISSING = 'Ray is not installed: pip install -e ".[ray]" (or pip install "ray[tune]>=2.9,<3")'
DRAIN_EVERY = 0.2  # seconds between reads of the progress actor


def import_ray():
    """The ``ray`` module, or an InputError in one line that says how to install it."""
    try:
        import ray
    except ImportError:
        raise InputError(MISSING) from None
    return ray


@contextmanager
def ray_session(address: str | None = None, num_cpus: int | None = None) -> Iterator[int]:
    """Join the Ray cluster at ``address`` (None: start one on this machine with ``num_cpus``
    CPUs) unless this process is connected already; yields the cluster's CPU count. A session
    this call started is shut down at the end; one found running is left as it was."""
    ray = import_ray()
    started = not ray.is_initialized()
    if started:
        _check_reachable(address)
        try:
            ray.init(
                address=address,
                num_cpus=None if address else num_cpus,
                include_dashboard=False,
                logging_level="ERROR",
                configure_logging=False,
            )
        except (ConnectionError, ValueError, RuntimeError) as err:
            where = f"at {address}" if address else "on this machine"
            first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
            raise InputError(f"--address: cannot reach a Ray cluster {where} ({first})") from None
    try:
        yield max(1, int(ray.cluster_resources().get("CPU", 1)))
    finally:
        if started:
            ray.shutdown()


def _check_reachable(address: str | None, seconds: float = 5.0) -> None:
    """Refuse at once a ``HOST:PORT`` where nothing listens (``ray.init`` would retry for
    minutes); other forms (``auto``, ``ray://...``) are Ray's to check."""
    host, sep, port = (address or "").rpartition(":")
    if not sep or not host or "/" in host or not port.isdigit():
        return
    try:
        socket.create_connection((host.strip("[]"), int(port)), timeout=seconds).close()
    except OSError as err:
        raise InputError(
            f"--address: cannot reach a Ray cluster at {address} ({err.strerror or err}); "
            "`ray start --head` prints the address to give"
        ) from None


class _ProgressBox:
    """Where tasks leave their progress lines until the driver takes them (a Ray actor)."""

    def __init__(self) -> None:
        self.lines: list[tuple[str, str]] = []

    def put(self, item: tuple[str, str]) -> None:
        self.lines.append(item)

    def take(self) -> list[tuple[str, str]]:
        lines, self.lines = self.lines, []
        return lines


class _ActorQueue:
    """``workers.send_progress``'s queue inside a task: each line goes to the progress actor."""

    def __init__(self, box) -> None:
        self.box = box
        self.last = None

    def put(self, item: tuple[str, str]) -> None:
        self.last = self.box.put.remote(item)

    def flush(self) -> None:
        """Wait until the actor holds every line sent (it takes one caller's calls in order),
        so that a job's lines are there before its result reaches the driver."""
        if self.last is not None:
            import ray

            ray.get(self.last)


class RemoteTraceback(Exception):
    """The traceback of a job that failed in a task, as text (the ``__cause__`` of its error)."""

    def __str__(self) -> str:
        return f'\n"""\n{self.args[0]}"""'


def _run_job(fn: Callable[..., Any], args: tuple, box, threads: int) -> tuple[bool, Any, str]:
    """A job in a Ray task: (True, result, "") or (False, the exception it raised, traceback).
    The exception is returned, not raised, so that the driver gets it as the job raised it."""
    local.limit_threads(threads)
    queue = _ActorQueue(box)
    before, local._progress_queue = local._progress_queue, queue
    try:
        return True, fn(*args), ""
    except Exception as err:
        return False, err, traceback.format_exc()
    finally:
        local._progress_queue = before
        queue.flush()


def run_jobs(
    jobs: list[Job],
    workers: int,
    on_progress: Callable[[str, str], None] | None = None,
    on_done: Callable[[str, Any], None] | None = None,
    threads: int = 1,
    then: Callable[[str, Any], list[Job]] | None = None,
    gpus: float = 0.0,
) -> tuple[dict[str, Any], list[JobFailure]]:
    """``workers.run_jobs`` on the Ray cluster this process is connected to (``ray_session``):
    at most ``workers`` tasks at a time, each with ``threads`` CPUs and ``gpus`` of a GPU.

    Returns (results by name, failures); a failing job does not stop the others; ``then(name,
    result)`` of a job that succeeded gives jobs queued behind those already there."""
    ray = import_ray()
    if not ray.is_initialized():
        raise RuntimeError("ray_backend.run_jobs: no Ray session (use ray_session)")
    results: dict[str, Any] = {}
    failures: list[JobFailure] = []
    if not jobs:
        return results, failures
    task = ray.remote(num_cpus=threads, num_gpus=gpus, max_retries=0)(_run_job)
    box = ray.remote(num_cpus=0)(_ProgressBox).remote()
    queue = list(jobs)
    pending: dict[Any, Job] = {}

    def drain() -> None:
        for name, message in ray.get(box.take.remote()):
            if on_progress is not None:
                on_progress(name, message)

    try:
        last = time.monotonic()
        while queue or pending:
            while queue and len(pending) < max(1, workers):
                job = queue.pop(0)
                pending[task.remote(job.fn, job.args, box, threads)] = job
            done, _ = ray.wait(list(pending), num_returns=1, timeout=DRAIN_EVERY)
            if time.monotonic() - last >= DRAIN_EVERY or done:
                drain()  # before a job's result: its lines come first, as locally
                last = time.monotonic()
            for ref in done:
                job = pending.pop(ref)
                try:
                    ok, value, trace = ray.get(ref)
                except ray.exceptions.RayError as err:  # the task's process died
                    ok, value, trace = False, RuntimeError(f"Ray task lost: {err}"), ""
                if not ok:
                    if trace:
                        value.__cause__ = RemoteTraceback(trace)
                    failures.append(JobFailure(job.name, value))
                    continue
                try:
                    results[job.name] = value
                    if on_done is not None:
                        on_done(job.name, value)
                    queue += [] if then is None else then(job.name, value)
                except Exception as err:
                    failures.append(JobFailure(job.name, err))
        drain()
    except KeyboardInterrupt:
        for ref in pending:  # this run's tasks, and no other's
            ray.cancel(ref, force=True)
        raise
    finally:
        ray.kill(box)
    return results, failures
