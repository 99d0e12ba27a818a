"""The package's layout: layers whose imports point one way, no import cycle, small modules.

Every import counts, at the top of a module, inside a function or under ``TYPE_CHECKING``:
an import moved into a function to dodge a cycle is still a cycle.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import sensorimotor

PACKAGE = Path(sensorimotor.__file__).parent
# a module's layer: the first part of its name below the package; a layer may import its own
# and those listed for it
BASE = {"errors", "files", "version", "stats"}
LAYERS = {
    "errors": set(),
    "version": set(),
    "portable": set(),  # environment settings the numerical libraries read when they load
    "files": {"errors"},
    "stats": {"errors"},
    "sim": BASE,
    "learn": BASE | {"sim"},
    "analysis": BASE | {"sim", "learn"},
    "jobs": {"errors", "files", "version"},  # runs jobs; imports nothing of the science
    "pipeline": BASE | {"sim", "learn", "analysis", "jobs"},
    "report": BASE | {"sim", "learn", "analysis", "pipeline"},  # never an experiment
    "envs": {"errors", "sim"},
    "rl": BASE | {"sim", "learn", "envs", "jobs"},  # jobs: an agent's progress to its parent
    "experiments": BASE | {"sim", "learn", "analysis", "jobs", "pipeline", "report", "rl"},
    "reproduce": BASE | {"learn", "jobs", "pipeline", "report", "experiments"},
    "cli": BASE
    | {"sim", "learn", "analysis", "jobs", "pipeline", "report", "rl", "reproduce"},
    "__main__": {"cli"},
    "__init__": {"errors", "version", "portable", "sim", "learn", "analysis", "reproduce"},
}
# learn.fast: the speed of the one loop. It reads the model definition, the batching and the
# optimiser's private kernels, and the loop reaches it through one door (``learn.engine``).
FAST = "sensorimotor.learn.fast"
# what fast computes (the model, the slowness prior of the loss) and the order it reads the data
FAST_MAY_IMPORT = {
    "sensorimotor.learn.models",
    "sensorimotor.learn.slowness",
    "sensorimotor.learn.batches",
}
FAST_DOOR = {"sensorimotor.learn.engine"}
MAX_TOP_LEVEL = 8
MAX_LINES = 600


def module_name(path: Path) -> str:
    parts = path.relative_to(PACKAGE).with_suffix("").parts
    if parts[-1] == "__init__" and len(parts) > 1:
        parts = parts[:-1]
    return ".".join(("sensorimotor", *parts))


def imports_of(path: Path) -> set[str]:
    """Every sensorimotor module that ``path`` imports, wherever the import statement is."""
    name = module_name(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")
                anchor = anchor[: len(anchor) - node.level + 1]
                base = ".".join([*anchor, base] if base else anchor)
            found.add(base)
            found |= {f"{base}.{a.name}" for a in node.names}  # `from pkg import module`
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", "") == "import_module":
            found |= {a.value for a in node.args if isinstance(a, ast.Constant)}
        elif isinstance(node, ast.Dict):  # the lazy public API: {"name": "sensorimotor.x.y"}
            found |= {
                v.value
                for v in node.values
                if isinstance(v, ast.Constant) and str(v.value).startswith("sensorimotor.")
            }
    return {m for m in found if m.split(".")[0] == "sensorimotor"}


MODULES = {module_name(p): p for p in sorted(PACKAGE.rglob("*.py"))}
GRAPH = {
    name: {m for m in imports_of(path) if m in MODULES} - {name} for name, path in MODULES.items()
}


def layer(module: str) -> str:
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else "__init__"


def test_every_import_points_down_the_layers():
    wrong = [
        f"{a} imports {b}"
        for a, targets in GRAPH.items()
        for b in targets
        if layer(b) != layer(a) and layer(b) not in LAYERS[layer(a)]
    ]
    assert not wrong, wrong


def test_fast_imports_only_the_model_the_prior_the_batches_and_itself_through_one_door():
    inside = {m for m in GRAPH if m == FAST or m.startswith(FAST + ".")}
    out_of_fast = [
        f"{a} imports {b}"
        for a in inside
        for b in GRAPH[a]
        if b not in inside and b not in FAST_MAY_IMPORT and layer(b) == "learn"
    ]
    assert not out_of_fast, out_of_fast
    into_fast = [
        f"{a} imports {b}"
        for a, targets in GRAPH.items()
        if a not in inside and a not in FAST_DOOR
        for b in targets
        if b in inside
    ]
    assert not into_fast, into_fast


def test_no_import_cycle():
    """Depth-first search over the whole graph; a back edge is a cycle, printed in full."""
    state: dict[str, int] = {}  # 1: on the current path, 2: done
    path: list[str] = []

    def visit(m: str) -> list[str] | None:
        state[m] = 1
        path.append(m)
        for n in sorted(GRAPH[m]):
            if state.get(n) == 1:
                return [*path[path.index(n) :], n]
            if n not in state and (cycle := visit(n)):
                return cycle
        path.pop()
        state[m] = 2
        return None

    for m in sorted(GRAPH):
        if m not in state:
            cycle = visit(m)
            assert cycle is None, " -> ".join(cycle)


def test_the_checks_find_a_cycle_and_an_upward_import(tmp_path, monkeypatch):
    """The graph reader sees imports inside functions and under TYPE_CHECKING."""
    sim = tmp_path / "sim"
    sim.mkdir()
    (sim / "a.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from sensorimotor.learn import x\n"
        "def f():\n    from . import b\n"
    )
    monkeypatch.setattr(f"{__name__}.PACKAGE", tmp_path)
    assert imports_of(sim / "a.py") >= {"sensorimotor.learn.x", "sensorimotor.sim.b"}


def test_the_top_level_is_small_and_every_module_readable_in_one_sitting():
    top = [p.name for p in PACKAGE.glob("*.py")]
    assert len(top) <= MAX_TOP_LEVEL, top
    long = {n: len(p.read_text().splitlines()) for n, p in MODULES.items()}
    assert not {n: k for n, k in long.items() if k > MAX_LINES}


@pytest.mark.parametrize("name", sensorimotor.__all__)
def test_the_public_api_resolves(name):
    assert getattr(sensorimotor, name) is not None


def test_a_model_kinds_name_is_written_in_the_registry_alone():
    """Facts written once: no module but the registry spells a kind's name as a string (a
    list of kinds is read from ``learn.kinds.KINDS``, a particular kind named by its constant)."""
    from sensorimotor.learn.models import KINDS

    spelled: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text())
        prose = {  # the literal text of f-strings ("3 epochs"): words, not names
            id(v) for n in ast.walk(tree) if isinstance(n, ast.JoinedStr) for v in n.values
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and node.value in KINDS and id(node) not in prose:
                spelled.setdefault(name, set()).add(node.value)
    assert set(spelled) <= {"sensorimotor.learn.kinds"}, spelled
