"""The confidence intervals of `compare`, against values computed by hand."""

import pytest

from stack.runs.statistics import mean_interval, paired_difference, rate_interval


def test_t_interval_of_a_mean():
    interval = mean_interval([1.0, 2.0, 3.0, 4.0])
    half = 3.182446305284263 * 1.2909944487358056 / 2  # t(0.975, 3) * s / sqrt(n)
    assert interval.value == 2.5
    assert (interval.low, interval.high) == pytest.approx((2.5 - half, 2.5 + half))
    assert mean_interval([7.0]).as_list() == [7.0, 7.0, 7.0]


def test_wilson_interval_stays_in_zero_one_and_is_not_empty_at_zero():
    none = rate_interval(0, 10)
    assert none.value == 0.0 and none.low == 0.0
    assert none.high == pytest.approx(0.2775, abs=1e-4)
    half = rate_interval(5, 10)
    assert (half.low, half.high) == pytest.approx((0.2366, 0.7634), abs=1e-4)
    assert rate_interval(10, 10).high == pytest.approx(1.0) and rate_interval(10, 10).low < 1.0
    for trials in range(1, 1001):
        none, every = rate_interval(0, trials), rate_interval(trials, trials)
        assert none.low == 0.0 and every.high == 1.0, "the rate lies inside its interval, to the last bit"


def test_a_mean_interval_can_be_cut_at_the_metrics_floor():
    counts = [0, 0, 0, 0, 9]
    assert mean_interval(counts).low < 0 and mean_interval(counts, floor=0.0).low == 0.0
    assert mean_interval(counts, floor=0.0).high == mean_interval(counts).high


def test_paired_difference_removes_the_shared_spread():
    baseline = [20.0, 25.0, 30.0, 22.0]
    agent = [21.0, 26.1, 30.9, 23.0]
    difference = paired_difference(agent, baseline)
    assert difference.value == pytest.approx(1.0)
    assert difference.high - difference.low < 0.3, "pairing removes the seed-to-seed spread"
    with pytest.raises(ValueError, match="same episodes"):
        paired_difference([1.0], [1.0, 2.0])
