"""Compute z_s of Rec-SM runs on their own world's train/test splits into z2/ (a cache)."""

import time
from pathlib import Path

import numpy as np
import torch

from sensorimotor.learn.evaluate import load_run, representation
from sensorimotor.sim.database import load_database

torch.set_num_threads(1)  # 2 threads on the loaded 2-core machine: about 150 times slower

root = Path("/work/wt-22/docs/results/runs")
dbs = {}
for seed in range(1, 5):
    for world in ("rooms1", "rooms2"):
        name = f"{world}__rec-sm__s{seed}"
        run = load_run(root / name)
        db = dbs.setdefault(world, load_database(f"/work/scratch/i22/{world}.npz"))
        for split in ("train", "test"):
            f = Path(f"/work/scratch/i22/z2/{name}__{split}.npy")
            if f.exists():
                continue
            t = time.time()
            z = representation(run, db, split)
            np.save(str(f) + ".tmp.npy", z)
            Path(str(f) + ".tmp.npy").rename(f)
            print(name, split, round(time.time() - t), "s", flush=True)
