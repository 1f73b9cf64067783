"""Rates with intervals and paired tests (rabbit_policy.evaluation.statistics), and the push
scenarios' neighbourhoods (rabbit_policy.evaluation.push_recovery.Neighbourhood)."""

from __future__ import annotations

import math

import pytest

from rabbit_policy.evaluation.push_recovery import PUSH_SCENARIOS, Neighbourhood
from rabbit_policy.evaluation.statistics import format_rate, mcnemar_exact, rate, wilson_interval

pytestmark = pytest.mark.unit


def test_wilson_intervals_match_published_values_and_stay_in_0_1():
    # Newcombe (1998), Table I: 81/263 -> 0.2553-0.3662; 15/148 -> 0.0624-0.1605; 0/20 -> 0-0.1611
    for (k, n), (low, high) in (((81, 263), (0.2553, 0.3662)), ((15, 148), (0.0624, 0.1605)),
                                ((0, 20), (0.0, 0.1611)), ((20, 20), (0.8389, 1.0))):
        got = wilson_interval(k, n)
        assert got == pytest.approx((low, high), abs=1e-4)
    assert wilson_interval(0, 0) == (0.0, 1.0)
    for bad in ((3, 2), (-1, 4), (1.5, 4)):
        with pytest.raises(ValueError, match="whole numbers"):
            wilson_interval(*bad)


def test_a_rate_counts_successes_and_formats_with_its_interval():
    r = rate([True] * 16 + [False])
    assert (r["k"], r["n"]) == (16, 17) and r["rate"] == pytest.approx(16 / 17)
    assert format_rate(r) == "16/17 [73-99 %]"


def test_mcnemar_counts_only_the_discordant_trials():
    a = [True] * 10 + [True] * 8 + [False] * 1 + [False] * 5
    b = [True] * 10 + [False] * 8 + [True] * 1 + [False] * 5
    test = mcnemar_exact(a, b)
    assert (test["only_a"], test["only_b"]) == (8, 1)
    assert test["p_value"] == pytest.approx(2 * (1 + 9) / 2 ** 9)  # 2 P(X <= 1), X ~ Bin(9, 1/2)
    assert mcnemar_exact([True, False], [True, False])["p_value"] == 1.0
    assert mcnemar_exact([True] * 3, [False] * 3)["p_value"] == pytest.approx(0.25)
    with pytest.raises(ValueError, match="same trials"):
        mcnemar_exact([True], [True, False])


def test_a_neighbourhood_shifts_the_pushes_together_over_more_than_a_step_at_every_speed():
    nb = Neighbourhood()
    large = next(s for s in PUSH_SCENARIOS if s.name == "large_backward")
    trials = nb.trials(large)
    assert len(trials) == len(nb.shifts) * len(nb.speeds) >= 10
    assert max(nb.shifts) - min(nb.shifts) >= 0.5  # a step lasts 0.4-0.5 s at 0.9-1.1 m/s
    speed, first = trials[0]
    assert speed == nb.speeds[0] and first.times == tuple(t + nb.shifts[0] for t in large.times)
    assert any(s.times == large.times and v == 1.0 for v, s in trials)  # the nominal scenario is a trial
    assert all(math.isclose(s.force_x, large.force_x) for _v, s in trials)
    with pytest.raises(ValueError, match="inside"):
        Neighbourhood(shifts=(4.0,)).trials(large)


def test_the_impulse_at_90_percent_is_read_off_the_curve_with_its_interval():
    from rabbit_policy.evaluation.robustness import impulse_at

    impulses = [3.0, 6.0, 9.0, 12.0, 15.0]
    rates = [rate([True] * k + [False] * (40 - k)) for k in (40, 40, 38, 33, 36)]
    at = impulse_at(0.9, impulses, rates)
    assert at["impulse_Ns"] == 9.0  # 38/40 = 0.95 passes, 33/40 does not, later recoveries do not count
    assert at["low_Ns"] == 6.0  # 38/40's lower bound is under 0.9: only 40/40 is surely above it
    assert at["high_Ns"] == 15.0  # 33/40's upper bound (0.91) still allows 90 %, as does 36/40's
    assert impulse_at(0.9, impulses, [rate([False])] * 5)["impulse_Ns"] == 0.0


def test_the_interquartile_mean_is_the_middle_halfs_and_its_bootstrap_interval_repeats():
    """rliable's IQM (scipy's 25 %-trimmed mean where n is a multiple of 4) and a percentile
    bootstrap interval from a fixed seed: the same numbers on every machine."""
    from rabbit_policy.evaluation.statistics import bootstrap_interval, iqm

    assert iqm([4, 1, 3, 2]) == 2.5 and iqm(range(8)) == 3.5 and iqm([7.0]) == 7.0
    assert iqm([1, 2, 3]) == 2.0 and iqm([0, 0, 9]) == 2.25 / 1.5  # quartiles straddle the ends
    low, high = bootstrap_interval([0.2, 0.5, 0.9, 0.4, 0.6], seed=3)
    assert (low, high) == bootstrap_interval([0.2, 0.5, 0.9, 0.4, 0.6], seed=3) and 0.2 <= low < high <= 0.9
    assert bootstrap_interval([0.5, 0.5, 0.5]) == (0.5, 0.5)
    with pytest.raises(ValueError):
        iqm([])
