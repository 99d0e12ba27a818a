"""Rec-SMA, self-supervised, with a heading among its memory's inputs or without (a pilot).

    PYTHONPATH=src python docs/results/memory/heading_pilot.py TRAIN.npz FRESH.npz --heading odometry

``pose_supervised.py`` found that Rec-SMA's memory, told the position, learns it when it also
reads a heading (room 0.98 with the true one) and not without (0.45 after as many epochs). The
commands give the heading up to the unknown start heading: the turns summed (``--heading
odometry``). This pilot trains Rec-SMA as the kind trains (``SensorimotorEncoder.encode`` and
``ahead``: K = 32 from every 4th step, backpropagation through 256 steps, 4 streams, the state
carried, Adam 1e-3) on the prediction loss alone, its memory reading that heading beside the
readings (``--heading compass``: the true heading) or not (``--heading none``), and probes z_s
with the issue's probes on ``FRESH`` (every ``--probe-every`` epochs too). Autograd, one seed, a
fixed number of epochs: a pilot, not the kind's training.

``--slow-dims D --slow-weight W`` adds a slowness prior (slow feature analysis, the robotic
priors' temporal coherence): W times ``slowness`` of z_s's first D dimensions (``--slow-form
hinge``: a lower floor, and their spread held up by ``spread_hinge``; ``sfa``: also
``correlation``, so that they are D features, not one; ``contrastive``: no slowness, but a
time-contrastive loss, ``contrastive``, as in time-contrastive networks and CPC). The epochs then
log the training windows' slowness of both parts of z_s, and the end probes each part alone and
gives every dimension's slowness over the fresh test split's 256-step windows.
"""

from __future__ import annotations

import argparse
import json
import math
import time

import torch
from pose_supervised import heading_probes, memory_z, probes_of, readings, streams, turned

from sensorimotor.analysis.probes import PROBE_FIT_MAX
from sensorimotor.learn.config import TrainConfig
from sensorimotor.learn.models import REC_SMA, ModelConfig, build_model
from sensorimotor.learn.slowness import (  # the hinge form: a setting now
    slowness,
    spread_hinge,
    window_variance,
)
from sensorimotor.sim.database import load_database, scale_motors, scale_sensors

FLOOR = {"floor": 1e-4, "hinge": 1e-8, "sfa": 1e-8, "contrastive": 1e-8}  # of ``slowness``
GAP, EVERY, TEMPERATURE = 32, 8, 0.1  # --slow-form contrastive: set before its first run


def correlation(z: torch.Tensor) -> torch.Tensor:
    """The mean squared correlation between distinct dimensions of z (B, T, D) over every
    stream's window: with ``--slow-form sfa`` the slow dimensions must differ, as slow feature
    analysis asks (the hinge form's four came out one feature, correlations 0.996-1.000)."""
    x = z.reshape(-1, z.shape[-1])
    x = (x - x.mean(0)) / (x.std(0, unbiased=False) + 1e-8)
    c = x.T @ x / len(x)  # (D, D)
    off = c - torch.diag(torch.diagonal(c))
    d = z.shape[-1]
    return off.square().sum() / max(d * (d - 1), 1)


def contrastive(z: torch.Tensor) -> torch.Tensor:
    """Time-contrastive InfoNCE over the features z (B, T, D) of one chunk: sampled every
    ``EVERY`` steps, each stream's unit features pick out its own ``GAP`` steps later
    (cosine over ``TEMPERATURE``) among the other streams' at every sampled time. Only other
    streams are negatives: a code of the time within a stream, or a drift every stream shares,
    cannot meet it; what tells the streams apart in one window is mostly where they are."""
    u = torch.nn.functional.normalize(z[:, ::EVERY], dim=-1)  # (B, S, D)
    b, s, d = u.shape
    shift = GAP // EVERY
    if s <= shift:
        return z.sum() * 0.0
    anchors = u[:, : s - shift].reshape(-1, d)  # (B (S - shift), D)
    logits = anchors @ u.reshape(-1, d).T / TEMPERATURE  # (B (S - shift), B S)
    stream_a = torch.arange(b).repeat_interleave(s - shift)
    target = stream_a * s + torch.arange(s - shift).repeat(b) + shift
    stream_c = torch.arange(b).repeat_interleave(s)
    own = stream_a[:, None] == stream_c[None, :]
    own[torch.arange(len(target)), target] = False
    return torch.nn.functional.cross_entropy(logits.masked_fill(own, -torch.inf), target)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("train")
    ap.add_argument("fresh")
    ap.add_argument("--heading", choices=("none", "compass", "odometry"), default="odometry")
    ap.add_argument("--epochs", type=int, default=30)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--probe-every", type=int, default=0, help="probe every N epochs too")
    ap.add_argument("--ahead", type=int, default=None, help="K, steps predicted (the kind's: 32)")
    ap.add_argument("--slow-dims", type=int, default=0, help="z_s dimensions under slowness")
    ap.add_argument("--slow-weight", type=float, default=0.0, help="weight of their slowness")
    ap.add_argument(
        "--slow-form",
        choices=tuple(FLOOR),
        default="floor",
        help="floor: slowness over variance + 1e-4 (the first pilot); hinge: + 1e-8, "
        "and each slow dimension's spread held at least learn.slowness.LEAST_STD; sfa: hinge, and the slow "
        "dimensions decorrelated; contrastive: time-contrastive InfoNCE, no slowness",
    )
    ap.add_argument("--save", default=None, help="write the trained weights here (.pt)")
    args = ap.parse_args()
    torch.manual_seed(args.seed)
    torch.set_num_threads(1)
    settings = TrainConfig.of(REC_SMA)
    k, every, horizon, n_streams = (
        args.ahead or settings.ahead,
        settings.ahead_every,
        settings.horizon,
        settings.batch_size,
    )
    n_sensors = 5 if args.heading == "none" else 7
    model = build_model(ModelConfig(kind=REC_SMA, n_sensors=n_sensors), seed=args.seed)
    opt = torch.optim.Adam(model.parameters(), lr=settings.lr)
    db, fresh = load_database(args.train), load_database(args.fresh)
    part = db.take("train")
    memory_in = streams(readings(part, db.max_range, args.heading), n_streams)  # (B, T, 5|7)
    target = streams(scale_sensors(part.sensors, db.max_range), n_streams)  # (B, T, 5)
    motors = streams(scale_motors(part.motors), n_streams)  # (B, T, 2)
    length = memory_in.shape[1]
    draw = torch.Generator().manual_seed(args.seed)
    for epoch in range(args.epochs):
        t0, state, total, count, parts = time.time(), None, 0.0, 0, [0.0, 0.0, 0.0]
        if args.heading == "odometry":  # each stream's start heading drawn anew
            memory_in = turned(memory_in, torch.rand(n_streams, generator=draw) * 2 * math.pi)
        for i in range(0, length - k, horizon):
            j = min(i + horizon, length - k)
            z, state = model.encode(memory_in[:, i:j], state, motors[:, i:j])
            pred = model.ahead(z, motors[:, i : j + k - 1], k, every)[..., :5]  # (K, B, T', 5)
            starts = torch.arange(i, j, every)
            truth = torch.stack([target[:, starts + step + 1] for step in range(k)])
            loss = ((pred - truth) ** 2).sum(-1).mean()
            prediction = float(loss.detach())
            if args.slow_dims:
                floor = FLOOR[args.slow_form]
                slow = slowness(z[..., : args.slow_dims], floor)
                prior = (
                    contrastive(z[..., : args.slow_dims])
                    if args.slow_form == "contrastive"
                    else slow
                )
                if args.slow_form in ("hinge", "sfa"):
                    prior = prior + spread_hinge(z[..., : args.slow_dims])
                if args.slow_form == "sfa":
                    prior = prior + correlation(z[..., : args.slow_dims])
                loss = loss + args.slow_weight * prior
                parts[0] += float(slow.detach()) * (j - i)
                parts[1] += float(slowness(z.detach()[..., args.slow_dims :], floor)) * (j - i)
                parts[2] += float(prior.detach()) * (j - i)
            opt.zero_grad()
            loss.backward()
            opt.step()
            state = tuple(x.detach() for x in state)
            total, count = total + prediction * (j - i), count + (j - i)
        slow_log = (
            f", slowness {parts[0] / count:.4f} (the other dimensions {parts[1] / count:.4f})"
            + (f", InfoNCE {parts[2] / count:.3f}" if args.slow_form == "contrastive" else "")
            if args.slow_dims
            else ""
        )
        print(
            f"epoch {epoch + 1}: open-loop loss {total / count:.4f}{slow_log} "
            f"({time.time() - t0:.0f} s)",
            flush=True,
        )
        if args.probe_every and (epoch + 1) % args.probe_every == 0 and epoch + 1 < args.epochs:
            print(
                json.dumps({"epoch": epoch + 1, "probes": probe(model, fresh, args.heading)}),
                flush=True,
            )
    model.eval()  # z_s once for every probe and measure of the end
    fit, test = fresh.take("train"), fresh.take("test")
    z_fit = memory_z(model, fit, fresh.max_range, args.heading, PROBE_FIT_MAX)
    z = memory_z(model, test, fresh.max_range, args.heading)
    result = {
        "heading": args.heading,
        "epochs": args.epochs,
        "ahead": k,
        "slow_dims": args.slow_dims,
        "slow_weight": args.slow_weight,
        "probes": probes_of(fresh, z_fit, z),
    }
    if args.slow_dims:
        d = args.slow_dims
        result |= {
            "probes_slow_dims": probes_of(fresh, z_fit[:, :d], z[:, :d]),
            "probes_other_dims": probes_of(fresh, z_fit[:, d:], z[:, d:]),
            "slow_form": args.slow_form,
            **windows_of(torch.from_numpy(z), FLOOR[args.slow_form]),
        }
    print(json.dumps(result))
    if args.save:
        torch.save(model.state_dict(), args.save)


def windows_of(z: torch.Tensor, floor: float, window: int = 256) -> dict:
    """``slowness`` (with ``floor``) and the spread within a window (the variance) of each
    column of z (n, 10), the test split's z_s, cut into windows."""
    n = len(z) // window
    z = z[: n * window].reshape(n, window, -1)  # (windows, 256, 10)
    dims = range(z.shape[-1])
    return {
        "test_slowness_per_dim": [
            round(float(slowness(z[..., i : i + 1], floor)), 5) for i in dims
        ],
        "test_spread_per_dim": [float(v) for v in window_variance(z)],
    }


def probe(model, fresh, heading: str) -> dict:
    """The issue's probes of z_s on ``fresh``, the model left in training mode after."""
    model.eval()
    probes = heading_probes(model, fresh, heading)
    model.train()
    return probes


if __name__ == "__main__":
    main()
