"""The four encoders of the paper (section III, sizes from section V.A), and the
action-conditioned one that goes beyond it, in one file.

Every model maps sensors s_t (and motors m_t) to a prediction of s_{t+1} through a sensory
representation z_s (10-d). Shapes: B batch, T time, K steps ahead, 5 sensors, 2 motors.

    S-encoder      s_t -> 16 -> 32 -> 64 -> z_s(10)                   -> 128 -> s_{t+1}
    SM-encoder     s_t -> 16 -> 32 -> 64 -> z_s(10) | m_t -> 16 -> 32 -> 64 -> z_m(5) -> 128 -> s
    Recurrent-S    s_t -> 16 -> LSTM(3 x 32) -> z_s(10)               -> 128 -> s_{t+1}
    Recurrent-SM   s_t -> 16 -> LSTM(3 x 32) -> z_s(10) | m_t -> 16 -> z_m(5)   -> 128 -> s
    Rec-SMA        s_t -> 16 | m_{t-1} -> LSTM(3 x 32) -> z_s(10) | m_t -> 16 -> z_m(5) -> 128 -> s

Rec-SMA's memory reads the previous motor command beside the reading, so it can integrate the
path. It is also trained open loop (``ahead``): from z_s at t, a transition imagines the next
belief without a reading, z_{t+k} = z_{t+k-1} + transition(z_{t+k-1}, z_m(m_{t+k-1}))
(15 -> 64 -> 10), and the same predictor reads each imagined belief, so z_s must hold what
predicts the readings K steps ahead: where the robot is, not only what it sees.

ReLU after every hidden layer; z_s, z_m and the prediction are linear. The same ``forward``
serves training, evaluation and analysis; analysis reads ``z_s`` and nothing else.

On the CPU, training runs these layers through hand-written passes over stacked seeds
(``stacked.py``, ``stacked_lstm.py``), checked against this file before training starts
(``stacked.computes_models_py``); edit a model here and, if those passes do not compute it
any more, it trains with autograd instead: as edited, only slower.
"""

from __future__ import annotations

import itertools
from dataclasses import asdict, dataclass

import torch
from torch import nn

from sensorimotor.learn.kinds import (  # noqa: F401 (the registry, read through models too)
    KINDS,
    REC_S,
    REC_SM,
    REC_SMA,
    SM,
    Kind,
    S,
    paper_kinds,
    paper_panels,
    register,
)

# LSTM (h, c), each (layers, B, 32), and for a motor memory the last command (1, B, 2); None = zero
State = tuple[torch.Tensor, ...] | None


MAX_WIDTH = 4096  # units of any one layer: far beyond these models, within any memory


@dataclass(frozen=True)
class ModelConfig:
    """Sizes of one encoder; the defaults are the paper's."""

    kind: str = REC_SM
    """A name in ``KINDS``."""
    n_sensors: int = 5
    """Distance sensors in s_t."""
    n_motors: int = 2
    """Motor command (d, r)."""
    z_sensors: int = 10
    """Size of the sensory representation z_s."""
    z_motors: int = 5
    """Size of the motor representation z_m."""
    ff_hidden: tuple[int, ...] = (16, 32, 64)
    """Hidden layers of the feed-forward encoders (S, SM; sensor and motor)."""
    rec_hidden: int = 16
    """The one hidden layer of the recurrent models' sensor and motor encoders."""
    lstm_size: int = 32
    """Units of each LSTM layer."""
    lstm_layers: int = 3
    """Stacked LSTM layers."""
    predictor_hidden: int = 128
    """The prediction subnetwork's one hidden layer."""
    transition_hidden: int = 64
    """The open-loop transition's one hidden layer (kinds with a motor memory)."""
    memory_motors: bool | None = None
    """Whether the memory reads the previous command (None: the kind's ``motor_memory``);
    False on such a kind feeds it zeros: the ablation that removes path integration."""

    def __post_init__(self) -> None:
        """Refuse an unknown kind, and sizes that are not integers in 1..MAX_WIDTH (a
        hand-edited config.json would otherwise fail deep inside torch, or exhaust memory)."""
        if self.kind not in KINDS:
            raise ValueError(f"unknown model {self.kind!r}: use one of {', '.join(KINDS)}")
        if self.memory_motors is not None and not isinstance(self.memory_motors, bool):
            raise ValueError(
                f"memory_motors must be true, false or null, got {self.memory_motors!r}"
            )
        if self.memory_motors and not KINDS[self.kind].motor_memory:
            raise ValueError(f"{self.kind}: its memory does not read motors (use rec-sma)")
        object.__setattr__(self, "ff_hidden", tuple(self.ff_hidden))
        skip = ("kind", "ff_hidden", "memory_motors")
        sizes = {k: v for k, v in asdict(self).items() if k not in skip}
        sizes |= {f"ff_hidden[{i}]": v for i, v in enumerate(self.ff_hidden)}
        if not self.ff_hidden or len(self.ff_hidden) > 16:
            raise ValueError(f"ff_hidden must hold 1 to 16 layer sizes, got {self.ff_hidden!r}")
        for name, v in sizes.items():
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= MAX_WIDTH:
                raise ValueError(f"{name} must be an integer in 1..{MAX_WIDTH}, got {v!r}")

    @property
    def recurrent(self) -> bool:
        return KINDS[self.kind].recurrent

    @property
    def uses_motors(self) -> bool:
        return KINDS[self.kind].motors

    @property
    def motor_memory(self) -> bool:
        """The model has a motor input to its memory and an open-loop transition."""
        return KINDS[self.kind].motor_memory

    @property
    def reads_motors(self) -> bool:
        """The memory's motor input carries the commands (not the ablation's zeros)."""
        return self.motor_memory and self.memory_motors is not False

    def to_dict(self) -> dict:
        d = asdict(self)
        d["ff_hidden"] = list(self.ff_hidden)
        return d


def mlp(sizes: list[int]) -> nn.Sequential:
    """Linear layers through ``sizes`` with a ReLU after every one but the last."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU())
    return nn.Sequential(*layers)


class SensorimotorEncoder(nn.Module):
    """One of the encoders, chosen by ``config.kind``."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        c = config
        self.config = c
        if c.recurrent:
            self.sensor_in = nn.Sequential(nn.Linear(c.n_sensors, c.rec_hidden), nn.ReLU())
            memory_in = c.rec_hidden + (c.n_motors if c.motor_memory else 0)
            self.lstm = nn.LSTM(memory_in, c.lstm_size, c.lstm_layers, batch_first=True)
            self.sensor_out = nn.Linear(c.lstm_size, c.z_sensors)
            motor_sizes = [c.n_motors, c.rec_hidden, c.z_motors]
        else:
            self.sensor_encoder = mlp([c.n_sensors, *c.ff_hidden, c.z_sensors])
            motor_sizes = [c.n_motors, *c.ff_hidden, c.z_motors]
        z_in = c.z_sensors
        if c.uses_motors:
            self.motor_encoder = mlp(motor_sizes)
            z_in += c.z_motors
        self.predictor = mlp([z_in, c.predictor_hidden, c.n_sensors])
        if c.motor_memory:
            self.transition = mlp([z_in, c.transition_hidden, c.z_sensors])
            nn.init.zeros_(self.transition[-1].weight)  # the imagined belief starts still:
            nn.init.zeros_(self.transition[-1].bias)  # open loop begins as "nothing moves"

    def encode(
        self, sensors: torch.Tensor, state: State = None, motors: torch.Tensor | None = None
    ) -> tuple[torch.Tensor, State]:
        """The sensory representation z_s of every step: (B, T, 5) -> (B, T, 10), new state.

        Feed-forward models treat steps independently and accept any leading shape (..., 5).
        Recurrent models carry the LSTM state (h, c) through time; ``state=None`` is zero.
        A motor memory also reads ``motors`` (B, T, 2), the commands m_t: at step t it sees
        m_{t-1}, the last one carried in the state (zero at the start).
        """
        if not self.config.recurrent:
            return self.sensor_encoder(sensors), None  # (..., 10)
        h = self.sensor_in(sensors)  # (B, T, 16)
        if not self.config.motor_memory:
            h, state = self.lstm(h, state)  # (B, T, 32); h, c: (3, B, 32)
            return self.sensor_out(h), state  # (B, T, 10)
        if motors is None:
            raise ValueError(f"{KINDS[self.config.kind].label} needs motor commands")
        last = motors.new_zeros(1, len(motors), motors.shape[-1]) if state is None else state[2]
        before = torch.cat([last.transpose(0, 1), motors[:, :-1]], dim=1)  # m_{t-1}: (B, T, 2)
        if not self.config.reads_motors:
            before = torch.zeros_like(before)
        lstm_state = None if state is None else state[:2]
        h, (hn, cn) = self.lstm(torch.cat([h, before], dim=-1), lstm_state)  # (B, T, 32)
        return self.sensor_out(h), (hn, cn, motors[:, -1:].transpose(0, 1))  # (B, T, 10)

    def forward(
        self, sensors: torch.Tensor, motors: torch.Tensor | None = None, state: State = None
    ) -> tuple[torch.Tensor, torch.Tensor, State]:
        """Predict s_{t+1} from s_t (and m_t): returns (prediction, z_s, state).

        sensors (B, T, 5) scaled readings, motors (B, T, 2) scaled commands (ignored by S models).
        """
        z_s, state = self.encode(sensors, state, motors)  # (B, T, 10)
        z = z_s
        if self.config.uses_motors:
            if motors is None:
                raise ValueError(f"{KINDS[self.config.kind].label} needs motor commands")
            z_m = self.motor_encoder(motors)  # (B, T, 5)
            z = torch.cat([z_s, z_m], dim=-1)  # (B, T, 15)
        return self.predictor(z), z_s, state  # (B, T, 5), (B, T, 10)

    def ahead(
        self, z_s: torch.Tensor, motors: torch.Tensor, steps: int, every: int = 1
    ) -> torch.Tensor:
        """Open-loop predictions of s_{t+1} .. s_{t+K} from the beliefs z_s at every
        ``every``-th step t, given the commands in between: z_s (B, T, 10), motors
        (B, T + K - 1, 2) with m_t at [:, t] -> (K, B, ceil(T / every), 5). The first is
        ``forward``'s prediction; each later one reads the belief the transition imagines one
        command further, without a reading."""
        if not self.config.motor_memory:
            raise ValueError(f"{KINDS[self.config.kind].label} has no open-loop transition")
        z = z_s[:, ::every]  # (B, T', 10)
        span = every * (z.shape[1] - 1) + 1
        z_m = self.motor_encoder(motors)  # (B, T + K - 1, 5)
        preds = []
        for k in range(steps):
            zz = torch.cat([z, z_m[:, k : k + span : every]], dim=-1)  # (B, T', 15)
            preds.append(self.predictor(zz))  # (B, T, 5): s_{t+k+1}
            if k + 1 < steps:
                z = z + self.transition(zz)  # (B, T, 10): the belief after m_{t+k}
        return torch.stack(preds)  # (K, B, T, 5)


def build_model(config: ModelConfig | str, seed: int | None = None) -> SensorimotorEncoder:
    """A freshly initialised encoder; with ``seed``, the initial weights depend on it alone."""
    if isinstance(config, str):
        config = ModelConfig(kind=config)
    if seed is None:
        return SensorimotorEncoder(config)
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(seed)
        return SensorimotorEncoder(config)


def count_parameters(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())
