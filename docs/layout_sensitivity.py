"""How much of Table I is the layout? The published Square models (docs/results/runs) tested on
families of Rooms1 and Rooms2 layouts that fit the paper's sentences (``experiments.walls``).

Run by hand: ``python docs/layout_sensitivity.py [--layouts 20] [--data-seeds 2] [--steps
100000] [--out docs/results]``; writes ``layout_sensitivity.json`` and ``.md`` into --out.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from sensorimotor.experiments.walls import FAMILY_SIZE, sensitivity_markdown, wall_sensitivity
from sensorimotor.files import write_text_atomic

ROOT = Path(__file__).resolve().parent


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, default=ROOT / "results" / "runs")
    parser.add_argument("--layouts", type=int, default=FAMILY_SIZE, help="layouts per family")
    parser.add_argument("--data-seeds", type=int, default=2, help="test databases per layout")
    parser.add_argument("--steps", type=int, default=100_000, help="steps per test database")
    parser.add_argument("--out", type=Path, default=ROOT / "results")
    args = parser.parse_args()
    runs = sorted(args.runs.glob("square__*__s*"))
    result = wall_sensitivity(
        runs, layouts=args.layouts, data_seeds=range(args.data_seeds), steps=args.steps,
        log=lambda line: print(line, file=sys.stderr, flush=True),
    )  # fmt: skip
    result["command"] = "python " + " ".join([Path(sys.argv[0]).as_posix(), *sys.argv[1:]])
    result["runs"] = [_shown(r) for r in runs]
    text = sensitivity_markdown(result) + f"\nMade by `{result['command']}`.\n"
    write_text_atomic(args.out / "layout_sensitivity.json", json.dumps(result, indent=2))
    write_text_atomic(args.out / "layout_sensitivity.md", text)
    print(text)


def _shown(path: Path) -> str:
    """A run folder's path as the JSON records it: relative to the repository when inside it."""
    try:
        return path.resolve().relative_to(ROOT.parent).as_posix()
    except ValueError:
        return str(path)


if __name__ == "__main__":
    main()
