"""Statistics over seeds and the one verdict type: every table, claim and test of the package.

One convention each:

- **mean and sd**: ``mean_sd`` gives the mean and the sample standard deviation (n - 1); for
  one value the sd is 0.0 and the caller reports n beside it (``describe``: mean, sd, n), so a
  table shows "± sd" only where n > 1. Table I, the claims, the map, RL and scaling all use it.
- **missing numbers** (None, NaN) are *refused* by every statistic here (ValueError). A caller
  that means to leave them out says so with ``present``, the one helper that drops them.
- **pairs**: ``paired_differences`` takes a - b seed by seed (the same seed meets the same
  data, splits and starts: pairing removes their share of the noise).
- **intervals of a mean**: ``t_interval`` (Student-t), ``bootstrap_interval`` (percentile
  bootstrap, stratified as rliable's, a fixed resampling seed: the same values give the same
  bytes) and ``interval``, which picks between them: **Student-t below 10 values, the bootstrap
  from 10 up** (a bootstrap of a handful of values only resamples what it saw and is too
  narrow; Agarwal et al., "Deep RL at the edge of the statistical precipice", 2021). ``iqm``:
  the interquartile mean, rliable's aggregate. ``wilson_interval``: the interval of a share
  of successes over independent trials (episodes, start/goal pairs), exact-coverage-like near
  0 and 1 where the normal one collapses.
- **verdicts**: ``Verdict`` records a claim, its threshold, its test, its numbers, whether it
  holds (None: not judged), and the threshold's provenance: ``BEFORE`` ("set before the
  data") or ``CHOSEN`` ("chosen on these data"), with ``where`` it was set (a file, a section,
  a commit). ``Verdict.to_dict`` is strict JSON (no NaN, no Infinity).

>>> mean_sd([1.0, 2.0, 3.0])
(2.0, 1.0)
>>> describe([0.5])
{'mean': 0.5, 'sd': 0.0, 'n': 1}
>>> mean_sd(present([1.0, None, float("nan"), 3.0]))
(2.0, 1.4142135623730951)
>>> paired_differences({1: 0.5, 0: 0.25}, {0: 0.0, 1: 0.25})
[0.25, 0.25]
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass

import numpy as np

CONFIDENCE = 0.95
T_BELOW = 10  # ``interval``: Student-t below this many values, the bootstrap from it up
BOOTSTRAP = 10_000  # resamples
BOOTSTRAP_SEED = 0  # the resampling generator's seed: results are bytes-reproducible

BEFORE = "set before the data"
CHOSEN = "chosen on these data"
PROVENANCES = (BEFORE, CHOSEN)


# --- missing numbers ---------------------------------------------------------------------------


def is_missing(value) -> bool:
    """None or NaN (of any float type)."""
    return value is None or value != value  # NaN is the one value unequal to itself


def present(values) -> list[float]:
    """The values that are there, as floats: None and NaN left out. The one place where missing
    numbers are dropped; every statistic below refuses them."""
    return [float(v) for v in _flat(values) if not is_missing(v)]


def unless_missing(values, holds) -> bool | None:
    """``holds`` as a bool, or None (not judged) when a number it rests on is missing."""
    return None if any(is_missing(v) for v in _flat(values)) else bool(holds)


def _flat(values) -> list:
    return list(values.ravel()) if isinstance(values, np.ndarray) else list(values)


def _numbers(values, what: str) -> list[float]:
    """``values`` as floats; ValueError if one is missing (the caller decides: ``present``)."""
    v = _flat(values)
    if any(is_missing(x) for x in v):
        raise ValueError(
            f"{what}: a value is missing (None or NaN) in {v}; leave it out with stats.present"
        )
    return [float(x) for x in v]


# --- mean, sd, standard errors, pairs ------------------------------------------------------------


def mean_sd(values) -> tuple[float, float]:
    """Mean and sample standard deviation (n - 1); 0.0 for one value (report n beside it).
    ValueError for no value or a missing one."""
    v = _numbers(values, "mean_sd")
    if not v:
        raise ValueError("mean_sd: no values")
    mean = sum(v) / len(v)
    if len(v) < 2:
        return mean, 0.0
    return mean, math.sqrt(sum((x - mean) ** 2 for x in v) / (len(v) - 1))


def describe(values) -> dict:
    """``{"mean", "sd", "n"}`` of ``values`` (``mean_sd``'s convention)."""
    mean, sd = mean_sd(values)
    return {"mean": mean, "sd": sd, "n": len(_flat(values))}


def standard_error(values) -> float | None:
    """sd / sqrt(n) of the mean; None below two values (no spread to estimate)."""
    v = _numbers(values, "standard_error")
    return None if len(v) < 2 else mean_sd(v)[1] / math.sqrt(len(v))


def se_of_difference(sd_a: float, n_a: int, sd_b: float, n_b: int) -> float | None:
    """Standard error of the difference of two means over independent seeds (Welch):
    sqrt(sd_a² / n_a + sd_b² / n_b); None unless both have two values or more."""
    if min(n_a, n_b) < 2:
        return None
    return math.sqrt(sd_a**2 / n_a + sd_b**2 / n_b)


def paired_differences(a, b) -> list[float]:
    """``a - b`` seed by seed. Sequences: position i is seed i of both (as many of each);
    mappings ``{seed: value}``: paired on their seeds (the same in both), in seed order.
    ValueError when the seeds differ or a value is missing."""
    if isinstance(a, Mapping) or isinstance(b, Mapping):
        if not (isinstance(a, Mapping) and isinstance(b, Mapping)) or set(a) != set(b):
            raise ValueError(f"paired values need the same seeds: {list(a)} and {list(b)}")
        seeds = sorted(a)
        a, b = [a[s] for s in seeds], [b[s] for s in seeds]
    x, y = _numbers(a, "paired_differences"), _numbers(b, "paired_differences")
    if len(x) != len(y):
        raise ValueError(f"paired values need as many seeds: {len(x)} and {len(y)}")
    return [p - q for p, q in zip(x, y, strict=True)]


# --- intervals ---------------------------------------------------------------------------------


def t_interval(values, confidence: float = CONFIDENCE) -> tuple[float, float] | None:
    """The Student-t ``confidence`` interval of the mean: mean ± t(n - 1) · sd / sqrt(n);
    None below two values."""
    from scipy.stats import t

    v = _numbers(values, "t_interval")
    if len(v) < 2:
        return None
    mean, sd = mean_sd(v)
    half = float(t.ppf(0.5 + confidence / 2, len(v) - 1)) * sd / math.sqrt(len(v))
    return mean - half, mean + half


def wilson_interval(
    successes: int, trials: int, confidence: float = CONFIDENCE
) -> tuple[float, float]:
    """Wilson's score ``confidence`` interval of a success rate ``successes / trials``."""
    from scipy.stats import norm

    if not 0 <= successes <= trials or trials < 1:
        raise ValueError(f"wilson_interval: {successes} successes of {trials} trials")
    z = float(norm.ppf(0.5 + confidence / 2))
    p = successes / trials
    centre = (p + z * z / (2 * trials)) / (1 + z * z / trials)
    half = (
        z / (1 + z * z / trials) * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials))
    )
    return max(0.0, centre - half), min(1.0, centre + half)


def iqm(values) -> float:
    """Interquartile mean: drop the lowest and the highest ``floor(n / 4)`` values, average the
    rest (``scipy.stats.trim_mean(values, 0.25)``, what rliable computes)."""
    v = np.sort(np.asarray(_numbers(values, "iqm"), dtype=np.float64))
    cut = len(v) // 4
    return float(v[cut : len(v) - cut].mean())


def bootstrap_interval(
    values,
    statistic: Callable = np.mean,
    *,
    strata: Sequence | None = None,
    resamples: int = BOOTSTRAP,
    confidence: float = CONFIDENCE,
    seed: int = BOOTSTRAP_SEED,
) -> tuple[float, float]:
    """Percentile bootstrap ``confidence`` interval of ``statistic`` over ``values``: draw
    ``resamples`` samples with replacement, each stratum (``strata``: a label per value, e.g.
    the task; None: one stratum) resampled within itself to its own size, as rliable's
    stratified bootstrap; the statistic of each sample, then its (1 ± confidence) / 2
    quantiles. A fixed ``seed``: the same values give the same interval."""
    v = np.asarray(_numbers(values, "bootstrap_interval"), dtype=np.float64)
    if not len(v):
        raise ValueError("bootstrap_interval: no values")
    rng = np.random.default_rng(seed)
    if strata is None:
        samples = v[rng.integers(0, len(v), size=(resamples, len(v)))]  # (B, n)
    else:
        labels = list(strata)
        if len(labels) != len(v):
            raise ValueError(f"one stratum per value: {len(labels)} labels, {len(v)} values")
        groups = [np.flatnonzero([label == g for label in labels]) for g in dict.fromkeys(labels)]
        samples = np.concatenate(
            [v[g][rng.integers(0, len(g), size=(resamples, len(g)))] for g in groups], axis=1
        )
    by_mean = statistic is np.mean  # one vectorised mean over each resample
    stats = samples.mean(1) if by_mean else np.array([statistic(s) for s in samples])
    alpha = (1.0 - confidence) / 2.0
    low, high = np.quantile(stats, [alpha, 1.0 - alpha])
    return float(low), float(high)


def interval_name(n: int) -> str | None:
    """The interval ``interval`` gives for ``n`` values: "Student-t", "bootstrap" or None."""
    return None if n < 2 else ("Student-t" if n < T_BELOW else "bootstrap")


def interval(
    values, confidence: float = CONFIDENCE, strata: Sequence | None = None
) -> tuple[float, float] | None:
    """The ``confidence`` interval of the mean of ``values``: **Student-t below 10 values**
    (``T_BELOW``; ``t_interval``), the percentile **bootstrap from 10 up**
    (``bootstrap_interval``, stratified by ``strata`` where given). None below two values."""
    v = _numbers(values, "interval")
    if len(v) < T_BELOW:
        return t_interval(v, confidence)
    return bootstrap_interval(v, np.mean, strata=strata, confidence=confidence)


def balanced_accuracy(truth, guess) -> float:
    """The mean over the labels present in ``truth`` of the fraction of their steps guessed
    right: a constant guess scores 1 / (labels present), whatever the labels' frequencies (a
    guess of a label absent from ``truth`` is simply wrong)."""
    truth, guess = np.asarray(truth), np.asarray(guess)
    return float(np.mean([(guess[truth == c] == c).mean() for c in np.unique(truth)]))


# --- verdicts ----------------------------------------------------------------------------------


def word(
    holds: bool | None, yes: str = "supported", no: str = "not supported", none: str = "n/a"
) -> str:
    """A verdict in words: the report's claims table says "supported", "not supported", "n/a";
    the map and scaling sections pass their own words ("holds", "fails")."""
    return none if holds is None else (yes if holds else no)


def jsonable(obj):
    """``obj`` as strict JSON data: NaN and ±Infinity become None, numpy scalars and arrays
    Python numbers and lists, tuples lists, mapping keys strings."""
    if isinstance(obj, Mapping):
        return {str(k): jsonable(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple | np.ndarray):
        return [jsonable(v) for v in obj]
    if isinstance(obj, bool | np.bool_):
        return bool(obj)
    if isinstance(obj, int | np.integer):
        return int(obj)
    if isinstance(obj, float | np.floating):
        return float(obj) if math.isfinite(obj) else None
    return obj


@dataclass(frozen=True)
class Verdict:
    """One claim tested: its wording, its threshold, the test (what is compared, how), the
    numbers, whether it holds (None: not judged, a number missing or too few seeds), and the
    threshold's provenance (``BEFORE`` or ``CHOSEN``) with ``where`` it was set."""

    claim: str
    threshold: str
    test: str
    numbers: str | Mapping
    holds: bool | None
    provenance: str
    where: str

    def __post_init__(self):
        if self.provenance not in PROVENANCES:
            raise ValueError(f"provenance must be one of {PROVENANCES}, got {self.provenance!r}")
        if self.holds is not None:
            object.__setattr__(self, "holds", bool(self.holds))  # a numpy bool too

    def word(self, yes: str = "supported", no: str = "not supported", none: str = "n/a") -> str:
        return word(self.holds, yes, no, none)

    def to_dict(self) -> dict:
        """Strict JSON data (no NaN, no Infinity: they become null)."""
        d = jsonable(asdict(self))
        json.dumps(d, allow_nan=False)  # a last check: nothing here may be left that is not JSON
        return d

    @classmethod
    def from_dict(cls, d: Mapping) -> Verdict:
        return cls(**{k: d[k] for k in cls.__dataclass_fields__})


__all__ = [
    "BEFORE",
    "BOOTSTRAP",
    "BOOTSTRAP_SEED",
    "CHOSEN",
    "CONFIDENCE",
    "T_BELOW",
    "Verdict",
    "balanced_accuracy",
    "bootstrap_interval",
    "describe",
    "interval",
    "interval_name",
    "iqm",
    "is_missing",
    "jsonable",
    "mean_sd",
    "paired_differences",
    "present",
    "se_of_difference",
    "standard_error",
    "t_interval",
    "unless_missing",
    "word",
]
