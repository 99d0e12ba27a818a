"""The report section of a Rooms1 grid from the rl.json of each task folder present (as
reproduce writes it): ``python section.py FOLDER`` writes ``FOLDER/section.md``."""

import json
import sys
from pathlib import Path
from types import SimpleNamespace

from sensorimotor.experiments import rl as rl_stage
from sensorimotor.report.blocks import to_markdown

out = Path(sys.argv[1])
tasks, steps = {}, {}
for task in rl_stage.tasks():
    if not (out / task / "rl.json").is_file():
        continue
    rl = json.loads((out / task / "rl.json").read_text())
    for r in rl["results"].values():
        del r["curve"]
    tasks[task] = {"folder": task, "rl": rl}
    steps[task] = rl["steps"]
found = {"headline": rl["headline"], "world": "rooms1", "seeds": rl["seeds"], "steps": steps,
         "eval_episodes": rl["eval_episodes"], "tasks": tasks}  # fmt: skip
blocks = rl_stage.section(SimpleNamespace(out=out), found)
(out / "section.md").write_text(to_markdown(blocks, out))
