"""Statistics over seeds, as rliable reports them: mean, 95 % bootstrap CI, interquartile mean.

With a handful of seeds a mean alone says little (Agarwal et al., "Deep RL at the edge of the
statistical precipice", 2021): every score here comes with a percentile-bootstrap confidence
interval over seeds (fixed resampling seed: the same scores give the same bytes) and the
interquartile mean (IQM), the mean of the middle 50 % of the scores.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from sensorimotor.learn.models import KINDS

BOOTSTRAP = 10_000  # resamples
CONFIDENCE = 0.95
BOOTSTRAP_SEED = 0  # the resampling generator's seed: results are bytes-reproducible


def iqm(values: Sequence[float] | np.ndarray) -> float:
    """Interquartile mean: drop the lowest and the highest ``floor(n / 4)`` values, average the
    rest (``scipy.stats.trim_mean(values, 0.25)``, what rliable computes)."""
    v = np.sort(np.asarray(values, dtype=np.float64).ravel())
    cut = len(v) // 4
    return float(v[cut : len(v) - cut].mean())


def bootstrap_ci(
    values: Sequence[float] | np.ndarray, statistic=np.mean, resamples: int = BOOTSTRAP
) -> tuple[float, float]:
    """Percentile bootstrap ``CONFIDENCE`` interval of ``statistic`` over ``values`` (n,):
    resample n values with replacement ``resamples`` times; the 2.5 and 97.5 percentiles."""
    v = np.asarray(values, dtype=np.float64).ravel()
    rng = np.random.default_rng(BOOTSTRAP_SEED)
    samples = v[rng.integers(0, len(v), size=(resamples, len(v)))]  # (B, n)
    stats = (
        np.array([statistic(s) for s in samples]) if statistic is not np.mean else samples.mean(1)
    )
    alpha = (1.0 - CONFIDENCE) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    return float(low), float(high)


def summary(values: Sequence[float]) -> dict:
    """``{mean, ci_low, ci_high, iqm, iqm_ci_low, iqm_ci_high, per_seed}`` of per-seed scores."""
    v = [float(x) for x in values]
    if not v or not all(math.isfinite(x) for x in v):
        raise ValueError(f"scores must be finite and not empty, got {v}")
    low, high = bootstrap_ci(v)
    iqm_low, iqm_high = bootstrap_ci(v, iqm, resamples=2_000)
    return {
        "mean": float(np.mean(v)),
        "ci_low": low,
        "ci_high": high,
        "iqm": iqm(v),
        "iqm_ci_low": iqm_low,
        "iqm_ci_high": iqm_high,
        "per_seed": v,
    }


def summary_lines(rl: dict) -> list[str]:
    """One line per feature set of ``rl.json``: final success, its CI and IQM, transfer; then
    the verdicts."""
    lines = []
    for score, how in (("success", "deterministic"), ("success_stochastic", "stochastic")):
        lines.append(f"final success, {how} policy, mean [95 % CI] IQM, then transfer:")
        for name, r in rl["results"].items():
            ok = r[score]
            where = "".join(f", {w} {t[score]['mean']:.2f}" for w, t in r["transfer"].items())
            lines.append(
                f"  {name}: {ok['mean']:.2f} [{ok['ci_low']:.2f}, {ok['ci_high']:.2f}] "
                f"IQM {ok['iqm']:.2f}{where}"
            )
        v = rl["verdicts"][score]
        if v["motors_help"]["supported"] is not None:
            yes = "supported" if v["motors_help"]["supported"] else "not supported"
            lines.append(f"  {CLAIM}: {yes}")
        if v["pose_beats_random"]["supported"] is not None:
            d = v["pose_beats_random"]["difference"]
            lines.append(
                f"  pose - random: {d['mean']:+.2f} [{d['ci_low']:+.2f}, {d['ci_high']:+.2f}]"
            )
    return lines


HEADLINE = "success_stochastic"
"""The score a report leads with: the success rate of the policy PPO trains, its actions sampled
(DESIGN.md, "Reinforcement learning": the mean action rewards reflexes and fails the oracle)."""
MIN_SEEDS = 3  # fewer seeds: a report states no verdict (a bootstrap over 2 values says nothing)
MOTOR_FEATURES = tuple(k for k in KINDS if KINDS[k].motors)  # encoders trained with motors
CLAIM = "features learned with motors help the agent more than raw readings"
THRESHOLD = (
    "supported when, for every motor-trained feature set in the grid (sm, rec-sm), the 95 % "
    "bootstrap CI of its mean final success minus raw's, paired by seed, lies above 0"
)


def paired_difference(a: Sequence[float], b: Sequence[float]) -> dict:
    """``summary`` of the per-seed differences ``a[i] - b[i]``: agents of the same seed meet the
    same training and evaluation starts, so the pairing removes the starts' share of noise."""
    if len(a) != len(b):
        raise ValueError(f"paired scores need as many seeds: {len(a)} and {len(b)}")
    return summary([x - y for x, y in zip(a, b, strict=True)])


def verdicts(results: dict, score: str = "success") -> dict:
    """The paper's expectation (conclusion) tested on the final ``score`` (a success rate), the
    same threshold against the untrained encoder (``motors_beat_random``: is the help learned?),
    and the sanity check that the oracle ``pose`` beats ``random``; each ``None`` when its
    feature sets were not run."""

    def diff(a: str, b: str) -> dict | None:
        if a not in results or b not in results:
            return None
        return paired_difference(results[a][score]["per_seed"], results[b][score]["per_seed"])

    motors = {f: diff(f, "raw") for f in MOTOR_FEATURES if f in results}
    motors = {f: d for f, d in motors.items() if d is not None}
    learned = {f: diff(f, "random") for f in MOTOR_FEATURES if f in results}
    learned = {f: d for f, d in learned.items() if d is not None}
    pose = diff("pose", "random")
    return {
        "motors_beat_random": {  # is it what the encoder learned, or any recurrent features?
            "differences": learned,
            "supported": all(d["ci_low"] > 0 for d in learned.values()) if learned else None,
        },
        "motors_help": {
            "claim": CLAIM,
            "threshold": THRESHOLD,
            "differences": motors,
            "supported": all(d["ci_low"] > 0 for d in motors.values()) if motors else None,
        },
        "pose_beats_random": {
            "difference": pose,
            "supported": None if pose is None else pose["ci_low"] > 0,
        },
    }
