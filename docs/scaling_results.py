"""Copy a reproduction's scaling experiment into docs/results/scaling/: its numbers
(scaling.json), its report section as Markdown (scaling.md) and the figures the section shows.

    python docs/scaling_results.py OUT "how OUT was made (the command, its time)"

OUT is the folder of ``sensorimotor reproduce --experiment scaling --out OUT``.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path
from types import SimpleNamespace

from sensorimotor.experiments.scaling import section
from sensorimotor.files import write_text_atomic
from sensorimotor.report.blocks import p, to_markdown

DEST = Path(__file__).parent / "results" / "scaling"


def main(out: Path, note: str) -> None:
    found = json.loads((out / "scaling" / "scaling.json").read_text())
    DEST.mkdir(parents=True, exist_ok=True)
    shutil.copy(out / "scaling" / "scaling.json", DEST / "scaling.json")
    # the figures the section shows, where it looks for them (relative to docs/results/)
    first_unseen = found["conditions"]["plans"]["test_worlds"][0]
    for rel in (
        Path("errors.png"),
        Path("analysis") / f"plans__rec-sm__s0__on__{first_unseen}" / "clusters.png",
    ):
        (DEST / rel).parent.mkdir(parents=True, exist_ok=True)
        shutil.copy(out / "scaling" / rel, DEST / rel)
    blocks = section(SimpleNamespace(out=DEST.parent), found)
    blocks.insert(1, p(note))
    write_text_atomic(DEST / "scaling.md", to_markdown(blocks, DEST))


if __name__ == "__main__":
    main(Path(sys.argv[1]), sys.argv[2])
