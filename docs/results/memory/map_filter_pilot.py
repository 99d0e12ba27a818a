"""A learner that builds the observer's map: a histogram filter over a latent grid of places and
headings, moved by the commands through the robot's known motion and weighted by a learned
observation model, trained by the readings' likelihood alone (docs/results/memory/README.md,
"A learner that builds the observer's map"; Jonschkowski & Brock 2016).

    PYTHONPATH=src python docs/results/memory/map_filter_pilot.py rooms1.npz rooms1_fresh1.npz --minutes 30 --out map_filter
    PYTHONPATH=src python docs/results/memory/map_filter_pilot.py rooms1.npz rooms1_fresh1.npz --diagnose map_filter.pt
"""

from __future__ import annotations

import argparse
import json
import math
import time

import numpy as np
import torch

from sensorimotor.analysis.observer import READING_SD, UNIFORM_SHARE
from sensorimotor.analysis.probes import place_probes
from sensorimotor.sim.core import MAX_RANGE
from sensorimotor.sim.database import load_database, scale_sensors

G, CELL, H = 25, 2.0, 16  # latent grid: G x G places of CELL units, H headings
SD, UNIFORM = READING_SD / MAX_RANGE, UNIFORM_SHARE  # the observer's beam model, scaled to [0, 1]
T, B = 256, 8  # sequence length and sequences a batch (the budget: about 3 s a batch on one core)
PROBE_FIT = 20_000  # fresh training-split steps the probes fit on (as the observer's)

THETA = torch.arange(H) * (2 * math.pi / H)
SIGN_X, SIGN_Y = torch.cos(THETA) >= 0, torch.sin(THETA) >= 0


def move(b: torch.Tensor, d: torch.Tensor, r: torch.Tensor) -> torch.Tensor:
    """The belief b (B, H, G, G: heading, y, x) after moving d (B,) units along each heading
    (a bilinear shift, less than a cell), then turning by r (B,) rad (linear between headings)."""
    ax = (d[:, None] * torch.cos(THETA).abs()[None] / CELL)[..., None, None]  # (B, H, 1, 1)
    ay = (d[:, None] * torch.sin(THETA).abs()[None] / CELL)[..., None, None]
    up_x = torch.nn.functional.pad(b[..., :-1], (1, 0))  # mass one cell toward +x
    down_x = torch.nn.functional.pad(b[..., 1:], (0, 1))
    b = (1 - ax) * b + ax * torch.where(SIGN_X[None, :, None, None], up_x, down_x)
    up_y = torch.nn.functional.pad(b[..., :-1, :], (0, 0, 1, 0))
    down_y = torch.nn.functional.pad(b[..., 1:, :], (0, 0, 0, 1))
    b = (1 - ay) * b + ay * torch.where(SIGN_Y[None, :, None, None], up_y, down_y)
    k = r / (2 * math.pi / H)  # (B,) headings turned
    k0 = torch.floor(k)
    f = (k - k0)[:, None, None, None]
    h = torch.arange(H)[None]
    i0 = ((h - k0[:, None].long()) % H)[..., None, None].expand_as(b)
    i1 = ((h - k0[:, None].long() - 1) % H)[..., None, None].expand_as(b)
    return (1 - f) * b.gather(1, i0) + f * b.gather(1, i1)


def loglik(table: torch.Tensor, z: torch.Tensor) -> torch.Tensor:
    """(B, H, G, G) log-likelihood of the scaled readings z (B, R) at every latent state."""
    pred = torch.sigmoid(table)  # (H, G, G, R)
    e = (pred[None] - z[:, None, None, None, :]) / SD
    dens = (1 - UNIFORM) * torch.exp(-0.5 * e * e) / (SD * math.sqrt(2 * math.pi)) + UNIFORM
    return torch.log(dens).sum(-1)


def step(b, table, z, m_prev):
    """One filter step: move by the last command, weigh by the reading. Returns the belief and
    the log of the reading's predictive likelihood (B,)."""
    if m_prev is not None:
        b = move(b, m_prev[:, 0], m_prev[:, 1])
    joint = torch.log(b.clamp_min(1e-30)) + loglik(table, z)  # in logs: a surprised belief
    lc = torch.logsumexp(joint.flatten(1), dim=1)  # underflows otherwise, and its gradient
    return torch.exp(joint - lc[:, None, None, None]), lc


def uniform(n: int) -> torch.Tensor:
    return torch.full((n, H, G, G), 1.0 / (H * G * G))


def features(table, sensors, motors) -> np.ndarray:
    """(N, G*G + 4): the belief's marginal over places, then its mean place (x, y in cells) and
    heading (cos, sin), over a stream that starts with a uniform belief."""
    z, m = torch.from_numpy(scale_sensors(sensors)), torch.from_numpy(motors.astype(np.float32))
    b, out = uniform(1), np.empty((len(z), G * G + 4), dtype=np.float32)
    cx = torch.arange(G, dtype=torch.float32)
    with torch.no_grad():
        for t in range(len(z)):
            b, _ = step(b, table, z[t : t + 1], m[t - 1 : t] if t else None)
            place = b[0].sum(0)  # (G, G): y, x
            head = b[0].sum((1, 2))
            out[t, : G * G] = place.flatten().numpy()
            out[t, G * G] = float((place.sum(0) * cx).sum())
            out[t, G * G + 1] = float((place.sum(1) * cx).sum())
            out[t, G * G + 2] = float((head * torch.cos(THETA)).sum())
            out[t, G * G + 3] = float((head * torch.sin(THETA)).sum())
    return out


def probe(table, fresh) -> dict:
    """The same probes as every representation, on the belief's marginal and on its mean."""
    fit, test = fresh.take("train"), fresh.take("test")
    n = min(len(fit), PROBE_FIT)
    zf = features(table, fit.sensors[:n], fit.motors[:n])
    z = features(table, test.sensors, test.motors)
    w = fresh.world
    rooms = [w.room_index(q[:, 0], q[:, 1]) for q in (fit.poses[:n], test.poses)]
    size = (w.width, w.height)
    return {
        name: place_probes(zf[:, cols], fit.poses[:n], z[:, cols], test.poses, *rooms, size)
        for name, cols in (("marginal", slice(0, G * G)), ("mean", slice(G * G, G * G + 4)))
    }


def diagnose(table, fresh, steps: int = 2000) -> dict:
    """Does the belief track a place? Over the fresh test split's first ``steps``: its entropy,
    how many latent states its peak visits, and how its peak heading follows the robot's."""
    test = fresh.take("test")
    z = torch.from_numpy(scale_sensors(test.sensors[:steps]))
    m = torch.from_numpy(test.motors[:steps].astype(np.float32))
    b, entropy, peak = uniform(1), [], []
    with torch.no_grad():
        for t in range(len(z)):
            b, _ = step(b, table, z[t : t + 1], m[t - 1 : t] if t else None)
            q = b.flatten()
            entropy.append(float(-(q * torch.log(q.clamp_min(1e-30))).sum()))
            peak.append(int(q.argmax()))
    heading = np.array(peak) // (G * G) * (2 * math.pi / H)
    true = test.poses[:steps, 2].astype(np.float64)
    return {
        "entropy_nats": float(np.mean(entropy)),
        "entropy_max": math.log(H * G * G),
        "peak_states": len(set(peak)),
        "heading_corr_cos": float(np.corrcoef(np.cos(heading), np.cos(true))[0, 1]),
        "heading_corr_sin": float(np.corrcoef(np.sin(heading), np.sin(true))[0, 1]),
    }


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("data")
    p.add_argument("fresh")
    p.add_argument("--minutes", type=float, default=30.0)
    p.add_argument("--probe-every", type=float, default=10.0, help="minutes")
    p.add_argument("--lr", type=float, default=0.05)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default="map_filter")
    p.add_argument("--diagnose", help="a trained table (.pt): print how its belief moves, and stop")
    a = p.parse_args()
    if a.diagnose:
        table = torch.load(a.diagnose, weights_only=True)["table"]
        print(json.dumps(diagnose(table, load_database(a.fresh)), indent=1))
        return
    torch.manual_seed(a.seed)
    torch.set_num_threads(1)
    rng = np.random.default_rng(a.seed)
    db, fresh = load_database(a.data), load_database(a.fresh)
    train = db.take("train")
    z_all = torch.from_numpy(scale_sensors(train.sensors))
    m_all = torch.from_numpy(train.motors.astype(np.float32))
    table = torch.nn.Parameter(torch.randn(H, G, G, z_all.shape[1]))
    opt = torch.optim.Adam([table], lr=a.lr)
    began, last_probe, log = time.time(), time.time(), []
    batch = 0
    while True:
        starts = rng.integers(0, len(z_all) - T, size=B)
        rows = torch.from_numpy(starts)[:, None] + torch.arange(T)[None]
        z, m = z_all[rows], m_all[rows]  # (B, T, R), (B, T, 2)
        b, total = uniform(B), 0.0
        for t in range(T):
            b, lc = step(b, table, z[:, t], m[:, t - 1] if t else None)
            total = total + lc.mean()
        loss = -total / T
        opt.zero_grad()
        loss.backward()
        opt.step()
        batch += 1
        minutes = (time.time() - began) / 60
        if batch % 20 == 0:
            print(f"batch {batch} ({minutes:.1f} min): {-loss.item():.3f} nats a step", flush=True)
        done = minutes >= a.minutes
        if done or time.time() - last_probe >= a.probe_every * 60:
            last_probe = time.time()
            found = probe(table.detach(), fresh)
            row = {"batch": batch, "minutes": round(minutes, 2), "nats": -loss.item(), **found}
            log.append(row)
            room = {k: (v["room"] or {}).get("balanced_accuracy") for k, v in found.items()}
            print(f"  probe at batch {batch}: room {room}", flush=True)
            with open(f"{a.out}.json", "w") as f:
                json.dump(log, f, indent=1, allow_nan=False)
            torch.save({"table": table.detach()}, f"{a.out}.pt")
        if done:
            break


if __name__ == "__main__":
    main()
