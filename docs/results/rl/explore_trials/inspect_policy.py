"""How one saved explore policy behaves: collisions an episode, mean forward command and the
coverage after 400 steps, over 20 episodes of its stochastic policy.
    python inspect_policy.py AGENT_FOLDER FEATURES SEED   (the folder holds policy.zip)"""

import sys

import numpy as np
from stable_baselines3 import PPO

from sensorimotor.rl.features import load_encoder
from sensorimotor.rl.runner import RLConfig, make_env

folder, feat, seed = sys.argv[1], sys.argv[2], int(sys.argv[3])
cfg = RLConfig(task="explore", world="rooms1", features=(feat,), runs="docs/results/runs")
enc, _ = load_encoder(feat, cfg.runs, "rooms1", seed)
venv = make_env(cfg, "rooms1", feat, enc, 20, 123)
model = PPO.load(f"{folder}/policy.zip", device="cpu")
obs = venv.reset()
hits = np.zeros(20)
moves = np.zeros(20)
cov = None
for t in range(400):
    a, _ = model.predict(obs, deterministic=False)
    obs, r, d, infos = venv.step(a)
    hits += [i["collision"] for i in infos]
    moves += (np.clip(a[:, 0], -1, 1) + 1) / 2
    if t == 398:
        cov = [i["coverage"] for i in infos]
print(
    feat,
    seed,
    "collisions/ep",
    hits.mean(),
    "mean d",
    (moves / 400).mean(),
    "coverage",
    np.mean(cov),
    np.round(cov, 2),
)
