"""Can Rec-SMA's memory hold the pose when it is told it? (issue 32's diagnosis)

    PYTHONPATH=src python docs/results/memory/pose_supervised.py TRAIN.npz FRESH.npz [--epochs N]

Rec-SMA's memory (``learn/models.py``: readings and the previous command -> LSTM 3 x 32 ->
z_s, 10-d) learns from prediction alone and probes at room 0.43 balanced accuracy. This script
trains the same memory, from the same inputs, with the pose as its target: a linear read-out
of z_s fitted to the position (x and y standardised) by mean squared error (a loss of 2
means nothing learnt), truncated backpropagation
through 256 steps with the state carried, as Rec-SMA trains. It then scores z_s with the
issue's own probes (``analysis.analyze.probe_places``, on ``FRESH``: fitted on its training
split, scored on its test split after 200 steps). Supervision is what the self-supervised
model does not get: if even this memory stays far from the goals, its size or inputs are the
limit; if it reaches them, the prediction loss is. ``--target displacement`` asks only for the
path integrated over a window; ``--heading`` adds a heading to the memory's inputs (the true
one, or the commands' turns summed, which the commands alone give).
"""

from __future__ import annotations

import argparse
import json
import math
import time
from pathlib import Path

import numpy as np
import torch

from sensorimotor.analysis.analyze import probe_places
from sensorimotor.analysis.probes import PROBE_FIT_MAX, place_probes
from sensorimotor.learn.evaluate import Run, run_model
from sensorimotor.learn.models import REC_SMA, ModelConfig, build_model
from sensorimotor.sim.database import load_database, scale_motors, scale_sensors


def standard_position(poses: np.ndarray) -> np.ndarray:
    """(n, 3) poses -> (n, 2) x and y, each to mean 0 and variance 1 (the heading is left out:
    in a world of right angles, readings fix it only up to a quarter turn)."""
    xy = poses[:, :2].astype(np.float64)
    return ((xy - xy.mean(0)) / xy.std(0)).astype(np.float32)


def displacements(poses: np.ndarray, horizon: int, scale: float = 10.0) -> np.ndarray:
    """(n, 3) poses -> (n, 2): the position relative to the pose at the start of its
    ``horizon``-step window, in that pose's frame, over ``scale`` units: what integrating the
    commands from the window's start gives, without any wall or map."""
    p = poses.astype(np.float64)
    start = p[(np.arange(len(p)) // horizon) * horizon]
    dx, dy, h = p[:, 0] - start[:, 0], p[:, 1] - start[:, 1], start[:, 2]
    along, across = np.cos(h) * dx + np.sin(h) * dy, -np.sin(h) * dx + np.cos(h) * dy
    return (np.stack([along, across], 1) / scale).astype(np.float32)


def r2(pred: torch.Tensor, target: torch.Tensor) -> list[float]:
    """R^2 of each column."""
    pred, target = pred.reshape(-1, 2).double(), target.reshape(-1, 2).double()
    sse, sst = ((pred - target) ** 2).sum(0), ((target - target.mean(0)) ** 2).sum(0)
    return [round(float(v), 4) for v in 1 - sse / sst]


def readings(part, max_range: float, heading: str) -> np.ndarray:
    """(n, 5) scaled readings, with (cos, sin) of a heading beside them (n, 7): ``compass``
    the true one; ``odometry`` the turns of the commands summed from the part's start (the true
    heading less the unknown start heading, to 1e-5: the commands alone give it). With either
    the memory need not integrate the turns to integrate the path."""
    s = scale_sensors(part.sensors, max_range)
    if heading == "none":
        return s
    if heading == "compass":
        h = part.poses[:, 2].astype(np.float64)
    else:  # the turn before step t is m_{t-1}'s, as the memory reads it
        h = np.concatenate([[0.0], np.cumsum(part.motors[:-1, 1].astype(np.float64))])
    return np.concatenate([s, np.cos(h)[:, None], np.sin(h)[:, None]], 1).astype(np.float32)


def turned(s: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """Streams (B, T, 7) whose heading columns are turned by ``angle`` (B,): another unknown
    start heading for each stream (the summed turns fix only the heading's changes)."""
    c, n = torch.cos(angle)[:, None], torch.sin(angle)[:, None]
    cos, sin = s[..., 5], s[..., 6]
    return torch.cat([s[..., :5], (c * cos - n * sin)[..., None], (n * cos + c * sin)[..., None]], -1)


def memory_z(model, part, max_range: float, heading: str, steps: int | None = None) -> np.ndarray:
    """z_s (n, 10) of a memory that reads ``readings(part, ..., heading)`` and the commands,
    over the part's first ``steps`` steps (all by default), from a zero state."""
    s = torch.from_numpy(readings(part, max_range, heading)[:steps])
    with torch.no_grad():
        return run_model(model, s, torch.from_numpy(scale_motors(part.motors[:steps])))[1].numpy()


def probes_of(fresh, z_fit: np.ndarray, z: np.ndarray) -> dict:
    """``place_probes`` of features of ``fresh``'s first training steps (``z_fit``) and of its
    test split (``z``)."""
    fit, test = fresh.take("train"), fresh.take("test")
    world, fit_poses = fresh.world, fit.poses[: len(z_fit)]
    rooms_fit = world.room_index(fit_poses[:, 0], fit_poses[:, 1])
    rooms = world.room_index(test.poses[:, 0], test.poses[:, 1])
    return place_probes(z_fit, fit_poses, z, test.poses, rooms_fit, rooms,
                        (world.width, world.height))


def heading_probes(model, fresh, heading: str) -> dict:
    """``probe_places``' probes of a memory that reads a heading (its inputs are not a
    database's readings, so ``probe_places`` cannot run it)."""
    fit, test = fresh.take("train"), fresh.take("test")
    z_fit = memory_z(model, fit, fresh.max_range, heading, PROBE_FIT_MAX)
    return probes_of(fresh, z_fit, memory_z(model, test, fresh.max_range, heading))


def streams(a: np.ndarray, n: int) -> torch.Tensor:
    """(T, D) -> (n, T // n, D): n contiguous streams (the remainder dropped)."""
    t = len(a) // n
    return torch.from_numpy(np.ascontiguousarray(a[: n * t])).reshape(n, t, -1)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("train")
    ap.add_argument("fresh")
    ap.add_argument("--epochs", type=int, default=20)
    ap.add_argument("--streams", type=int, default=32)
    ap.add_argument("--horizon", type=int, default=256)
    ap.add_argument("--curriculum", type=lambda v: [int(h) for h in v.split(",")], default=[],
                    help="shorter horizons trained first, e.g. 32,64,128")
    ap.add_argument("--stage-epochs", type=int, default=5, help="epochs of each curriculum stage")
    ap.add_argument("--lr", type=float, default=1e-3)
    ap.add_argument("--target", choices=("position", "displacement"), default="position",
                    help="displacement: from each window's start, the memory reset there")
    ap.add_argument("--heading", choices=("none", "compass", "odometry"), default="none",
                    help="a heading as an input: the true one, or the commands' turns summed")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--set", nargs="*", default=[], help="ModelConfig sizes, e.g. lstm_size=64")
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    sizes = {k: int(v) for k, v in (s.split("=") for s in args.set)}
    n_sensors = 5 if args.heading == "none" else 7
    model = build_model(ModelConfig(kind=REC_SMA, n_sensors=n_sensors, **sizes), seed=args.seed)
    head = torch.nn.Linear(model.config.z_sensors, 2)
    params = [p for n, p in model.named_parameters() if n.startswith(("lstm", "sensor_"))]
    opt = torch.optim.Adam(params + list(head.parameters()), lr=args.lr)
    db, fresh = load_database(args.train), load_database(args.fresh)
    part = db.take("train")
    reset = args.target == "displacement"
    draw = torch.Generator().manual_seed(args.seed)
    stages = [(h, args.stage_epochs) for h in args.curriculum] + [(args.horizon, args.epochs)]
    for horizon, epochs in stages:
        n = len(part.sensors)
        if reset:  # whole windows in every stream
            n = n // (args.streams * horizon) * args.streams * horizon
        s = streams(readings(part, db.max_range, args.heading)[:n], args.streams)
        m = streams(scale_motors(part.motors[:n]), args.streams)
        target = displacements(part.poses[:n], horizon) if reset else standard_position(part.poses)
        y = streams(target[:n], args.streams)
        for epoch in range(epochs):
            t0, state, total = time.time(), None, 0.0
            if args.heading == "odometry":  # each stream's start heading drawn anew: it must
                s = turned(s, torch.rand(len(s), generator=draw) * 2 * math.pi)  # be inferred
            for i in range(0, s.shape[1], horizon):
                state = None if reset else state
                z, state = model.encode(s[:, i : i + horizon], state, m[:, i : i + horizon])
                loss = ((head(z) - y[:, i : i + horizon]) ** 2).sum(-1).mean()
                opt.zero_grad()
                loss.backward()
                opt.step()
                state = tuple(x.detach() for x in state)
                total += float(loss.detach()) * z.shape[1]
            print(f"horizon {horizon} epoch {epoch + 1}: loss {total / s.shape[1]:.4f} "
                  f"({time.time() - t0:.0f} s)", flush=True)
    model.eval()
    if reset:  # windows of the fresh test split, each from the zero state
        part = fresh.take("test")
        n = len(part.sensors) // args.horizon * args.horizon
        with torch.no_grad():
            z, _ = model.encode(
                streams(readings(part, fresh.max_range, args.heading)[:n], n // args.horizon),
                None,
                streams(scale_motors(part.motors[:n]), n // args.horizon),
            )
            got = r2(head(z), streams(displacements(part.poses[:n], args.horizon), n // args.horizon))
        print(json.dumps({"sizes": sizes, "epochs": args.epochs, "horizon": args.horizon,
                          "curriculum": args.curriculum, "target": args.target,
                          "heading": args.heading,
                          "test_r2_along_across": got}))
        return
    run = Run(Path(args.train), model, {"data": {"world": db.meta["world"]["name"]}})
    with torch.no_grad():
        probes = (
            probe_places(run, fresh)
            if args.heading == "none"
            else heading_probes(model, fresh, args.heading)
        )
    print(json.dumps({"sizes": sizes, "epochs": args.epochs, "curriculum": args.curriculum,
                      "lr": args.lr, "heading": args.heading, "probes": probes}))


if __name__ == "__main__":
    main()
