"""Independent jobs (trainings, analyses) in worker processes, one torch thread each.

Tiny models train fastest one thread per process (two threads in one process are slower), so
the way to use a machine's cores is one worker per core. Workers report progress through a
queue; the parent prints it in one place. A worker dies with its parent (Linux), so a killed
run never leaves orphans writing into the folders a rerun will use.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import platform
import queue as queue_mod
import signal
import threading
import time
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from sensorimotor.errors import InputError
from sensorimotor.version import __version__

_progress_queue = None  # set in each worker by _init_worker


@dataclass(frozen=True)
class Job:
    """One unit of work: ``fn(*args)`` run in a worker; ``name`` says what it is (a run name)."""

    name: str
    fn: Callable[..., Any]
    args: tuple = field(default=())


@dataclass(frozen=True)
class JobFailure:
    """What a failed job raised, kept so that the other jobs can finish."""

    name: str
    error: BaseException


def raise_first(
    failures: list[JobFailure], prefix: str = "", log: Callable[[str], None] | None = None
) -> None:
    """Raise the first failure, named (``prefix`` before its name), after logging the others;
    an InputError stays one line (a job's error that names the job already is not named twice).
    Nothing if there is none."""
    if not failures:
        return
    if log is not None:
        for f in failures[1:]:
            log(f"[red]failed: {f.name}: {f.error}")
    first = failures[0]
    more = f" (and {len(failures) - 1} more)" if len(failures) > 1 else ""
    if isinstance(first.error, InputError):
        msg = str(first.error)
        msg = msg if msg.startswith(first.name) else f"{first.name}: {msg}"
        raise InputError(f"{prefix}{msg}{more}")
    raise RuntimeError(f"{prefix}{first.name} failed{more}: {first.error}") from first.error


def send_progress(name: str, message: str) -> None:
    """Send a progress line from inside a job to the parent (printed there), or drop it."""
    if _progress_queue is not None:
        _progress_queue.put((name, message))


PROGRESS_EVERY = 10.0  # seconds: the most often a job's ``progress_sender`` sends a line


def progress_sender(name: str, every: float = PROGRESS_EVERY) -> Callable[[str, bool], None]:
    """``send(message, last=False)``: ``send_progress`` of job ``name`` at most every ``every``
    seconds (and always when ``last``), so a long job shows in its parent's log."""
    sent = [-float("inf")]

    def send(message: str, last: bool = False) -> None:
        now = time.monotonic()
        if last or now - sent[0] >= every:
            send_progress(name, message)
            sent[0] = now

    return send


def _die_with_parent() -> None:
    try:
        import ctypes

        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        pass


def _init_worker(progress_queue, threads: int) -> None:
    global _progress_queue
    _progress_queue = progress_queue
    _die_with_parent()
    # Ctrl-C reaches every process of the terminal's group; the parent alone answers it (by
    # stopping the workers), else each worker would fail its job and go on to the next one.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    limit_threads(threads)


def _stop_workers(pool: ProcessPoolExecutor) -> None:
    """Drop the queued jobs and end the running ones now. What they finished is on disk (every
    file is written whole and renamed), so a rerun goes on from there."""
    processes = list((pool._processes or {}).values())  # no public handle on the workers
    pool.shutdown(wait=False, cancel_futures=True)
    for process in processes:
        process.terminate()
    for process in processes:
        process.join(timeout=3)
        if process.is_alive():  # SIGTERM not acted on: a worker must not outlive the command
            process.kill()
            process.join(timeout=5)


THREAD_VARIABLES = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def limit_threads(threads: int) -> None:
    """Hold this process to ``threads`` threads in every native pool, not only torch's: left
    alone, scikit-learn's OpenMP (k-means) and numpy's BLAS in an analysis take every core and
    slow the worker training beside it (by about 15 %, measured)."""
    for var in THREAD_VARIABLES:  # pools of libraries loaded from now on
        os.environ[var] = str(threads)
    import torch
    from threadpoolctl import threadpool_limits

    torch.set_num_threads(threads)
    threadpool_limits(threads)  # pools already loaded


def run_jobs(
    jobs: list[Job],
    workers: int,
    on_progress: Callable[[str, str], None] | None = None,
    on_done: Callable[[str, Any], None] | None = None,
    threads: int = 1,
    then: Callable[[str, Any], list[Job]] | None = None,
) -> tuple[dict[str, Any], list[JobFailure]]:
    """Run every job, ``workers`` at a time; returns (results by name, failures).

    With ``workers == 1`` the jobs run in this process, in order. A failing job does not stop
    the others: its exception is returned, for the caller to name. ``then(name, result)`` of
    a job that succeeded gives jobs that need it, queued behind those already there.
    """
    global _progress_queue
    results: dict[str, Any] = {}
    failures: list[JobFailure] = []
    if workers <= 1 or (len(jobs) <= 1 and then is None):
        import torch

        before, old_queue = torch.get_num_threads(), _progress_queue
        torch.set_num_threads(threads)
        _progress_queue = _ListQueue(on_progress)
        try:
            queue = list(jobs)
            while queue:
                job = queue.pop(0)
                try:
                    results[job.name] = job.fn(*job.args)
                    if on_done is not None:
                        on_done(job.name, results[job.name])
                    if then is not None:
                        queue += then(job.name, results[job.name])
                except Exception as err:
                    failures.append(JobFailure(job.name, err))
        finally:
            _progress_queue = old_queue
            torch.set_num_threads(before)
        return results, failures

    ctx = mp.get_context("spawn")
    progress_queue = ctx.Queue()
    stop = threading.Event()

    def pump() -> None:
        while not stop.is_set():
            try:
                name, message = progress_queue.get(timeout=0.1)
            except queue_mod.Empty:
                continue
            except (EOFError, OSError, ValueError):  # a worker killed mid-message
                return
            if on_progress is not None:
                on_progress(name, message)

    printer = threading.Thread(target=pump, daemon=True)
    printer.start()
    interrupted = False
    try:
        with ProcessPoolExecutor(
            max_workers=workers if then is not None else min(workers, len(jobs)),
            mp_context=ctx,
            initializer=_init_worker,
            initargs=(progress_queue, threads),
        ) as pool:
            pending = {pool.submit(job.fn, *job.args): job for job in jobs}
            try:
                while pending:
                    done, _ = wait(pending, return_when=FIRST_COMPLETED)
                    for future in done:
                        job = pending.pop(future)
                        try:
                            results[job.name] = future.result()
                            if on_done is not None:
                                on_done(job.name, results[job.name])
                            more = [] if then is None else then(job.name, results[job.name])
                        except Exception as err:
                            failures.append(JobFailure(job.name, err))
                            continue
                        pending.update({pool.submit(j.fn, *j.args): j for j in more})
            except KeyboardInterrupt:
                interrupted = True
                _stop_workers(pool)
                raise
    finally:
        stop.set()
        # A worker stopped while writing leaves half a message, which a read would wait on for
        # ever: after Ctrl-C, neither wait for the printer nor read what is left.
        printer.join(timeout=1 if interrupted else None)
        while not interrupted:  # flush what is left
            try:
                name, message = progress_queue.get_nowait()
            except (queue_mod.Empty, OSError, ValueError):
                break
            if on_progress is not None:
                on_progress(name, message)
    return results, failures


class _ListQueue:
    """In-process stand-in for the progress queue: calls the printer at once."""

    def __init__(self, on_progress):
        self.on_progress = on_progress

    def put(self, item) -> None:
        if self.on_progress is not None:
            self.on_progress(*item)


def default_workers() -> int:
    return max(
        1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else os.cpu_count() or 1
    )


def hardware() -> dict:
    """What the numbers were measured on."""

    import torch

    info = {
        "python": platform.python_version(),
        "platform": platform.platform(),
        "processor": cpu_name(),
        "cpus": default_workers(),
        "torch": torch.__version__,
        "cuda": torch.cuda.get_device_name(0) if torch.cuda.is_available() else None,
        "sensorimotor": __version__,
    }
    return info


def cpu_name() -> str:
    """The CPU's model name (``/proc/cpuinfo``), or the platform's processor string."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"
