"""What Rec-SMA's open-loop head reaches when its belief is the true pose (issue 32's diagnosis).

    PYTHONPATH=src python docs/results/memory/pose_oracle.py TRAIN.npz FRESH.npz [--set k=v ...]

Rec-SMA (``learn/models.py``) predicts the readings 1..32 steps ahead from its belief z_s and
the commands in between, through its transition and predictor. Its memory has not learnt the
place (room 0.43 balanced accuracy at 5 seeds). Two explanations differ in where the limit is:
the memory (the head could render the readings from a place code, but the memory does not
learn one), or the head (given the place, the 10-d belief, the transition and the predictor
still cannot predict far, so the loss gives the memory no reason to learn it).

This script separates them. It replaces the memory by the true pose: z_s = g(x/50, y/50,
cos h, sin h), g an MLP 4 -> 64 -> 64 -> 10. The same ``SensorimotorEncoder.ahead``, with
the kind's sizes (or ``--set`` ones), is trained on the ``ahead`` loss of ``TRAIN``'s train
split, the best epoch picked on its validation split. The open-loop errors are scored on
``FRESH``'s test split, for k = 1, 2, 4, 8, 16, 32, beside the mean reading's error.
No memory is learnt here: this is the head's ceiling, not a model to ship.
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import time

import numpy as np
import torch

from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.evaluate import split_tensors
from sensorimotor.learn.models import REC_SMA, ModelConfig, SensorimotorEncoder, mlp
from sensorimotor.sim.database import load_database

SHOW = (1, 2, 4, 8, 16, 32)


def pose_features(poses: np.ndarray, size: float = 50.0) -> torch.Tensor:
    """(n, 3) poses -> (n, 4): x and y over the world's size, cos and sin of the heading."""
    x, y, h = poses[:, 0] / size, poses[:, 1] / size, poses[:, 2]
    return torch.from_numpy(np.stack([x, y, np.cos(h), np.sin(h)], 1).astype(np.float32))


def split(db, name: str) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Pose features, scaled readings and scaled commands of one split."""
    return (pose_features(db.take(name).poses), *split_tensors(db, name))


def windows(steps: int, starts: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Index arrays of the commands m_t .. m_{t+K-1} and targets s_{t+1} .. s_{t+K}."""
    k = torch.arange(steps)
    return starts[:, None] + k, starts[:, None] + k + 1


def errors(g, model, data, steps: int, every: int = 1) -> torch.Tensor:
    """(K,) the paper's error of each k over the starts t = 0, every, ... with K targets."""
    pose, sensors, motors = data
    starts = torch.arange(0, len(sensors) - steps, every)
    total = torch.zeros(steps, dtype=torch.float64)
    with torch.no_grad():
        for chunk in starts.split(20_000):
            m_idx, s_idx = windows(steps, chunk)
            z = g(pose[chunk])[:, None]  # (B, 1, 10)
            pred = model.ahead(z, motors[m_idx], steps)[:, :, 0]  # (K, B, 5)
            target = sensors[s_idx].transpose(0, 1)  # (K, B, 5)
            total += ((pred - target) ** 2).sum(-1).sum(-1).double()
    return (total / len(starts)).float()


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("train")
    ap.add_argument("fresh")
    ap.add_argument("--epochs", type=int, default=60)
    ap.add_argument("--batch", type=int, default=256)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", nargs="*", default=[], help="ModelConfig sizes, e.g. predictor_hidden=512")
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    sizes = {k: int(v) for k, v in (s.split("=") for s in args.set)}
    config = ModelConfig(kind=REC_SMA, **sizes)
    steps, every = TrainConfig.of(REC_SMA).ahead, TrainConfig.of(REC_SMA).ahead_every
    model = SensorimotorEncoder(config)
    g = mlp([4, 64, 64, config.z_sensors])
    params = [p for n, p in model.named_parameters() if not n.startswith(("lstm", "sensor_"))]
    params += list(g.parameters())
    opt = torch.optim.Adam(params, lr=1e-3)
    db, fresh = load_database(args.train), load_database(args.fresh)
    train, val, test = split(db, "train"), split(db, "val"), split(fresh, "test")
    pose, sensors, motors = train
    all_starts = torch.arange(0, len(sensors) - steps, every)
    best, best_state, history = math.inf, None, []
    for epoch in range(args.epochs):
        t0 = time.time()
        order = all_starts[torch.randperm(len(all_starts))]
        for batch in order.split(args.batch):
            m_idx, s_idx = windows(steps, batch)
            pred = model.ahead(g(pose[batch])[:, None], motors[m_idx], steps)[:, :, 0]
            loss = ((pred - sensors[s_idx].transpose(0, 1)) ** 2).sum(-1).mean()
            opt.zero_grad()
            loss.backward()
            opt.step()
        v = float(errors(g, model, val, steps, every).mean())
        history.append(v)
        if v < best:
            best, best_state = v, (copy.deepcopy(g.state_dict()), copy.deepcopy(model.state_dict()))
        print(f"epoch {epoch + 1}: val open-loop mean {v:.4f} ({time.time() - t0:.0f} s)", flush=True)
    g.load_state_dict(best_state[0])
    model.load_state_dict(best_state[1])
    e = errors(g, model, test, steps)
    mean_reading = float(((test[1] - train[1].mean(0)) ** 2).sum(-1).mean())
    out = {
        "sizes": sizes,
        "epochs": args.epochs,
        "best_val_open_loop_mean": best,
        "test_open_loop": {str(k): round(float(e[k - 1]), 4) for k in SHOW},
        "test_open_loop_mean": round(float(e.mean()), 4),
        "mean_reading_error": round(mean_reading, 4),
        "val_history": [round(h, 4) for h in history],
    }
    print(json.dumps(out))


if __name__ == "__main__":
    main()
