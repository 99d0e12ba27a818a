"""Worker processes: every job runs once, results come back by name, a failure is kept apart."""

from __future__ import annotations

import math
import operator

import pytest

from sensorimotor.jobs.workers import Job, run_jobs


@pytest.mark.parametrize("workers", [1, 2])
def test_results_by_name_and_failures_kept_apart(workers):
    jobs = [Job(f"add{i}", operator.add, (i, 10)) for i in range(5)]
    jobs.append(Job("bad", math.sqrt, (-1.0,)))
    done = []
    results, failures = run_jobs(jobs, workers, on_done=lambda name, r: done.append(name))
    assert results == {f"add{i}": i + 10 for i in range(5)}
    assert [f.name for f in failures] == ["bad"]
    assert isinstance(failures[0].error, ValueError)
    assert sorted(done) == sorted(results)


def test_in_process_progress_reaches_the_printer():
    from sensorimotor.jobs.workers import send_progress

    lines = []

    def job() -> int:
        send_progress("run-a", "epoch 0")
        return 1

    results, failures = run_jobs(
        [Job("run-a", job)], 1, on_progress=lambda n, m: lines.append((n, m))
    )
    assert results == {"run-a": 1}
    assert not failures
    assert lines == [("run-a", "epoch 0")]


@pytest.mark.parametrize("workers", [1, 2])
def test_follow_up_jobs_run_once_after_the_job_they_need(workers):
    """``then`` queues jobs behind a finished one: each runs once, with its result, and a
    failed job has none."""
    jobs = [Job(f"add{i}", operator.add, (i, 10)) for i in range(3)]
    jobs.append(Job("bad", math.sqrt, (-1.0,)))

    def then(name, result):
        if name.startswith("add"):
            return [Job(f"double-{name}", operator.mul, (result, 2))]
        return []

    results, failures = run_jobs(jobs, workers, then=then)
    assert results == {**{f"add{i}": i + 10 for i in range(3)},
                       **{f"double-add{i}": 2 * (i + 10) for i in range(3)}}  # fmt: skip
    assert [f.name for f in failures] == ["bad"]


def test_a_single_job_with_follow_ups_still_uses_the_workers():
    """One job whose follow-ups fan out: they run in worker processes, not all in this one."""
    import os

    def then(name, _):
        return [Job(f"pid{i}", os.getpid) for i in range(4)] if name == "first" else []

    results, _ = run_jobs([Job("first", os.getpid)], 2, then=then)
    assert os.getpid() not in results.values()


def _native_threads() -> list[int]:
    """The threads of torch and of every native pool an analysis loads (a worker's job)."""
    import sklearn.cluster  # noqa: F401  (loads scikit-learn's OpenMP)
    import torch
    from threadpoolctl import threadpool_info

    return [torch.get_num_threads()] + [pool["num_threads"] for pool in threadpool_info()]


def test_a_worker_holds_every_native_pool_to_its_threads():
    """Not only torch: scikit-learn's OpenMP and numpy's BLAS left at every core would slow the
    worker training beside an analysis."""
    jobs = [Job(f"job{i}", _native_threads) for i in range(2)]
    results, failures = run_jobs(jobs, 2)
    assert not failures
    for threads in results.values():
        assert len(threads) > 2  # torch and at least a BLAS and an OpenMP were seen
        assert set(threads) == {1}


def test_a_progress_sender_sends_at_most_every_interval_and_always_the_last(monkeypatch):
    from sensorimotor.jobs import workers

    sent = []
    monkeypatch.setattr(workers, "send_progress", lambda name, msg: sent.append((name, msg)))
    clock = [0.0, 1.0, 2.0, 11.0, 12.0]
    monkeypatch.setattr(workers.time, "monotonic", lambda: clock.pop(0) if clock else 99.0)
    send = workers.progress_sender("job", every=10.0)
    for i in range(4):
        send(f"step {i}")
    send("done", last=True)
    assert sent == [("job", "step 0"), ("job", "step 3"), ("job", "done")]
