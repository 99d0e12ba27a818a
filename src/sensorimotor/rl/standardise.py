"""Standardised features: every feature set shifted and scaled by one training rollout's statistics.

The feature sets differ in scale by orders of magnitude (the pose in [-1, 1], the readings in
[0, 1], an encoder's z_s wherever its training left it), and PPO's network is fed them as they
are: an unscaled feature set is a handicap that has nothing to do with what it holds (the issue
"RL made fair"). So every agent, whatever its features, sees ``(f - mean) / sd`` per dimension,
with ``mean`` and ``sd`` measured once, before training, on a rollout of ``STATS_STEPS`` steps in
its own task and world (seeded apart from its training and evaluation starts), driven by actions
drawn uniformly from the action box (about what an untrained policy does), through the same
feature wrapper (a recurrent encoder's state carried as in training). The statistics are then
frozen: training, evaluation and transfer read the same numbers.

Why not stable-baselines3's ``VecNormalize`` (observations only): its running statistics keep
moving while the policy learns (the policy chases its own input), they live outside
``policy.zip`` and must be copied to every evaluation environment by hand, and they would
follow each agent's own visits, so that two agents of different features are scaled by
different data. A fixed rollout is one deterministic function of the seed, the same for every
policy of a feature set, and its numbers go into ``result.json`` (and the per-dimension spread
into ``rl.json``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

STATS_STEPS = 10_000  # environment steps of the statistics' rollout (all environments together)
STATS_SEED = 2_000_000  # the rollout's environments are seeded STATS_SEED + agent seed + i
MIN_SD = 1e-6  # a dimension that does not vary is shifted, not scaled
POLICY = "actions uniform in the action box"


@dataclass(frozen=True)
class Standardisation:
    """Per-dimension ``mean`` and ``sd`` (F,) of a rollout's features, frozen."""

    mean: np.ndarray
    sd: np.ndarray
    steps: int

    def apply(self, features: np.ndarray) -> np.ndarray:
        """(n, F) -> (n, F) float32: ``(f - mean) / sd`` (sd below ``MIN_SD``: 1)."""
        scale = np.where(self.sd > MIN_SD, self.sd, 1.0)
        return ((features - self.mean) / scale).astype(np.float32)

    def to_dict(self) -> dict:
        return {
            "mean": [float(m) for m in self.mean],
            "sd": [float(s) for s in self.sd],
            "steps": self.steps,
            "policy": POLICY,
        }


def rollout_features(venv, steps: int, seed: int) -> np.ndarray:
    """(steps, F) the observations of ``venv`` (a ``FeatureVecEnv``, already seeded) under
    actions drawn uniformly from [-1, 1]^2 by a generator seeded ``seed``: the reset's, then
    each step's, all environments, in order."""
    rng = np.random.default_rng(seed)
    n = venv.num_envs
    rows = [venv.reset()]
    for _ in range(math.ceil(steps / n) - 1):
        obs, _, _, _ = venv.step(rng.uniform(-1.0, 1.0, (n, 2)).astype(np.float32))
        rows.append(obs)
    return np.concatenate(rows)[:steps].astype(np.float64)


def fit(venv, steps: int = STATS_STEPS, seed: int = 0) -> Standardisation:
    """The ``Standardisation`` of ``rollout_features(venv, steps, seed)`` (population sd)."""
    f = rollout_features(venv, steps, seed)
    return Standardisation(f.mean(0), f.std(0), steps)
