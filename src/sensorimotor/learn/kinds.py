"""The registry of encoder families: one ``Kind`` per family, its traits, its training
settings and its place in the paper, written once and read by every list of models in the
package. No torch here: the command line reads it to name the models in its help."""

from __future__ import annotations

from dataclasses import dataclass


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
    """The memory reads the previous motor command, and a transition predicts open loop."""
    cost: float = 100.0
    """Core-seconds one seed took in the paper grid on a 2-core CPU: longest jobs start first."""
    quick_epochs: int | None = None
    """Epoch cap at ``reproduce --scale quick`` (None: early stopping alone)."""
    training: tuple[tuple[str, int | float], ...] = ()
    """``TrainConfig`` settings of this kind that are not the paper's defaults."""
    paper: bool = True
    """One of the paper's four: trained by ``reproduce``'s paper stages, in its figures and
    claims. Another kind joins where its runs are (``reproduce --experiment memory``)."""

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
REC_S = register(
    Kind("rec-s", "Recurrent-S-encoder", "Rec-S", True, False, cost=77, quick_epochs=30)
).name
REC_SM = register(
    Kind("rec-sm", "Recurrent-SM-encoder", "Rec-SM", True, True, cost=230, quick_epochs=80)
).name
REC_SMA = register(
    Kind(
        "rec-sma",
        "Recurrent-SMA-encoder (action-conditioned memory)",
        "Rec-SMA",
        True,
        True,
        motor_memory=True,
        cost=1500,
        quick_epochs=40,
        training=(
            ("batch_size", 4),
            ("horizon", 256),
            ("ahead", 32),
            ("ahead_every", 4),
            ("min_ratio", 0.99),
        ),
        paper=False,
    )
).name


def paper_kinds() -> list[str]:
    """The paper's kinds (``Kind.paper``), in the order of its Table I."""
    return [name for name, kind in KINDS.items() if kind.paper]


def paper_panels() -> list[str]:
    """The paper's kinds in the order of its Fig. 4 panels: without motors first, then with;
    memoryless before recurrent."""
    return sorted(paper_kinds(), key=lambda k: (KINDS[k].motors, KINDS[k].recurrent))
