"""The stages' cache: each output of ``reproduce`` and of its experiments is kept beside the key
of what it was made from (a short hash of a JSON-able description of its inputs), and redone
only when the key it would be made with now differs."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path


def stage_key(obj) -> str:
    """A short stable hash of a JSON-able description of a stage's inputs."""
    return hashlib.sha256(json.dumps(obj, sort_keys=True).encode()).hexdigest()[:16]


def read_key(path: Path) -> str | None:
    """The ``key`` recorded in the JSON file ``path``; None where there is none to read."""
    from sensorimotor.files import read_json_if_any

    try:
        return read_json_if_any(path, "stage record")["key"]
    except (KeyError, TypeError):
        return None
