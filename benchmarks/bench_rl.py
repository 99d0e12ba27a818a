"""Benchmark of ``sensorimotor rl``'s environment loop and of PPO, per feature set.

Two tables, each with a ratio to a reference measured in the same run:

1. Environment steps per second (random actions) of ``FeatureVecEnv`` over ``--envs``
   corner-task environments, one batched encoder call a step, the environments stepped one by
   one (``DummyVecEnv`` over ``gym.make``) and together (``rl.vec_env.TaskVecEnv``: one
   simulator call a step), against the plain single environment (``gym.make``, no features)
   stepped alone.
2. PPO (``sensorimotor.rl.runner`` settings, batched environments, no evaluation) steps per
   second for each feature set, against PPO on ``raw`` (the issue's target: ``rec-sm`` at no
   less than half of it); and PPO on ``raw`` with the environments stepped one by one.

Speeds are per second of this process's CPU time (``time.process_time``, one thread): on a
machine shared with other work, wall time measures the neighbours too.

Run by hand: ``python benchmarks/bench_rl.py [--steps N] [--ppo-steps N] [--envs N]``.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import gymnasium as gym
import numpy as np
import torch
from rich.console import Console
from rich.table import Table
from stable_baselines3 import PPO

from sensorimotor.envs import TASKS
from sensorimotor.rl.features import feature_sets, load_encoder
from sensorimotor.rl.runner import RLConfig, make_env
from sensorimotor.version import __version__

RUNS = Path(__file__).resolve().parent.parent / "docs" / "results" / "runs"


def plain_env_speed(steps: int) -> float:
    env = gym.make(TASKS["corner"].env_id, world="rooms1")
    env.reset(seed=0)
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, 2)).astype(np.float32)
    t0 = time.process_time()
    for a in actions:
        *_, terminated, truncated, _ = env.step(a)
        if terminated or truncated:
            env.reset()
    return steps / (time.process_time() - t0)


def feature_env_speed(features: str, steps: int, n: int, batched: bool) -> float:
    encoder, _ = load_encoder(features, RUNS, "rooms1", 0)
    venv = make_env(RLConfig(runs=str(RUNS)), "rooms1", features, encoder, n, 0, batched)
    venv.reset()
    actions = np.random.default_rng(0).uniform(-1, 1, (steps // n, n, 2)).astype(np.float32)
    t0 = time.process_time()
    for a in actions:
        venv.step(a)
    return (steps // n) * n / (time.process_time() - t0)


def ppo_speed(features: str, steps: int, batched: bool = True) -> float:
    config = RLConfig(runs=str(RUNS))
    encoder, _ = load_encoder(features, RUNS, "rooms1", 0)
    venv = make_env(config, "rooms1", features, encoder, config.n_envs, 0, batched)
    model = PPO("MlpPolicy", venv, seed=0, device="cpu", **config.ppo)
    t0 = time.process_time()
    model.learn(total_timesteps=steps)
    return model.num_timesteps / (time.process_time() - t0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=20_000, help="environment steps per row")
    parser.add_argument("--ppo-steps", type=int, default=8_192, help="PPO steps per row")
    parser.add_argument("--envs", type=int, default=8, help="parallel environments")
    args = parser.parse_args()
    torch.set_num_threads(1)
    console = Console()
    console.print(f"sensorimotor {__version__}, torch {torch.__version__}, one thread, CPU time")

    plain = plain_env_speed(args.steps)
    table = Table(title=f"environment steps/s, corner in rooms1, {args.envs} environments")
    for col in ("features", "one by one", "ratio", "batched", "ratio to the plain env"):
        table.add_column(col, justify="right")
    table.add_row("plain env (no features, 1 env)", f"{plain:,.0f}", "1.00", "", "")
    for f in feature_sets():
        alone = feature_env_speed(f, args.steps, args.envs, batched=False)
        together = feature_env_speed(f, args.steps, args.envs, batched=True)
        table.add_row(
            f,
            f"{alone:,.0f}",
            f"{alone / plain:.2f}",
            f"{together:,.0f}",
            f"{together / plain:.2f}",
        )
    console.print(table)

    table = Table(title=f"PPO steps/s ({args.ppo_steps:,} steps, no evaluation)")
    for col in ("features", "steps/s", "ratio to raw"):
        table.add_column(col, justify="right")
    raw = ppo_speed("raw", args.ppo_steps)
    for f in feature_sets():
        speed = raw if f == "raw" else ppo_speed(f, args.ppo_steps)
        table.add_row(f, f"{speed:,.0f}", f"{speed / raw:.2f}")
    slow = ppo_speed("raw", args.ppo_steps, batched=False)
    table.add_row("raw, one by one", f"{slow:,.0f}", f"{slow / raw:.2f}")
    console.print(table)


if __name__ == "__main__":
    main()
