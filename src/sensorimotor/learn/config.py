"""How one model is trained: ``TrainConfig``, the settings of a run (the paper's by default),
each checked when it is made."""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

from sensorimotor.errors import InputError
from sensorimotor.learn.models import KINDS, MAX_WIDTH, REC_SM
from sensorimotor.sim import MAX_SEED


def check_device(device: str) -> None:
    """Refuse a device name other than auto, cpu or cuda."""
    if device not in ("auto", "cpu", "cuda"):
        raise InputError(f"unknown device {device!r}: use auto, cpu or cuda")


MAX_AHEAD = 256  # open-loop steps: each costs a pass of the predictor over every step


@dataclass(frozen=True)
class TrainConfig:
    """How one model is trained; the defaults are the paper's (section V.A)."""

    model: str = REC_SM
    """s, sm, rec-s or rec-sm."""
    seed: int = 0
    """Seeds the initial weights and the data order."""
    lr: float = 1e-3
    """Adam's learning rate."""
    batch_size: int = 64
    """Transitions per step (feed-forward); streams per step (recurrent)."""
    horizon: int = 20
    """Truncation horizon of back-propagation through time (recurrent models)."""
    ahead: int = 1
    """Readings predicted open loop from each step, s_{t+1} .. s_{t+ahead}, the loss their
    mean (kinds with a motor memory; the others predict one)."""
    ahead_every: int = 1
    """Open-loop predictions start at every this many steps (the memory reads every one):
    the loss's mean is estimated at a fraction of the cost."""
    slow_dims: int = 0
    """The first this many dimensions of z_s also learn by the slowness prior
    (``slowness.slowness_prior``; kinds with a motor memory; 0: prediction alone)."""
    slow_weight: float = 1.0
    """The slowness prior's weight beside the prediction loss (with ``slow_dims``)."""
    patience: int = 10
    """Stop after this many epochs in a row without improvement."""
    min_ratio: float = 0.95
    """An epoch improves when its validation error is below this fraction of the best so far."""
    max_epochs: int | None = None
    """Cap on epochs (None: early stopping alone)."""
    max_minutes: float | None = None
    """Cap on training wall time, checked after each epoch (None: no cap)."""
    device: str = "cpu"
    """cpu or cuda."""
    threads: int = 1
    """Torch threads (one is fastest for these tiny models; two in one process are slower)."""

    def __post_init__(self) -> None:
        """Refuse a setting that could not train, before any run folder is written; numpy
        numbers become Python's (config.json is JSON)."""
        if self.model not in KINDS:
            kinds = ", ".join(KINDS)
            raise InputError(f"TrainConfig.model: use one of {kinds}, got {self.model!r}")
        check_device(self.device)
        counts = {"seed": 0, "batch_size": 1, "horizon": 1, "patience": 1, "threads": 1}
        counts |= {"ahead": 1, "ahead_every": 1, "slow_dims": 0}
        counts |= {} if self.max_epochs is None else {"max_epochs": 1}
        for name, least in counts.items():
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, numbers.Integral) or value < least:
                raise InputError(f"TrainConfig.{name} must be an integer >= {least}, got {value!r}")
            object.__setattr__(self, name, int(value))
        if self.seed > MAX_SEED:
            raise InputError(f"TrainConfig.seed must be at most {MAX_SEED}, got {self.seed}")
        positive = {"lr": self.lr, "min_ratio": self.min_ratio, "slow_weight": self.slow_weight}
        positive |= {} if self.max_minutes is None else {"max_minutes": self.max_minutes}
        for name, value in positive.items():
            if isinstance(value, bool) or not isinstance(value, numbers.Real):
                raise InputError(f"TrainConfig.{name} must be a number, got {value!r}")
            if not (math.isfinite(value) and value > 0):
                raise InputError(f"TrainConfig.{name} must be positive and finite, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.min_ratio > 1:
            raise InputError(f"TrainConfig.min_ratio must be at most 1, got {self.min_ratio!r}")
        if self.ahead > 1 and not KINDS[self.model].motor_memory:
            raise InputError(
                f"TrainConfig.ahead: {self.model} predicts one step (open loop needs rec-sma's "
                f"transition), got {self.ahead}"
            )
        if self.slow_dims and not KINDS[self.model].motor_memory:
            raise InputError(
                f"TrainConfig.slow_dims: the slowness prior trains rec-sma's beliefs, not "
                f"{self.model}'s, got {self.slow_dims}"
            )
        if self.slow_dims > MAX_WIDTH:  # z_s's width bounds it (checked against it in train)
            raise InputError(
                f"TrainConfig.slow_dims must be at most {MAX_WIDTH}, got {self.slow_dims}"
            )
        if self.ahead > MAX_AHEAD:
            raise InputError(f"TrainConfig.ahead must be at most {MAX_AHEAD}, got {self.ahead}")
        if self.ahead_every > self.horizon:  # a window's first step always starts one
            raise InputError(
                f"TrainConfig.ahead_every must be at most the horizon ({self.horizon}), "
                f"got {self.ahead_every}"
            )

    @classmethod
    def of(cls, model: str, **settings) -> TrainConfig:
        """The training of ``model``: the paper's defaults, then the kind's own
        (``Kind.training``), then ``settings``."""
        if model not in KINDS:
            raise InputError(f"TrainConfig.model: use one of {', '.join(KINDS)}, got {model!r}")
        return cls(**{"model": model, **dict(KINDS[model].training), **settings})
