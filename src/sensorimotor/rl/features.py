"""What the policy sees: the true pose, the raw readings, or a frozen encoder's z_s.

``FeatureVecEnv`` wraps a vectorised task environment (``envs.tasks``) and replaces each
observation (the 5 readings) by one feature set:

======== ==== =================================================================================
name     size what
======== ==== =================================================================================
pose     4    the oracle: ``2x/W - 1, 2y/H - 1, cos(heading), sin(heading)`` (``info["pose"]``)
raw      5    the readings divided by the range (``sim.database.scale_sensors``)
s, sm    10   z_s of a trained feed-forward encoder (``learn.models``) on the scaled readings
rec-s,   10   z_s of a trained recurrent encoder, its LSTM state carried through the episode
rec-sm        and set to zero when the episode ends (with the environment's reset)
random   10   z_s of an *untrained* Recurrent-SM encoder (same shape, seeded weights): the
              baseline the S-RL Toolbox found strong
======== ==== =================================================================================

z_s depends on the readings alone in every model (the motor command enters the predictor,
not z_s; see ``learn.models``), so the features of step t exist before the agent acts.
All parallel environments go through the encoder in one batched call per step.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch
from gymnasium import spaces
from stable_baselines3.common.vec_env import VecEnv, VecEnvWrapper

from sensorimotor.errors import InputError
from sensorimotor.learn.evaluate import load_run
from sensorimotor.learn.models import KINDS, REC_S, REC_SM, SM, S, SensorimotorEncoder, build_model
from sensorimotor.sim.core import DEFAULT_LAYOUT, MAX_RANGE
from sensorimotor.sim.database import scale_sensors

FEATURES = ("pose", "raw", S, SM, REC_S, REC_SM, "random")
RANDOM_KIND = REC_SM  # the untrained encoder's architecture
SIZES = {"pose": 4, "raw": 5}  # the encoders give z_s: ModelConfig.z_sensors


def parse_features(text: str) -> list[str]:
    """``"pose,raw,rec-sm"`` -> a list of known feature names, in order, without repeats."""
    names = [n.strip() for n in text.split(",") if n.strip()]
    unknown = [n for n in names if n not in FEATURES]
    if unknown or not names:
        raise InputError(
            f"unknown features {', '.join(unknown) or repr(text)}: use some of {', '.join(FEATURES)}"
        )
    return list(dict.fromkeys(names))


def run_folder(runs: Path, trained_on: str, kind: str, seed: int) -> Path:
    """The training run folder of one encoder: ``RUNS/{world}__{kind}__s{seed}`` (as
    ``sensorimotor reproduce`` names them)."""
    return Path(runs) / f"{trained_on}__{kind}__s{seed}"


def load_encoder(
    features: str, runs: Path, trained_on: str, seed: int
) -> tuple[SensorimotorEncoder | None, str | None]:
    """The frozen encoder behind ``features`` and the run folder it comes from.

    ``pose`` and ``raw`` need none: ``(None, None)``. ``random`` is an untrained
    Recurrent-SM encoder whose weights depend on ``seed`` alone. A trained one is RL seed
    ``seed``'s own encoder seed: ``run_folder(runs, trained_on, features, seed)``; it must be
    that kind, trained on that world, with the environment's sensor layout (InputError).
    """
    if features in SIZES:
        return None, None
    if features == "random":
        return _frozen(build_model(RANDOM_KIND, seed=seed)), None
    if features not in KINDS:
        raise InputError(f"unknown features {features!r}: use one of {', '.join(FEATURES)}")
    folder = run_folder(runs, trained_on, features, seed)
    run = load_run(folder)
    layout = run.config["data"].get("sensor_layout")
    if layout is not None and layout != DEFAULT_LAYOUT.to_dict():
        raise InputError(
            f"{folder}: trained on sensor layout {layout}, the environment has "
            f"{DEFAULT_LAYOUT.to_dict()}"
        )
    if run.kind != features or run.trained_on != trained_on:
        raise InputError(
            f"{folder}: a {run.kind} encoder trained on {run.trained_on}, "
            f"not {features} on {trained_on}"
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
    ``make_vec_env`` or by hand. The recurrent state of each environment starts at zero on
    ``reset`` and after that environment's episode ends; ``terminal_observation`` in ``infos``
    (what PPO bootstraps from at a truncation) gets the features of the last step, computed
    with the state of the episode that ended.
    """

    def __init__(
        self, venv: VecEnv, features: str, encoder: SensorimotorEncoder | None = None
    ) -> None:
        if features not in FEATURES:
            raise InputError(f"unknown features {features!r}: use one of {', '.join(FEATURES)}")
        if (encoder is None) != (features in SIZES):
            raise ValueError(
                f"features {features!r} {'need' if encoder is None else 'take no'} encoder"
            )
        self.features = features
        self.encoder = encoder
        size = SIZES.get(features) or encoder.config.z_sensors
        space = spaces.Box(-np.inf, np.inf, shape=(size,), dtype=np.float32)
        super().__init__(venv, observation_space=space)
        self.recurrent = encoder is not None and encoder.config.recurrent
        self.state = None  # recurrent: (h, c), each (layers, N, units); None before reset
        self.sizes = venv.get_attr("world")[0].width, venv.get_attr("world")[0].height

    def _zero_state(self) -> None:
        c = self.encoder.config
        shape = (c.lstm_layers, self.num_envs, c.lstm_size)
        self.state = (torch.zeros(shape), torch.zeros(shape))

    def _features(self, readings: np.ndarray, poses: np.ndarray, rows: np.ndarray) -> np.ndarray:
        """Features (n, F) of environments ``rows`` (n,) from their readings (n, 5) and poses
        (n, 3); advances their recurrent state by one step."""
        if self.features == "pose":
            w, h = self.sizes
            x, y, heading = poses[:, 0], poses[:, 1], poses[:, 2]  # (n,) each
            out = np.stack([2 * x / w - 1, 2 * y / h - 1, np.cos(heading), np.sin(heading)], 1)
            return out.astype(np.float32)  # (n, 4)
        scaled = scale_sensors(readings, MAX_RANGE)  # (n, 5) in [0, 1]
        if self.encoder is None:
            return scaled
        with torch.no_grad():
            x = torch.from_numpy(scaled)[:, None, :]  # (n, 1, 5): one time step
            if not self.recurrent:
                return self.encoder.encode(x)[0][:, 0].numpy()  # (n, 10)
            h, c = self.state
            z, (h_new, c_new) = self.encoder.encode(x, (h[:, rows], c[:, rows]))  # (n, 1, 10)
            h[:, rows], c[:, rows] = h_new, c_new
            return z[:, 0].numpy()  # (n, 10)

    def reset(self) -> np.ndarray:
        readings = self.venv.reset()  # (N, 5)
        poses = np.array([info["pose"] for info in self.venv.reset_infos])  # (N, 3)
        if self.recurrent:
            self._zero_state()
        return self._features(readings, poses, np.arange(self.num_envs))

    def step_wait(self):
        readings, rewards, dones, infos = self.venv.step_wait()  # readings: (N, 5)
        done = np.flatnonzero(dones)  # (D,) environments whose episode ended (and were reset)
        if done.size:  # the last step of each ended episode, in that episode's state
            last = np.array([infos[i]["terminal_observation"] for i in done])  # (D, 5)
            poses = np.array([infos[i]["pose"] for i in done])  # (D, 3)
            for i, f in zip(done, self._features(last, poses, done), strict=True):
                infos[i]["terminal_observation"] = f
            if self.recurrent:
                for part in self.state:
                    part[:, done] = 0.0  # a new episode starts from a zero state
        poses = np.array(
            [
                self.venv.reset_infos[i]["pose"] if dones[i] else infos[i]["pose"]
                for i in range(self.num_envs)
            ]
        )  # (N, 3): where each observation was read (the new episode's start where reset)
        return self._features(readings, poses, np.arange(self.num_envs)), rewards, dones, infos
