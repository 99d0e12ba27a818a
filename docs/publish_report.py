"""Copy a reproduction's report into docs/: `python docs/publish_report.py runs/paper`.

Writes docs/results.md (the report, image links rewritten) and docs/results/ (its images,
downscaled and palette-compressed so that the repository stays small), plus the small files of
each trained run (config, history, result, best weights) so that evaluation can be rerun.
"""

from __future__ import annotations

import re
import shutil
import sys
from pathlib import Path

from PIL import Image

SCALE = 0.7  # of the report's 150-dpi figures
COLORS = 64
RUN_FILES = ("config.json", "history.csv", "result.json", "model.pt")


def publish(report_dir: Path, docs: Path) -> None:
    md = (report_dir / "report.md").read_text()
    dest = docs / "results"
    images = re.findall(r"!\[[^\]]*\]\(([^)]+)\)", md)
    # replace only the report's own folders: the experiments' (map, rl, memory, ...) stay
    for folder in {Path(rel).parts[0] for rel in images if len(Path(rel).parts) > 1} | {"runs"}:
        if (dest / folder).exists():
            shutil.rmtree(dest / folder)
    for rel in images:
        out = dest / rel
        out.parent.mkdir(parents=True, exist_ok=True)
        im = Image.open(report_dir / rel).convert("RGB")
        im = im.resize((int(im.width * SCALE), int(im.height * SCALE)), Image.LANCZOS)
        im.quantize(colors=COLORS, method=Image.Quantize.MEDIANCUT).save(out, optimize=True)
        md = md.replace(f"]({rel})", f"](results/{rel})")
    for run in sorted((report_dir / "runs").iterdir()):
        for name in RUN_FILES:
            if (run / name).exists():
                (dest / "runs" / run.name).mkdir(parents=True, exist_ok=True)
                shutil.copy2(run / name, dest / "runs" / run.name / name)
    for name in ("table1.json", "claims.json", "timings.json"):
        shutil.copy2(report_dir / name, dest / name)
    (docs / "results.md").write_text(md)


if __name__ == "__main__":
    publish(Path(sys.argv[1]), Path(__file__).parent)
