"""The three claims of the map stage (``experiments.map.verdict``, its margins) for the slow-context
map over the seeds in ``context_plan.log`` (tau 400, 20 clones, no EM), against the Markov numbers
and the shipped EM map's of ``docs/results/map/map.json``. Run from the project root."""

import json
import re
from pathlib import Path

from sensorimotor.experiments.map import MARGINS, verdict

HERE = Path(__file__).parent
LINE = re.compile(
    r"^(\w+) \w+__rec-sm__s(\d) tau=400.0 C=20 em=0: bits ([\d.]+).*balanced map ([\d.]+) "
    r"cells ([\d.]+);.*planning map ([\d.]+) random ([\d.]+)"
)
shipped = json.loads((HERE.parent / "map.json").read_text())["worlds"]
rows: dict = {}
for line in (HERE / "context_plan.log").read_text().splitlines():
    if m := LINE.match(line):
        w, s = m[1], int(m[2])
        rows.setdefault(w, {})[s] = [float(x) for x in m.groups()[2:]]
for w, by_seed in sorted(rows.items()):
    seeds = sorted(by_seed)
    bits, bal_map, bal_cells, plan_map, plan_random = zip(*(by_seed[s] for s in seeds), strict=True)
    metrics = shipped[w]["rec-sm"]["metrics"]
    markov = [metrics["bits.markov"]["values"][s] for s in seeds]
    em_map = [metrics["bits.map"]["values"][s] for s in seeds]
    claims = {
        "predicts (Markov - map, bits/step)": verdict(markov, list(bits), MARGINS["predicts"]),
        "localises (balanced: map - cells)": verdict(
            list(bal_map), list(bal_cells), MARGINS["localises"]
        ),
        "plans (map - random)": verdict(
            list(plan_map), list(plan_random), MARGINS["plans"], [100] * len(seeds)
        ),
    }
    print(
        f"{w}, seeds {seeds}: bits/step slow-context map {sum(bits) / len(bits):.3f}, "
        f"shipped EM map {sum(em_map) / len(em_map):.3f}, Markov {sum(markov) / len(markov):.3f}"
    )
    for name, v in claims.items():
        print(
            f"  {name}: {v.numbers['mean']:+.3f} (SE {v.numbers['se']:.3f}, margin "
            f"{MARGINS[name.split()[0]]}): {v.word('holds', 'does NOT hold')}"
        )
