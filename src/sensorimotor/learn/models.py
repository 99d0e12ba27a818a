"""The four encoders of the paper (section III, sizes from section V.A), in one file.

Every model maps sensors s_t (and motors m_t) to a prediction of s_{t+1} through a sensory
representation z_s (10-d). Shapes: B batch, T time, 5 sensors, 2 motors.

    S-encoder      s_t -> 16 -> 32 -> 64 -> z_s(10)                   -> 128 -> s_{t+1}
    SM-encoder     s_t -> 16 -> 32 -> 64 -> z_s(10) | m_t -> 16 -> 32 -> 64 -> z_m(5) -> 128 -> s
    Recurrent-S    s_t -> 16 -> LSTM(3 x 32) -> z_s(10)               -> 128 -> s_{t+1}
    Recurrent-SM   s_t -> 16 -> LSTM(3 x 32) -> z_s(10) | m_t -> 16 -> z_m(5)   -> 128 -> s

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


@dataclass(frozen=True)
class Kind:
    """One encoder family: its traits decide its layers (``SensorimotorEncoder``), and every
    list of models in the package is read from ``KINDS``."""

    name: str
    """In commands and run-folder names (``square__rec-sm__s0``)."""
    label: str
    """The paper's name, in titles."""
    short: str
    """In tables and figure legends."""
    recurrent: bool
    """An LSTM memory between the sensor encoder and z_s."""
    motors: bool
    """The predictor reads the encoded motor command z_m."""
    motor_memory: bool = False
    """The memory reads the motor commands too (not yet built: ``SensorimotorEncoder`` refuses)."""
    cost: float = 100.0
    """Core-seconds one seed took in the paper grid on a 2-core CPU: longest jobs start first."""
    quick_epochs: int | None = None
    """Epoch cap at ``reproduce --scale quick`` (None: early stopping alone)."""

    def __post_init__(self) -> None:
        if self.motor_memory and not self.recurrent:
            raise ValueError(f"{self.name}: a memory that reads motors needs a memory")


KINDS: dict[str, Kind] = {}
"""Every model kind by name, in the order of the paper's Table I. Add one with ``register``."""


def register(kind: Kind) -> Kind:
    """Add ``kind`` to ``KINDS``: from here on it is trained, tabulated, analysed and reported
    wherever the package lists models."""
    if kind.name in KINDS or kind.name == "raw":
        raise ValueError(f"model kind {kind.name!r} is already taken")
    KINDS[kind.name] = kind
    return kind


S = register(Kind("s", "S-encoder", "S", False, False, cost=20, quick_epochs=10)).name
SM = register(Kind("sm", "SM-encoder", "SM", False, True, cost=44, quick_epochs=10)).name
REC_S = register(Kind("rec-s", "Recurrent-S-encoder", "Rec-S", True, False, cost=77, quick_epochs=30)).name
REC_SM = register(
    Kind("rec-sm", "Recurrent-SM-encoder", "Rec-SM", True, True, cost=230, quick_epochs=80)
).name


def paper_panels() -> list[str]:
    """The kinds in the order of the paper's Fig. 4 panels: without motors first, then with;
    memoryless before recurrent."""
    return sorted(KINDS, key=lambda k: (KINDS[k].motors, KINDS[k].recurrent))


State = tuple[torch.Tensor, torch.Tensor] | None  # LSTM (h, c), each (layers, B, 32); None = zero


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

    def __post_init__(self) -> None:
        """Refuse an unknown kind, and sizes that are not integers in 1..MAX_WIDTH (a
        hand-edited config.json would otherwise fail deep inside torch, or exhaust memory)."""
        if self.kind not in KINDS:
            raise ValueError(f"unknown model {self.kind!r}: use one of {', '.join(KINDS)}")
        object.__setattr__(self, "ff_hidden", tuple(self.ff_hidden))
        sizes = {k: v for k, v in asdict(self).items() if k not in ("kind", "ff_hidden")}
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
    """One of the four encoders, chosen by ``config.kind``."""

    def __init__(self, config: ModelConfig):
        super().__init__()
        c = config
        self.config = c
        if KINDS[c.kind].motor_memory:
            raise NotImplementedError(f"{c.kind}: a memory that reads motors is not built yet")
        if c.recurrent:
            self.sensor_in = nn.Sequential(nn.Linear(c.n_sensors, c.rec_hidden), nn.ReLU())
            self.lstm = nn.LSTM(c.rec_hidden, c.lstm_size, c.lstm_layers, batch_first=True)
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

    def encode(self, sensors: torch.Tensor, state: State = None) -> tuple[torch.Tensor, State]:
        """The sensory representation z_s of every step: (B, T, 5) -> (B, T, 10), new state.

        Feed-forward models treat steps independently and accept any leading shape (..., 5).
        Recurrent models carry the LSTM state (h, c) through time; ``state=None`` is zero.
        """
        if not self.config.recurrent:
            return self.sensor_encoder(sensors), None  # (..., 10)
        h = self.sensor_in(sensors)  # (B, T, 16)
        h, state = self.lstm(h, state)  # (B, T, 32); h, c: (3, B, 32)
        return self.sensor_out(h), state  # (B, T, 10)

    def forward(
        self, sensors: torch.Tensor, motors: torch.Tensor | None = None, state: State = None
    ) -> tuple[torch.Tensor, torch.Tensor, State]:
        """Predict s_{t+1} from s_t (and m_t): returns (prediction, z_s, state).

        sensors (B, T, 5) scaled readings, motors (B, T, 2) scaled commands (ignored by S models).
        """
        z_s, state = self.encode(sensors, state)  # (B, T, 10)
        z = z_s
        if self.config.uses_motors:
            if motors is None:
                raise ValueError(f"{KINDS[self.config.kind].label} needs motor commands")
            z_m = self.motor_encoder(motors)  # (B, T, 5)
            z = torch.cat([z_s, z_m], dim=-1)  # (B, T, 15)
        return self.predictor(z), z_s, state  # (B, T, 5), (B, T, 10)


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
