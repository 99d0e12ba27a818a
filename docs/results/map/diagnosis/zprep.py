"""Compute z_s of Rec-SM runs on their own world's train/test splits into z2/ (a cache)."""

import os
import time
from pathlib import Path

import numpy as np
import torch

from sensorimotor.learn.evaluate import encode, load_run
from sensorimotor.sim.database import load_database

# DATA: the folder of {world}.npz (sensorimotor generate WORLD --steps 1000000 --seed 0);
# Z: the z_s cache of zprep.py. Both from the environment; run from the project root.
DATA = os.environ.get("DATA", "data")
Z = os.environ.get("Z", "z")

torch.set_num_threads(1)  # 2 threads on the loaded 2-core machine: about 150 times slower

root = Path("docs/results/runs")
dbs = {}
for seed in range(1, 5):
    for world in ("rooms1", "rooms2"):
        name = f"{world}__rec-sm__s{seed}"
        run = load_run(root / name)
        db = dbs.setdefault(world, load_database(f"{DATA}/{world}.npz"))
        for split in ("train", "test"):
            f = Path(f"{Z}/{name}__{split}.npy")
            if f.exists():
                continue
            t = time.time()
            z = encode(run, db, split)
            np.save(str(f) + ".tmp.npy", z)
            Path(str(f) + ".tmp.npy").rename(f)
            print(name, split, round(time.time() - t), "s", flush=True)
