"""Representation learning by sensorimotor prediction (Kulak & Garcia Ortiz), reproduced.

The package is a house of rooms, each holding one trade and importing only those before it::

    sim          worlds, the simulated robot, databases, events, figures  (numpy, numba)
    learn        the encoders (one registry of kinds), training, run folders, evaluation (torch)
    analysis     representations, clusters, probes, claims, Table I; ``analysis.map``: the map
    jobs         worker processes, Ray, the stages' cache (no science)
    pipeline     the paper's stages as jobs, the sweep
    report       the document
    experiments  past the paper: map, scaling, rl (one registry)
    reproduce    the front door: the paper's stages, the chosen experiments, the report

with ``stats`` (statistics over seeds, verdicts) below them all, and ``envs`` (the Gymnasium
environment, on ``sim``), ``rl`` (agents, on ``learn`` and ``envs``) and ``cli`` (the command
line) at the edges. What a
notebook needs is importable from here; each name loads its layer on first use, so
``import sensorimotor`` stays light:

>>> import sensorimotor
>>> world = sensorimotor.load_world("square")
>>> db = sensorimotor.generate(world, steps=1_000, seed=0)
>>> db.sensors.shape, db.motors.shape, db.poses.shape
((1000, 5), (1000, 2), (1000, 3))
"""

from __future__ import annotations

import importlib

from sensorimotor import portable

portable.apply()  # before numpy, numba or torch load (SENSORIMOTOR_PORTABLE=1)

from sensorimotor.errors import InputError  # noqa: E402
from sensorimotor.version import __version__  # noqa: E402

# public name -> the module that defines it
_API = {
    "World": "sensorimotor.sim.world",
    "load_world": "sensorimotor.sim.world",
    "Database": "sensorimotor.sim.database",
    "generate": "sensorimotor.sim.database",
    "load_database": "sensorimotor.sim.database",
    "save_database": "sensorimotor.sim.database",
    "import_bag": "sensorimotor.sim.rosbag",
    "corner_in_view": "sensorimotor.sim.events",
    "ModelConfig": "sensorimotor.learn.models",
    "build_model": "sensorimotor.learn.models",
    "TrainConfig": "sensorimotor.learn.config",
    "train": "sensorimotor.learn.train",
    "train_seeds": "sensorimotor.learn.train",
    "load_run": "sensorimotor.learn.evaluate",
    "evaluate_run": "sensorimotor.learn.evaluate",
    "encode": "sensorimotor.learn.evaluate",
    "analyze_files": "sensorimotor.analysis.analyze",
    "map_files": "sensorimotor.analysis.map.mapping",
    "reproduce": "sensorimotor.reproduce",
}

__all__ = ["InputError", "__version__", *_API]


def __getattr__(name: str):
    """Load a public name's layer on first use (PEP 562)."""
    if name not in _API:
        raise AttributeError(f"module 'sensorimotor' has no attribute {name!r}")
    value = getattr(importlib.import_module(_API[name]), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(__all__)
