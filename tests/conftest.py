"""Shared fixtures: small real databases, the real command line (in this process), one thread;
the longest modules collected first."""

from __future__ import annotations

import contextlib
import io
import os
import signal
import subprocess
import sys
import traceback
from pathlib import Path

import pytest
import torch

from sensorimotor.sim.database import generate, save_database
from sensorimotor.sim.world import load_world

LONGEST_FIRST = ("tests/pipeline/test_paper.py", "tests/jobs/test_ray.py")
"""Modules of minutes (a whole reproduction, a Ray cluster): collected first, so that with
``--dist loadscope`` (pyproject) each worker starts on one of them and the short modules fill
the rest, instead of one of them starting last on one worker while the other idles."""


def pytest_collection_modifyitems(items: list) -> None:
    items.sort(key=lambda item: item.nodeid.split("::")[0] not in LONGEST_FIRST)  # stable


def run_cli(*args: str | Path, cwd: Path | None = None, timeout: float = 600):
    """The command line on ``args`` as ``python -m sensorimotor ARGS`` runs it (``cli.run``: the
    same parsing, one-line errors and exit status), in this process: a command costs its work,
    not a Python and torch start. What a command may change in the process (torch's threads, the
    environment, the working folder) is put back; an unexpected exception is a traceback on
    stderr and exit 1, as Python's; past ``timeout`` seconds, TimeoutError. Returns a
    CompletedProcess (text output)."""
    from sensorimotor.cli import run

    argv = [str(a) for a in args]

    def too_long(*_):
        raise TimeoutError(f"sensorimotor {' '.join(argv)} took over {timeout:g} s")

    out, err = io.StringIO(), io.StringIO()
    threads, env, here = torch.get_num_threads(), dict(os.environ), os.getcwd()
    alarm = signal.signal(signal.SIGALRM, too_long)
    signal.setitimer(signal.ITIMER_REAL, timeout)
    try:
        if cwd is not None:
            os.chdir(cwd)
        with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
            try:
                rc = run(argv)
            except SystemExit as exit_:
                rc = exit_.code if isinstance(exit_.code, int) else 1
            except TimeoutError:
                raise
            except Exception:
                traceback.print_exc()
                rc = 1
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, alarm)
        os.chdir(here)
        torch.set_num_threads(threads)
        os.environ.clear()
        os.environ.update(env)
    command = [sys.executable, "-m", "sensorimotor", *argv]
    return subprocess.CompletedProcess(command, rc, out.getvalue(), err.getvalue())


def alive(pid: int, group: bool = False) -> bool:
    """Whether process ``pid`` (or process group ``pid``, with ``group``) still exists."""
    try:
        (os.killpg if group else os.kill)(pid, 0)
    except ProcessLookupError:
        return False
    return True


def assert_one_line_error(proc, *needles: str) -> None:
    """Exit 2, one line on stderr that contains every needle, no traceback."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout, proc.stderr)
    lines = [ln for ln in proc.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, proc.stderr
    assert "Traceback" not in proc.stderr
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])


@pytest.fixture
def cli():
    return run_cli


@pytest.fixture(scope="session")
def square_db_path(tmp_path_factory) -> Path:
    """A 20,000-step Square database (seed 0)."""
    path = tmp_path_factory.mktemp("data") / "square.npz"
    save_database(generate(load_world("square"), 20_000, seed=0), path)
    return path


@pytest.fixture(scope="session")
def rooms1_db_path(tmp_path_factory) -> Path:
    """A 20,000-step Rooms1 database (seed 1)."""
    path = tmp_path_factory.mktemp("data") / "rooms1.npz"
    save_database(generate(load_world("rooms1"), 20_000, seed=1), path)
    return path


@pytest.fixture
def one_thread():
    """Training runs on one thread (TrainConfig.threads); so do the references here."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)
