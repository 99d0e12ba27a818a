"""Standardised features: zero mean and unit sd on the rollout they were measured on, frozen
afterwards (the same observations give the same numbers), the same seed the same bytes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")

from sensorimotor.rl.features import load_encoder
from sensorimotor.rl.runner import RLConfig, make_env, standardisation_for
from sensorimotor.rl.standardise import fit, rollout_features

RUNS = Path(__file__).parents[2] / "docs" / "results" / "runs"
CONFIG = RLConfig(task="corner", world="rooms1", runs=str(RUNS), n_envs=3, stats_steps=300)


def env(features: str, seed: int = 7, scaled=None):
    encoder, _ = load_encoder(features, RUNS, "rooms1", 0)
    return make_env(CONFIG, "rooms1", features, encoder, 3, seed, True, scaled)


@pytest.mark.parametrize("features", ["pose", "raw", "rec-sm", "random"])
def test_standardised_features_have_zero_mean_and_unit_sd_on_their_rollout(features):
    stats = fit(env(features), 300, seed=1)
    assert stats.sd.shape == stats.mean.shape == env(features).observation_space.shape
    assert (stats.sd > 0).all()
    again = rollout_features(env(features, scaled=stats), 300, seed=1)  # the same rollout
    np.testing.assert_allclose(again.mean(0), 0.0, atol=1e-5)
    np.testing.assert_allclose(again.std(0), 1.0, atol=1e-4)


def test_the_statistics_are_frozen_the_same_observations_give_the_same_numbers():
    stats = fit(env("rec-sm"), 300, seed=1)
    plain, scaled = env("rec-sm", seed=11), env("rec-sm", seed=11, scaled=stats)
    np.testing.assert_array_equal(scaled.reset(), stats.apply(plain.reset()))
    rng = np.random.default_rng(0)
    ends = 0
    for _ in range(250):  # corner ends episodes: terminal observations too
        a = rng.uniform(-1, 1, (3, 2)).astype(np.float32)
        (o1, _, d1, i1), (o2, _, _d2, i2) = plain.step(a), scaled.step(a)
        np.testing.assert_array_equal(o2, stats.apply(o1))
        for k in np.flatnonzero(d1):
            ends += 1
            np.testing.assert_array_equal(
                i2[k]["terminal_observation"], stats.apply(i1[k]["terminal_observation"][None])[0]
            )
    assert ends > 0
    # far from the rollout the statistics stay: a second pass gives the same numbers again
    np.testing.assert_array_equal(fit(env("rec-sm"), 300, seed=1).sd, stats.sd)


def test_the_same_seed_gives_the_same_bytes_another_seed_other_numbers():
    encoder, _ = load_encoder("random", RUNS, "rooms1", 2)
    a = standardisation_for(CONFIG, "random", encoder, 2)
    b = standardisation_for(CONFIG, "random", encoder, 2)
    assert a.mean.tobytes() == b.mean.tobytes()
    assert a.sd.tobytes() == b.sd.tobytes()
    c = standardisation_for(CONFIG, "random", encoder, 3)
    assert not np.array_equal(a.mean, c.mean)
    d = a.to_dict()
    assert len(d["sd"]) == 10
    assert d["steps"] == 300
    assert standardisation_for(RLConfig(stats_steps=0), "raw", None, 0) is None
