"""Is a new Table I inside the shipped one's seed spread? (issue 38: a faster or re-timed grid
must not move the science): `python docs/table1_spread.py NEW/table1.json [SHIPPED]`.

For every cell (trained on, model, tested on) both tables hold, it prints the new mean beside
the shipped mean, sd and the range of its seeds, and says whether the new mean lies within one
shipped sd and inside the range; then how many cells do. SHIPPED defaults to
`docs/results/table1.json` (the paper-scale runs in `docs/results/runs`).
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

SHIPPED = Path(__file__).parent / "results" / "table1.json"


def cells(table: dict) -> dict[tuple[str, str, str], dict]:
    """(trained on, model, tested on) -> the cell's mean, sd and per-seed values."""
    return {
        (trained, row["model"], tested): cell
        for trained, rows in table["tables"].items()
        for row in rows
        for tested, cell in row["cells"].items()
    }


def main() -> None:
    if len(sys.argv) not in (2, 3):
        raise SystemExit(__doc__.splitlines()[1].strip())
    new = cells(json.loads(Path(sys.argv[1]).read_text()))
    old = cells(json.loads(Path(sys.argv[2] if len(sys.argv) == 3 else SHIPPED).read_text()))
    shared = [key for key in old if key in new]
    if not shared:
        raise SystemExit("error: the two tables share no cell")
    print(
        "| trained on | model | tested on | new | shipped mean ± sd [seeds' range] | gap | in sd | in range |"
    )
    print("|---|---|---|---|---|---|---|---|")
    in_sd = in_range = 0
    for key in shared:
        n, o = new[key]["mean"], old[key]
        lo, hi = min(o["values"]), max(o["values"])
        sd_ok, range_ok = abs(n - o["mean"]) <= o["sd"], lo <= n <= hi
        in_sd, in_range = in_sd + sd_ok, in_range + range_ok
        print(
            f"| {' | '.join(key)} | {n:.5f} | {o['mean']:.5f} ± {o['sd']:.5f} [{lo:.5f}, {hi:.5f}]"
            f" | {n / o['mean'] - 1:+.1%} | {'yes' if sd_ok else 'no'} | {'yes' if range_ok else 'no'} |"
        )
    print(
        f"\n{len(shared)} cells: {in_sd} within one shipped sd, {in_range} inside the shipped "
        "seeds' range"
    )


if __name__ == "__main__":
    main()
