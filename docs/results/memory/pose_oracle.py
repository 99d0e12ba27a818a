"""What Rec-SMA's open-loop head reaches when its belief is the true pose (issue 32's diagnosis).

    PYTHONPATH=src python docs/results/memory/pose_oracle.py TRAIN.npz FRESH.npz [--set k=v ...]
        [--oracle pose|scene] [--scene-range R] [--scene-rays N]

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

``--oracle scene`` gives g the scene instead of the place: a full turn of ``--scene-rays``
noiseless rays cast from the true pose (angles relative to the heading, so no world position
and no world heading), seeing ``--scene-range`` units, each over that range. With the range of
the robot's own lasers (10) it is what the robot could see by turning in place. If the scene
predicts the readings 32 steps ahead as well as the pose, the loss is met without the place.
Either way the 10-d belief g(.) is probed for the place on ``FRESH`` as every representation
is (``analysis.probes.place_probes``: fitted on the first 100,000 training steps, scored on
the test split).
"""

from __future__ import annotations

import argparse
import copy
import json
import math
import time

import numpy as np
import torch

from sensorimotor.analysis.probes import PROBE_FIT_MAX, place_probes
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.evaluate import split_tensors
from sensorimotor.learn.models import REC_SMA, ModelConfig, SensorimotorEncoder, mlp
from sensorimotor.sim.core import read_sensors, spread_layout
from sensorimotor.sim.database import load_database

SHOW = (1, 2, 4, 8, 16, 32)


def pose_features(poses: np.ndarray, size: float = 50.0) -> torch.Tensor:
    """(n, 3) poses -> (n, 4): x and y over the world's size, cos and sin of the heading."""
    x, y, h = poses[:, 0] / size, poses[:, 1] / size, poses[:, 2]
    return torch.from_numpy(np.stack([x, y, np.cos(h), np.sin(h)], 1).astype(np.float32))


def scene_features(world, poses: np.ndarray, rays: int, reach: float) -> torch.Tensor:
    """(n, 3) poses -> (n, rays): a full turn of noiseless readings over ``reach``."""
    layout = spread_layout(rays, 2 * math.pi, reach)
    return torch.from_numpy((read_sensors(world, poses, layout) / reach).astype(np.float32))


def split(db, name: str, features) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Oracle features, scaled readings and scaled commands of one split."""
    return (features(db.take(name).poses), *split_tensors(db, name))


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
    ap.add_argument(
        "--set", nargs="*", default=[], help="ModelConfig sizes, e.g. predictor_hidden=512"
    )
    ap.add_argument("--oracle", choices=("pose", "scene"), default="pose")
    ap.add_argument("--scene-range", type=float, default=10.0)
    ap.add_argument("--scene-rays", type=int, default=32)
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    sizes = {k: int(v) for k, v in (s.split("=") for s in args.set)}
    config = ModelConfig(kind=REC_SMA, **sizes)
    steps, every = TrainConfig.of(REC_SMA).ahead, TrainConfig.of(REC_SMA).ahead_every
    model = SensorimotorEncoder(config)
    db, fresh = load_database(args.train), load_database(args.fresh)
    if db.world.name != fresh.world.name:  # the head is scored, and g probed, on FRESH's poses
        raise SystemExit(
            f"error: {args.fresh} is of {fresh.world.name}, {args.train} of {db.world.name}"
        )
    if args.oracle == "pose":
        features, n_in = pose_features, 4
    else:

        def features(poses):
            return scene_features(db.world, poses, args.scene_rays, args.scene_range)

        n_in = args.scene_rays
    g = mlp([n_in, 64, 64, config.z_sensors])
    params = [p for n, p in model.named_parameters() if not n.startswith(("lstm", "sensor_"))]
    params += list(g.parameters())
    opt = torch.optim.Adam(params, lr=1e-3)
    train, val, test = (
        split(d, name, features) for d, name in ((db, "train"), (db, "val"), (fresh, "test"))
    )
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
        print(
            f"epoch {epoch + 1}: val open-loop mean {v:.4f} ({time.time() - t0:.0f} s)", flush=True
        )
    g.load_state_dict(best_state[0])
    model.load_state_dict(best_state[1])
    e = errors(g, model, test, steps)
    mean_reading = float(((test[1] - train[1].mean(0)) ** 2).sum(-1).mean())
    fit_poses, test_poses = fresh.take("train").poses[:PROBE_FIT_MAX], fresh.take("test").poses
    with torch.no_grad():
        z_fit, z = (g(features(q)).numpy() for q in (fit_poses, test_poses))
    rooms = [fresh.world.room_index(q[:, 0], q[:, 1]) for q in (fit_poses, test_poses)]
    size = (fresh.world.width, fresh.world.height)
    probes = place_probes(z_fit, fit_poses, z, test_poses, *rooms, size)
    out = {
        "oracle": args.oracle,
        "scene": {"rays": args.scene_rays, "range": args.scene_range}
        if args.oracle == "scene"
        else None,
        "belief_probes": probes,
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
