"""PPO cost per feature set (the RL grid's cost plan): CPU seconds of the statistics' rollout,
PPO steps per CPU-second, CPU seconds of one evaluation. ``python benchmarks/cost_rl.py TASK F1,F2``."""

import json
import sys
import time
from pathlib import Path

import torch
from stable_baselines3 import PPO

from sensorimotor.rl.features import load_encoder
from sensorimotor.rl.runner import EVAL_SEED, RLConfig, evaluate_both, make_env, standardisation_for

RUNS = Path(__file__).resolve().parent.parent / "docs" / "results" / "runs"


def main() -> None:
    torch.set_num_threads(1)
    task = sys.argv[1]
    out = {}
    for f in sys.argv[2].split(","):
        config = RLConfig(task=task, runs=str(RUNS))
        enc, _ = load_encoder(f, RUNS, "rooms1", 0)
        t0 = time.process_time()
        st = standardisation_for(config, f, enc, 0)
        t1 = time.process_time()
        venv = make_env(config, "rooms1", f, enc, 8, 0, True, st)
        model = PPO("MlpPolicy", venv, seed=0, device="cpu", **config.ppo)
        model.learn(total_timesteps=8192)
        t2 = time.process_time()
        ev = make_env(config, "rooms1", f, enc, 10, EVAL_SEED, True, st)
        evaluate_both(model, ev, 50)
        t3 = time.process_time()
        out[f] = {
            "stats_s": t1 - t0,
            "ppo_steps_per_s": model.num_timesteps / (t2 - t1),
            "eval50x2_s": t3 - t2,
        }
        print(task, f, json.dumps(out[f]), flush=True)


if __name__ == "__main__":
    main()
