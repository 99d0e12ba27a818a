"""Reinforcement learning on frozen encoders: do the representations help an agent act?

The paper's conclusion plans to use the learned representations in a reinforcement-learning
task. This layer runs the S-RL Toolbox's protocol on today's tools: the same algorithm
(stable-baselines3 PPO) on each feature set (``features.feature_sets()``: the true pose and the
raw readings as references, the trained encoders' z_s, an untrained encoder), many seeds,
confidence intervals over seeds (``results``, on ``stats``). ``runner.run_grid`` is what ``sensorimotor rl``
calls. stable-baselines3 is the ``[rl]`` extra: ``check_extra`` says so in one line.

The trained encoders are read from a folder of training runs named ``{world}__{kind}__s{seed}``
(what ``sensorimotor reproduce`` writes in ``OUT/runs``; a clone of the repository ships some in
``docs/results/runs``), given as ``sensorimotor rl --runs DIR`` or in the environment variable
``SENSORIMOTOR_RUNS`` (``RUNS_ENV``); there is no default.
"""

from __future__ import annotations

import importlib.util

from sensorimotor.errors import InputError

RUNS_ENV = "SENSORIMOTOR_RUNS"  # the command line's --runs, when the option is not given


def check_extra() -> None:
    """InputError (one line) when stable-baselines3, the ``[rl]`` extra, is not installed."""
    if importlib.util.find_spec("stable_baselines3") is None:
        raise InputError(
            "reinforcement learning needs stable-baselines3: pip install 'sensorimotor[rl]'"
        )
