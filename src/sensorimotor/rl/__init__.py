"""Reinforcement learning on frozen encoders: do the representations help an agent act?

The paper's conclusion plans to use the learned representations in a reinforcement-learning
task. This layer runs the S-RL Toolbox's protocol on today's tools: the same algorithm
(stable-baselines3 PPO) on each feature set (``features.FEATURES``: the true pose and the raw
readings as references, the four trained encoders' z_s, an untrained encoder), many seeds,
confidence intervals over seeds (``results``, on ``stats``). ``runner.run_grid`` is what
``sensorimotor rl`` calls. stable-baselines3 is the ``[rl]`` extra: ``check_extra`` says so in
one line.
"""

from __future__ import annotations

import importlib.util

from sensorimotor.errors import InputError


def check_extra() -> None:
    """InputError (one line) when stable-baselines3, the ``[rl]`` extra, is not installed."""
    if importlib.util.find_spec("stable_baselines3") is None:
        raise InputError(
            "reinforcement learning needs stable-baselines3: pip install 'sensorimotor[rl]'"
        )
