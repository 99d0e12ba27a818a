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
    """One line per feature set of ``rl.json``: final success, its CI and IQM, transfer."""
    lines = []
    for name, r in rl["results"].items():
        ok = r["success"]
        where = "".join(f", {w} {t['success']['mean']:.2f}" for w, t in r["transfer"].items())
        lines.append(
            f"{name}: success {ok['mean']:.2f} [{ok['ci_low']:.2f}, {ok['ci_high']:.2f}] "
            f"IQM {ok['iqm']:.2f}{where}"
        )
    return lines
