"""The bytes a fixed small job gives on this CPU, to compare across CPU kinds (DESIGN.md,
"Determinism"): `python docs/determinism_probe.py WORK` and again with SENSORIMOTOR_PORTABLE=1.

It generates a 20,000-step Square database (seed 0) and trains SM and Rec-SM for two epochs,
seeds 0 and 1 stacked, then prints a Markdown row per output: the CPU, the switch, the output
and the SHA-256 of its bytes (a database file; a model's weights, tensor by tensor in
``state_dict`` order, so that the zip container's layout plays no part). Same CPU kind, same
rows; under the switch, the same rows on every x86 CPU with AVX2 is the claim to check.
"""

from __future__ import annotations

import hashlib
import os
import subprocess
import sys
from pathlib import Path

import torch

from sensorimotor.files import file_hash
from sensorimotor.jobs.workers import cpu_name

STEPS = 20_000
EPOCHS = 2


def weights_hash(model_pt: Path) -> str:
    """SHA-256 of a run's weights, tensor by tensor (``torch.load(weights_only=True)``)."""
    state = torch.load(model_pt, map_location="cpu", weights_only=True)  # a state_dict
    h = hashlib.sha256()
    for name, tensor in state.items():
        h.update(name.encode())
        h.update(tensor.contiguous().numpy().tobytes())
    return h.hexdigest()


def main(work: Path) -> None:
    cli = [sys.executable, "-m", "sensorimotor"]
    work.mkdir(parents=True, exist_ok=True)
    db = work / "square.npz"
    if not db.exists():
        subprocess.run(
            [*cli, "generate", "square", "--steps", str(STEPS), "--seed", "0", "--out", str(db)],
            check=True,
            capture_output=True,
        )
    rows = [("database square.npz", file_hash(db))]
    for kind in ("sm", "rec-sm"):
        out = work / kind
        if not out.exists():
            args = ["--data", str(db), "--out", str(out), "--seeds", "0,1"]
            subprocess.run(
                [*cli, "train", kind, *args, "--max-epochs", str(EPOCHS)],
                check=True,
                capture_output=True,
            )
        for run in sorted(out.iterdir()):
            rows.append((f"weights {run.name}", weights_hash(run / "model.pt")))
    switch = os.environ.get("SENSORIMOTOR_PORTABLE", "") == "1"
    print("| CPU | SENSORIMOTOR_PORTABLE | output | SHA-256 (first 16) |")
    print("|---|---|---|---|")
    for name, digest in rows:
        print(f"| {cpu_name()} | {int(switch)} | {name} | {digest[:16]} |")


if __name__ == "__main__":
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    main(Path(sys.argv[1]))
