"""Statistics over seeds and the verdict type (``sensorimotor.stats``): one convention each,
checked against textbook values, scipy and the published Table I."""

from __future__ import annotations

import doctest
import json
import math
from pathlib import Path

import numpy as np
import pytest
from scipy import stats as scipy_stats

from sensorimotor import stats
from sensorimotor.stats import (
    BEFORE,
    CHOSEN,
    Verdict,
    bootstrap_interval,
    describe,
    interval,
    interval_name,
    iqm,
    mean_sd,
    paired_differences,
    present,
    se_of_difference,
    standard_error,
    t_interval,
    unless_missing,
    word,
)

TABLE_I = Path(__file__).parents[1] / "docs" / "results" / "table1.json"


def test_the_docstring_examples_hold():
    assert doctest.testmod(stats).failed == 0


def test_one_value_has_sd_zero_and_its_n_beside_it():
    assert mean_sd([0.25]) == (0.25, 0.0)
    assert describe([0.25]) == {"mean": 0.25, "sd": 0.0, "n": 1}
    assert mean_sd([1.0, 3.0]) == (2.0, math.sqrt(2.0))
    assert describe(np.array([1.0, 2.0, 6.0]))["n"] == 3


def test_missing_values_are_refused_unless_dropped_by_name():
    for bad in ([1.0, None], [1.0, math.nan], [np.float32("nan"), 2.0]):
        with pytest.raises(ValueError, match=r"stats\.present"):
            mean_sd(bad)
        with pytest.raises(ValueError, match="missing"):
            t_interval(bad)
    with pytest.raises(ValueError, match="no values"):
        mean_sd([])
    assert present([1.0, None, math.nan, 3.0]) == [1.0, 3.0]
    assert mean_sd(present([1.0, None, 3.0])) == (2.0, math.sqrt(2.0))
    assert unless_missing([0.5, 0.2], 0.5 > 0.2) is True
    assert unless_missing([0.1, 0.2], np.bool_(False)) is False
    assert unless_missing([math.nan, 0.2], False) is None
    assert unless_missing([None, 0.2], True) is None


def test_table_one_keeps_its_published_means_and_sds_to_the_bit():
    table = json.loads(TABLE_I.read_text())
    cells = [c for rows in table["tables"].values() for r in rows for c in r["cells"].values()]
    assert cells
    for cell in cells:
        assert mean_sd(cell["values"]) == (cell["mean"], cell["sd"])
        assert cell["n"] == len(cell["values"])


def test_standard_errors():
    assert standard_error([1.0]) is None
    assert standard_error([1.0, 2.0, 3.0]) == pytest.approx(1.0 / math.sqrt(3))
    assert se_of_difference(0.3, 4, 0.4, 4) == pytest.approx(0.25)  # sqrt(0.09/4 + 0.16/4)
    assert se_of_difference(0.3, 1, 0.4, 4) is None


def test_paired_differences_go_seed_by_seed():
    assert paired_differences([0.5, 0.75], [0.25, 0.5]) == [0.25, 0.25]
    # mappings pair on their seeds whatever their order, and come back in seed order
    assert paired_differences({2: 1.0, 0: 0.5, 1: 0.0}, {0: 0.25, 1: 0.5, 2: 0.0}) == [
        0.25,
        -0.5,
        1.0,
    ]
    with pytest.raises(ValueError, match="the same seeds"):
        paired_differences({0: 1.0, 1: 2.0}, {0: 1.0, 2: 2.0})
    with pytest.raises(ValueError, match="as many seeds"):
        paired_differences([1.0, 2.0], [1.0])
    with pytest.raises(ValueError, match="missing"):
        paired_differences([1.0, None], [1.0, 2.0])


def test_student_t_interval_against_the_textbook_and_scipy():
    # 1..5: mean 3, sd sqrt(2.5), t(4, 0.975) = 2.7764451: half-width 1.96324
    low, high = t_interval([1.0, 2.0, 3.0, 4.0, 5.0])
    assert (low, high) == pytest.approx((3 - 1.9632432, 3 + 1.9632432), abs=1e-6)
    x = [0.12, 0.31, 0.25, 0.4, 0.18, 0.22]
    want = scipy_stats.t.interval(0.9, len(x) - 1, loc=np.mean(x), scale=scipy_stats.sem(x))
    assert t_interval(x, confidence=0.9) == pytest.approx(want, rel=1e-12)
    assert t_interval([0.4]) is None
    assert t_interval([0.4, 0.4, 0.4]) == pytest.approx((0.4, 0.4))


def test_the_bootstrap_is_deterministic_and_right_by_hand():
    # n = 2 scores {0, 1}: resampled means are 0, 0.5, 1 with probability 1/4, 1/2, 1/4
    assert bootstrap_interval([0.0, 1.0]) == (0.0, 1.0)
    # {0, 0, 0, 1}: P(mean = 0) = 0.316; P(mean <= 0.5) = 0.949, P(mean <= 0.75) = 0.996
    assert bootstrap_interval([0.0, 0.0, 0.0, 1.0]) == (0.0, 0.75)
    x = np.random.default_rng(3).random(12)
    assert bootstrap_interval(x) == bootstrap_interval(list(x))  # the same bytes
    assert bootstrap_interval(x, seed=1) != bootstrap_interval(x)
    assert bootstrap_interval(x, iqm, resamples=500) == bootstrap_interval(x, iqm, resamples=500)


def test_a_stratified_bootstrap_resamples_within_each_stratum():
    values, strata = [0.0, 0.0, 1.0, 1.0], ["a", "a", "b", "b"]
    # every stratified resample keeps two 0s and two 1s: its mean is always 0.5
    assert bootstrap_interval(values, strata=strata) == (0.5, 0.5)
    low, high = bootstrap_interval(values)
    assert low < 0.5 < high
    with pytest.raises(ValueError, match="one stratum per value"):
        bootstrap_interval(values, strata=["a"])


def test_wilson_interval_against_the_textbook():
    # Newcombe (1998), table I: 81 of 263 -> 0.2553-0.3662; 0 of 10 -> 0-0.2775; 10 of 10 mirrors it
    assert stats.wilson_interval(81, 263) == pytest.approx((0.2553, 0.3662), abs=5e-5)
    assert stats.wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=5e-5)
    assert stats.wilson_interval(10, 10) == pytest.approx((1 - 0.2775, 1.0), abs=5e-5)
    with pytest.raises(ValueError, match="11 successes of 10 trials"):
        stats.wilson_interval(11, 10)


def test_iqm_on_known_arrays():
    assert iqm([1.0, 2.0, 3.0, 4.0, 100.0]) == 3.0  # the lowest and highest dropped
    assert iqm([4.0, 1.0, 3.0, 2.0]) == 2.5
    assert iqm([0.0, 1.0, 0.5]) == 0.5  # n = 3: nothing dropped, the mean
    x = np.random.default_rng(0).random(17)
    assert iqm(x) == pytest.approx(scipy_stats.trim_mean(x, 0.25))


def test_interval_is_student_t_below_ten_values_and_the_bootstrap_from_ten():
    x = list(np.random.default_rng(1).random(12))
    assert interval(x[:9]) == t_interval(x[:9])
    assert interval(x[:9]) != bootstrap_interval(x[:9])
    assert interval(x[:10]) == bootstrap_interval(x[:10])
    assert interval(x[:10]) != t_interval(x[:10])
    assert interval(x[:1]) is None
    assert [interval_name(n) for n in (1, 2, 9, 10, 30)] == [
        None,
        "Student-t",
        "Student-t",
        "bootstrap",
        "bootstrap",
    ]


def test_a_verdict_is_strict_json_and_records_its_provenance():
    v = Verdict(
        claim="the map predicts better than Markov",
        threshold="mean paired difference above 0.05",
        test="95 % Student-t interval of paired differences lies above 0.05",
        numbers={"mean": math.nan, "se": math.inf, "n": np.int64(3), "values": (1.0, -math.inf)},
        holds=np.bool_(True),
        provenance=BEFORE,
        where="experiments/map.py, MARGINS",
    )
    d = v.to_dict()
    text = json.dumps(d, allow_nan=False)
    assert d["numbers"] == {"mean": None, "se": None, "n": 3, "values": [1.0, None]}
    assert d["holds"] is True
    assert v.holds is True
    assert set(d) == {"claim", "threshold", "test", "numbers", "holds", "provenance", "where"}
    assert Verdict.from_dict(json.loads(text)).to_dict() == d
    with pytest.raises(ValueError, match="provenance"):
        Verdict("c", "t", "x", "", None, "guessed", "nowhere")
    chosen = Verdict("c", "t", "x", "1.0", None, CHOSEN, "here")
    assert chosen.to_dict()["provenance"] == "chosen on these data"


def test_verdict_words():
    assert [word(h) for h in (True, False, None)] == ["supported", "not supported", "n/a"]
    assert [word(h, "holds", "fails") for h in (True, False, None)] == ["holds", "fails", "n/a"]
    v = Verdict("c", "t", "x", "", False, BEFORE, "w")
    assert v.word() == "not supported"
