"""The map experiment (``experiments/map.py``) on the shipped paper-scale runs.

    PYTHONPATH=src python docs/results/map/paper_maps.py OUT DATA_DIR [--models raw,rec-sm]
        [--worlds rooms1,rooms2] [--seeds 1,3,5]

``DATA_DIR`` holds ``{world}.npz``, the 1,000,000-step seed-0 databases reproduce makes
(``sensorimotor generate WORLD --steps 1000000 --seed 0``; checked against the runs' recorded
SHA-256). The runs are ``docs/results/runs/{world}__{model}__s{seed}``. Each pass of
``--seeds`` (1, then 3, then 5 seeds) fits only the maps not fitted yet (the stage's cache)
and writes ``OUT/map/map.json`` and ``OUT/map/map.md``; ``--workers N`` maps at a time
(default one, in this process; ``--zcache`` applies in this process only).
``--extra-models s,sm,rec-s --extra-seeds M``: those models too, seeds 0..M-1 only.
``--raw-seeds N``: raw mapped with seeds 0..N-1 only (default: as many as the runs), so that
the CPU goes to the trained runs' seeds first. ``--zcache DIR``: z_s of each run on its own world's splits, read from
``DIR/{run}__{split}.npy`` where present (they are computed the same way otherwise).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from sensorimotor import experiments as ex
from sensorimotor.analysis.map import mapping
from sensorimotor.experiments import map as map_stage
from sensorimotor.files import file_hash, write_text_atomic
from sensorimotor.jobs.workers import run_jobs
from sensorimotor.report.blocks import to_markdown

RUNS = Path(__file__).resolve().parents[1] / "runs"


def main(argv: list[str]) -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out", type=Path)
    ap.add_argument("data", type=Path)
    ap.add_argument("--models", default="raw,rec-sm")
    ap.add_argument("--worlds", default="rooms1,rooms2")
    ap.add_argument("--seeds", default="1,3,5")
    ap.add_argument("--raw-seeds", type=int, default=None)
    ap.add_argument("--extra-models", default="")
    ap.add_argument("--extra-seeds", type=int, default=1)
    ap.add_argument("--zcache", type=Path, default=None)
    ap.add_argument("--workers", type=int, default=1)
    a = ap.parse_args(argv)
    if not 1 <= a.workers <= 64:  # each worker holds a database and a map (about 1-2 GB)
        ap.error(f"--workers must lie in [1, 64], got {a.workers}")
    worlds = tuple(a.worlds.split(","))
    models = [m for m in a.models.split(",") if m != "raw"]
    extra = [m for m in a.extra_models.split(",") if m]
    data = {w: a.data / f"{w}.npz" for w in worlds}
    for w in worlds:  # the databases the runs were trained on
        want = json.loads((RUNS / f"{w}__rec-sm__s0" / "config.json").read_text())["data"]
        if file_hash(data[w]) != want["sha256"]:
            sys.exit(f"{data[w]}: not the database the runs were trained on")
    if a.zcache is not None:
        plain = mapping.representation_of

        def cached(run, db, split="test"):
            name = getattr(run, "path", None)
            f = None if name is None else a.zcache / f"{Path(name).name}__{split}.npy"
            if f is not None and f.exists() and Path(name).name.startswith(db.world.name):
                return np.load(f, allow_pickle=False)
            return plain(run, db, split)

        mapping.representation_of = cached
    if a.raw_seeds is not None:
        every = map_stage.targets
        map_stage.targets = lambda rep: [
            t for t in every(rep) if t[1] != "raw" or t[4] < a.raw_seeds
        ]
    for n in map(int, a.seeds.split(",")):
        rep = SimpleNamespace(
            out=a.out,
            scale=SimpleNamespace(name="paper"),
            seeds=n,
            worlds=worlds,
            data=data,
            runs=[(w, m, s) for w in worlds for m in models for s in range(n)]
            + [(w, m, s) for w in worlds for m in extra for s in range(min(n, a.extra_seeds))],
            run_dir=lambda w, m, s: RUNS / f"{w}__{m}__s{s}",
        )
        ctx = ex.Context(rep, "map", run_jobs, a.workers, _say, print)
        found = ex.run_experiment(ctx)
        md = to_markdown(ex.sections(rep, {"map": found}), a.out)
        write_text_atomic(a.out / "map" / "map.md", md)
        print(f"{n} seed(s) done", flush=True)


def _say(job: str, message: str) -> None:
    print(job, message, flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
