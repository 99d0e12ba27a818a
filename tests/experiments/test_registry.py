"""Experiments past the paper as stages of reproduce: named, run into their own folder, their
numbers written as strict JSON, their sections handed to the report."""

from __future__ import annotations

import json
import sys
import types
from types import SimpleNamespace

import pytest

from sensorimotor import experiments as ex
from sensorimotor.errors import InputError
from sensorimotor.report.blocks import h, p


@pytest.fixture
def echo(monkeypatch):
    """A registered experiment that writes a file and returns the workers it was given."""
    mod = types.ModuleType("echo_experiment")

    def run(ctx):
        (ctx.dir / "made.txt").write_text(ctx.name)
        ctx.log("echo ran")
        return {"workers": ctx.workers, "value": ctx.rep.value}

    def section(rep, found):
        return [h(2, "Echo"), p(f"value {found['value']} on {found['workers']} workers")]

    mod.run, mod.section = run, section
    monkeypatch.setitem(sys.modules, "echo_experiment", mod)
    known = (ex.Experiment("echo", "echo_experiment", "echo"), ex.Experiment("other", "x", "x"))
    monkeypatch.setattr(ex, "EXPERIMENTS", {e.name: e for e in known})
    monkeypatch.setattr(ex, "DEFAULT", ("echo",))
    return mod


def test_names_are_checked_and_ordered(echo):
    assert ex.check_experiments(None) == ("echo",)
    assert ex.check_experiments(["none"]) == ()
    assert ex.check_experiments(["other", "echo"]) == ("echo", "other")
    with pytest.raises(InputError, match="use any of echo, other, none"):
        ex.check_experiments(["echo", "maze"])
    with pytest.raises(InputError, match="--experiment"):
        ex.check_experiments([""])


def test_an_experiment_runs_in_its_folder_and_its_section_reads_its_numbers(echo, tmp_path):
    lines: list[str] = []
    rep = SimpleNamespace(out=tmp_path, value=0.25)
    ctx = ex.Context(rep, "echo", None, 3, lambda *_: None, lines.append)
    found = ex.run_experiment(ctx)
    assert found == {"workers": 3, "value": 0.25}
    assert (tmp_path / "echo" / "made.txt").read_text() == "echo"
    assert json.loads((tmp_path / "echo" / "echo.json").read_text()) == found
    assert lines == ["echo ran"]
    blocks = ex.sections(rep, {"echo": found})
    assert [b.content for b in blocks] == ["Echo", "value 0.25 on 3 workers"]


def test_numbers_that_are_not_json_are_refused_and_nothing_is_written(echo, tmp_path):
    echo.run = lambda ctx: {"value": float("nan")}
    ctx = ex.Context(SimpleNamespace(out=tmp_path), "echo", None, 1, None, print)
    with pytest.raises(InputError, match="value is nan"):
        ex.run_experiment(ctx)
    assert not (tmp_path / "echo" / "echo.json").exists()


def test_a_failed_job_is_raised_as_the_experiments_one_line(tmp_path):
    from sensorimotor.jobs.workers import JobFailure

    def runner(failure):
        return lambda jobs, workers, progress: ({"a": 1}, [failure] if failure else [])

    def ctx(failure):
        return ex.Context(SimpleNamespace(out=tmp_path), "echo", runner(failure), 1, None, print)

    assert ctx(None).run([]) == {"a": 1}
    with pytest.raises(InputError, match=r"^echo: b: cannot square -1$"):
        ctx(JobFailure("b", InputError("cannot square -1"))).run([])
    with pytest.raises(RuntimeError, match=r"^echo: c failed: x$"):
        ctx(JobFailure("c", ZeroDivisionError("x"))).run([])


def test_each_chosen_experiments_check_runs_before_anything(echo):
    ex.check(SimpleNamespace(experiments=("echo",)))  # no check(rep): nothing to refuse

    def check(rep):
        if rep.value < 0:
            raise InputError("experiment echo: needs a value of 0 or more")

    echo.check = check
    ex.check(SimpleNamespace(experiments=("echo",), value=1))
    ex.check(SimpleNamespace(experiments=(), value=-1))  # not chosen: not checked
    with pytest.raises(InputError, match="needs a value"):
        ex.check(SimpleNamespace(experiments=("echo",), value=-1))
