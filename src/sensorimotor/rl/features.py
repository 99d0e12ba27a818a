"""What the policy sees: the true pose, the raw readings, or a frozen encoder's z_s.

``FeatureVecEnv`` wraps a vectorised task environment (``envs.tasks``) and replaces each
observation (the 5 readings) by one feature set. The feature sets are one registry,
``feature_sets()``, read when asked: the four below and one per model kind of
``learn.models.KINDS`` (a kind registered there is a feature set here):

======== ==== =================================================================================
name     size what
======== ==== =================================================================================
pose     4    the oracle: ``2x/W - 1, 2y/H - 1, cos(heading), sin(heading)`` (``info["pose"]``)
raw      5    the readings divided by the range (``sim.database.scale_sensors``)
KIND     10   z_s of the trained encoder of that kind (``s``, ``sm``: feed-forward; ``rec-s``,
              ``rec-sm``: recurrent, its LSTM state carried through the episode and set to zero
              when the episode ends, with the environment's reset), read from a runs folder
rec-sma  10   z_s of Rec-SMA, whose memory also reads the last command: the wrapper passes the
              command each action becomes (``(a0 + 1) / 2``, ``1.1 pi a1``, scaled as in training)
random   10   z_s of an *untrained* Recurrent-SM encoder (same shape, seeded weights): the
              baseline the S-RL Toolbox found strong
pose+raw 11   the oracle of a task that needs a memory (``homing``): the pose, the readings and
              the episode's start position (``2x/W - 1, 2y/H - 1``)
======== ==== =================================================================================

z_s depends on the readings (and for Rec-SMA the commands before them) alone in every model
(the motor command enters the predictor, not z_s; see ``learn.models``), so the features of
step t exist before the agent acts. A task that drives the robot before the agent's first
step (``homing``'s excursion, ``info["excursion"]`` of the reset) has its readings and
commands fed through a memory first, from a zero state: a recurrent encoder remembers them.
All parallel environments go through the encoder in one batched call per step. Every feature
set is standardised by the statistics of a training rollout, frozen (``rl.standardise``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from sensorimotor.envs.laser_world import MAX_STEP, MAX_TURN
from sensorimotor.errors import InputError
from sensorimotor.learn.evaluate import load_run
from sensorimotor.learn.models import KINDS, REC_SM, SensorimotorEncoder, build_model
from sensorimotor.rl import RUNS_ENV
from sensorimotor.rl.standardise import Standardisation
from sensorimotor.sim.core import DEFAULT_LAYOUT, MAX_RANGE
from sensorimotor.sim.database import scale_motors, scale_sensors

RANDOM_KIND = REC_SM  # the untrained encoder's architecture


def pose_features(
    readings: np.ndarray, poses: np.ndarray, size: tuple[float, float], homes: np.ndarray
) -> np.ndarray:
    """(n, 4) the oracle from the poses (n, 3) in a world of ``size`` (width, height)."""
    w, h = size
    x, y, heading = poses[:, 0], poses[:, 1], poses[:, 2]  # (n,) each
    out = np.stack([2 * x / w - 1, 2 * y / h - 1, np.cos(heading), np.sin(heading)], 1)
    return out.astype(np.float32)


def raw_features(
    readings: np.ndarray, poses: np.ndarray, size: tuple[float, float], homes: np.ndarray
) -> np.ndarray:
    """(n, 5) the readings (n, 5) scaled to [0, 1]."""
    return scale_sensors(readings, MAX_RANGE)


def pose_raw_features(
    readings: np.ndarray, poses: np.ndarray, size: tuple[float, float], homes: np.ndarray
) -> np.ndarray:
    """(n, 11) the oracle of a task that asks for a memory: the pose (4), the readings (5) and
    where the episode started (``2x/W - 1, 2y/H - 1`` of ``homes`` (n, 3)), all it depends on."""
    w, h = size
    home = np.stack([2 * homes[:, 0] / w - 1, 2 * homes[:, 1] / h - 1], 1).astype(np.float32)
    return np.concatenate(
        [pose_features(readings, poses, size, homes), raw_features(readings, poses, size, homes),
         home], 1
    )  # fmt: skip


@dataclass(frozen=True)
class FeatureSet:
    """One feature set: its name, its size and how it is computed (module doc)."""

    name: str
    size: int | None = None
    """Features per step; None: the encoder's z_s (``ModelConfig.z_sensors``)."""
    direct: (
        Callable[[np.ndarray, np.ndarray, tuple[float, float], np.ndarray], np.ndarray] | None
    ) = None
    """Computes them from the readings (n, 5), poses (n, 3), world size and the episodes'
    start poses (n, 3); None: an encoder's z_s of the scaled readings does."""
    kind: str | None = None
    """The encoder's model kind (``learn.models.KINDS``); None: no encoder."""
    trained: bool = False
    """The encoder is a training run read from the runs folder (else seeded, untrained)."""


POSE_RAW = "pose+raw"  # the oracle of homing (and any task that needs a memory)


def feature_sets() -> dict[str, FeatureSet]:
    """Every feature set by name: pose, raw, one per model kind in ``KINDS`` (read now, so a
    kind registered later is one; a memory that reads the motor commands gets the commands
    executed, the agent's and a task's excursion's), random, pose+raw."""
    return {
        "pose": FeatureSet("pose", 4, pose_features),
        "raw": FeatureSet("raw", 5, raw_features),
        **{k: FeatureSet(k, kind=k, trained=True) for k in KINDS},
        "random": FeatureSet("random", kind=RANDOM_KIND),
        POSE_RAW: FeatureSet(POSE_RAW, 11, pose_raw_features),
    }


def feature_set(name: str) -> FeatureSet:
    """The feature set ``name``; InputError naming the known ones."""
    sets = feature_sets()
    if name not in sets:
        raise InputError(f"unknown features {name!r}: use one of {', '.join(sets)}")
    return sets[name]


def needs_runs(features) -> list[str]:
    """Those of ``features`` read from trained encoder runs (``--runs``)."""
    sets = feature_sets()
    return [f for f in features if f in sets and sets[f].trained]


def parse_features(text: str) -> list[str]:
    """``"pose,raw,rec-sm"`` -> a list of known feature names, in order, without repeats."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    known = feature_sets()
    unknown = [n for n in names if n not in known]
    if unknown or not names:
        raise InputError(
            f"unknown features {', '.join(unknown) or repr(text)}: use some of {', '.join(known)}"
        )
    return list(dict.fromkeys(names))


def no_runs_error(features: list[str]) -> InputError:
    """The one line for trained feature sets asked for without a runs folder."""
    return InputError(
        f"features {', '.join(features)} read trained encoders: give --runs DIR (a folder of "
        f"runs named {{world}}__{{kind}}__s{{seed}}) or set {RUNS_ENV}"
    )


def run_folder(runs: Path, trained_on: str, kind: str, seed: int) -> Path:
    """The training run folder of one encoder: ``RUNS/{world}__{kind}__s{seed}`` (as
    ``sensorimotor reproduce`` names them)."""
    return Path(runs) / f"{trained_on}__{kind}__s{seed}"


def load_encoder(
    features: str, runs: Path | None, trained_on: str, seed: int
) -> tuple[SensorimotorEncoder | None, str | None]:
    """The frozen encoder behind ``features`` and the run folder it comes from.

    ``pose`` and ``raw`` need none: ``(None, None)``. ``random`` is an untrained
    Recurrent-SM encoder whose weights depend on ``seed`` alone. A trained one is RL seed
    ``seed``'s own encoder seed: ``run_folder(runs, trained_on, features, seed)``; it must be
    that kind, trained on that world, with the environment's sensor layout (InputError; also
    when ``runs`` is None).
    """
    fs = feature_set(features)
    if fs.kind is None:
        return None, None
    if not fs.trained:
        return _frozen(build_model(fs.kind, seed=seed)), None
    if runs is None:
        raise no_runs_error([features])
    folder = run_folder(runs, trained_on, fs.kind, seed)
    run = load_run(folder)
    layout = run.config["data"].get("sensor_layout")
    if layout is not None and layout != DEFAULT_LAYOUT.to_dict():
        raise InputError(
            f"{folder}: trained on sensor layout {layout}, the environment has "
            f"{DEFAULT_LAYOUT.to_dict()}"
        )
    if run.kind != fs.kind or run.trained_on != trained_on:
        raise InputError(
            f"{folder}: a {run.kind} encoder trained on {run.trained_on}, "
            f"not {fs.kind} on {trained_on}"
        )
    return _frozen(run.model), str(folder)


def _frozen(model: SensorimotorEncoder) -> SensorimotorEncoder:
    model.eval()
    for p in model.parameters():
        p.requires_grad_(False)
    return model


class FeatureVecEnv(VecEnvWrapper):
    """A vectorised task environment whose observations are one feature set (module doc).

    ``venv`` holds task environments (5 readings as observation, ``info["pose"]``), built by
    ``make_vec_env`` or by hand. With ``standardisation`` every observation (the terminal ones
    too) is standardised by those frozen statistics (``rl.standardise``). The recurrent
    state of each environment starts at zero on ``reset`` and after that environment's
    episode ends; ``terminal_observation`` in ``infos`` (what PPO bootstraps from at a
    truncation) gets the features of the last step, computed with the state of the episode
    that ended.
    """

    def __init__(
        self,
        venv: VecEnv,
        features: str,
        encoder: SensorimotorEncoder | None = None,
        standardisation: Standardisation | None = None,
    ) -> None:
        fs = feature_set(features)
        if (encoder is None) != (fs.kind is None):
            raise ValueError(
                f"features {features!r} {'need' if encoder is None else 'take no'} encoder"
            )
        self.features = features
        self.feature_set = fs
        self.standardisation = standardisation  # None: the features as computed
        self.encoder = encoder
        size = fs.size or encoder.config.z_sensors
        space = spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32)
        super().__init__(venv, observation_space=space)
        self.recurrent = encoder is not None and encoder.config.recurrent
        self.motor_memory = encoder is not None and encoder.config.motor_memory
        self.state = None  # recurrent: [h, c(, last command)], (layers, N, units); None before
        self.homes = np.zeros((self.num_envs, 3))  # (N, 3) where each episode started
        self.commands = torch.zeros(self.num_envs, 2)  # the last commands, scaled (N, 2)
        self.sizes = venv.get_attr("world")[0].width, venv.get_attr("world")[0].height

    def _zero_state(self) -> None:
        c = self.encoder.config
        shape = (c.lstm_layers, self.num_envs, c.lstm_size)
        self.state = [torch.zeros(shape), torch.zeros(shape)]
        if self.motor_memory:  # the last command, (1, N, 2): zero before the first
            self.state.append(torch.zeros(1, self.num_envs, 2))

    def _features(self, readings: np.ndarray, poses: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Features (n, F) of environments ``rows`` (n,) from their readings (n, 5) and poses
        (n, 3); advances their recurrent state by one step (a motor memory reads the last
        command, already in the state)."""
        if self.feature_set.direct is not None:  # pose, raw, pose+raw
            return self.feature_set.direct(readings, poses, self.sizes, self.homes[rows])
        scaled = scale_sensors(readings, MAX_RANGE)  # (n, 5) in [0, 1]
        with torch.no_grad():
            x = torch.from_numpy(scaled)[:, None, :]  # (n, 1, 5): one time step
            if not self.recurrent:
                return self.encoder.encode(x)[0][:, 0].numpy()  # (n, 10)
            state = tuple(part[:, rows] for part in self.state)
            motors = state[2].transpose(0, 1) if self.motor_memory else None  # (n, 1, 2)
            z, new = self.encoder.encode(x, state, motors)  # (n, 1, 10)
            for part, value in zip(self.state, new, strict=True):
                part[:, rows] = value
            return z[:, 0].numpy()  # (n, 10)

    def _start(self, rows, infos: list[dict]) -> None:
        """New episodes in environments ``rows`` (their reset ``infos``): the home is where each
        started; a memory starts from zero and reads the task's excursion, if any (the robot
        was driven before the agent's first step: ``envs.tasks.Task.excursion``)."""
        for i in rows:
            excursion = infos[i].get("excursion")
            self.homes[i] = infos[i]["pose"] if excursion is None else excursion["poses"][0]
            if not self.recurrent:
                continue
            for part in self.state:
                part[:, i] = 0.0
            if excursion is None or not len(excursion["readings"]):
                continue
            x = torch.from_numpy(scale_sensors(excursion["readings"], MAX_RANGE))[None]
            m = torch.from_numpy(scale_motors(excursion["motors"]))[None]  # (1, E, 2)
            with torch.no_grad():
                _, new = self.encoder.encode(x, None, m if self.motor_memory else None)
            for part, value in zip(self.state, new, strict=True):
                part[:, i : i + 1] = value

    def step_async(self, actions: np.ndarray) -> None:
        a = np.clip(np.asarray(actions, dtype=np.float64).reshape(self.num_envs, 2), -1.0, 1.0)
        commands = np.stack([(a[:, 0] + 1.0) / 2.0 * MAX_STEP, a[:, 1] * MAX_TURN], 1)  # (d, r)
        self.commands = torch.from_numpy(scale_motors(commands))  # (N, 2) as the encoder read
        self.venv.step_async(actions)

    def _out(self, features: np.ndarray) -> np.ndarray:
        """What the policy sees: the features, standardised when the wrapper has statistics."""
        s = self.standardisation
        return features.astype(np.float32) if s is None else s.apply(features)

    def reset(self) -> np.ndarray:
        readings = self.venv.reset()  # (N, 5)
        poses = np.array([info["pose"] for info in self.venv.reset_infos])  # (N, 3)
        if self.recurrent:
            self._zero_state()
        self._start(range(self.num_envs), self.venv.reset_infos)
        return self._out(self._features(readings, poses, np.arange(self.num_envs)))

    def step_wait(self):
        readings, rewards, dones, infos = self.venv.step_wait()  # readings: (N, 5)
        if self.motor_memory:  # the command just executed: what the memory reads next
            self.state[2][0] = self.commands
        done = np.flatnonzero(dones)  # (D,) environments whose episode ended (and were reset)
        if done.size:  # the last step of each ended episode, in that episode's state
            last = np.array([infos[i]["terminal_observation"] for i in done])  # (D, 5)
            poses = np.array([infos[i]["pose"] for i in done])  # (D, 3)
            for i, f in zip(done, self._out(self._features(last, poses, done)), strict=True):
                infos[i]["terminal_observation"] = f
            self._start(done, self.venv.reset_infos)  # the new episodes (zero state, excursion)
        poses = np.array(
            [
                self.venv.reset_infos[i]["pose"] if dones[i] else infos[i]["pose"]
                for i in range(self.num_envs)
            ]
        )  # (N, 3): where each observation was read (the new episode's start where reset)
        features = self._out(self._features(readings, poses, np.arange(self.num_envs)))
        return features, rewards, dones, infos
