"""The result tables' statistics (hintsjax.reproduce.stats): IQM, stratified percentile bootstrap
intervals, probability of improvement and the text the tables print, checked against hand-worked
values and against scipy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats as sps

from hintsjax.reproduce import stats
from hintsjax.reproduce.stats import Interval


def scipy_iqm(a, axis=-1):
    return sps.trim_mean(a, 0.25, axis=axis)


def pairwise_poi(x, y):
    """P(X > Y) + P(X = Y) / 2 by comparing every pair, the definition itself; batched on leading
    axes."""
    x, y = np.asarray(x)[..., :, None], np.asarray(y)[..., None, :]
    return ((x > y) + 0.5 * (x == y)).mean(axis=(-2, -1))


# --- IQM ---------------------------------------------------------------------------------------


def test_iqm_of_one_to_eight_is_the_mean_of_three_to_six():
    assert stats.iqm(np.arange(1, 9)) == pytest.approx(4.5)
    assert stats.iqm([8, 1, 7, 2, 6, 3, 5, 4]) == pytest.approx(4.5)  # order does not matter


def test_iqm_ignores_the_outer_quartiles():
    # the middle four of eight are 10, 10, 20, 20 whatever the extremes are
    assert stats.iqm([-1e6, -5, 10, 10, 20, 20, 50, 1e9]) == pytest.approx(15.0)


@pytest.mark.parametrize("n", [1, 2, 3, 5, 6, 7, 9, 10, 11, 13, 50])
def test_iqm_matches_scipy_trim_mean_for_any_n(n):
    x = np.random.default_rng(n).standard_cauchy(n)
    assert stats.iqm(x) == pytest.approx(sps.trim_mean(x, 0.25), rel=1e-12, abs=1e-12)


def test_iqm_of_a_2d_array_pools_every_run_of_every_task():
    runs_by_tasks = np.arange(1, 9).reshape(4, 2)
    assert stats.iqm(runs_by_tasks) == pytest.approx(4.5)
    x = np.random.default_rng(0).normal(size=(7, 3))
    assert stats.iqm(x) == pytest.approx(sps.trim_mean(x, 0.25, axis=None))


@pytest.mark.parametrize(
    "bad, problem",
    [
        ([], "empty"),
        (np.zeros((0, 3)), "empty"),
        ([1.0, np.nan, 2.0], "NaN"),
        ([1.0, np.inf], "infinite"),
        (3.0, "1-D or 2-D"),
        (np.zeros((2, 2, 2)), "1-D or 2-D"),
    ],
)
def test_bad_scores_raise_value_error_naming_the_problem(bad, problem):
    with pytest.raises(ValueError, match=problem):
        stats.iqm(bad)
    with pytest.raises(ValueError, match=problem):
        stats.bootstrap_ci(bad)
    with pytest.raises(ValueError, match=problem):
        stats.iqm_cell(bad)


# --- bootstrap ---------------------------------------------------------------------------------


def test_bootstrap_interval_contains_the_point_and_shrinks_as_n_grows():
    rng = np.random.default_rng(1)
    widths = []
    for n in (10, 100, 1000):
        ci = stats.bootstrap_ci(rng.normal(5.0, 2.0, n))
        assert ci.low < ci.point < ci.high
        widths.append(ci.width)
    # the width goes as 1 / sqrt(n): about a third of it per tenfold n
    assert widths[0] > 2 * widths[1] > 4 * widths[2]


def test_bootstrap_point_is_the_statistic_of_the_sample():
    x = np.random.default_rng(2).exponential(size=20)
    assert stats.bootstrap_ci(x).point == stats.iqm(x)
    assert stats.bootstrap_ci(x, np.median).point == np.median(x)


def test_same_seed_gives_the_same_interval_and_another_seed_another():
    x = np.random.default_rng(3).normal(size=15)
    assert stats.bootstrap_ci(x, seed=7) == stats.bootstrap_ci(x, seed=7)
    assert stats.bootstrap_ci(x, seed=7) != stats.bootstrap_ci(x, seed=8)
    assert stats.poi_ci(x, x + 0.3, seed=7) == stats.poi_ci(x, x + 0.3, seed=7)


def test_a_constant_sample_and_a_single_seed_give_a_zero_width_interval():
    ci = stats.bootstrap_ci([0.1, 0.1, 0.1, 0.1, 0.1])
    # the mean of five 0.1s is not quite 0.1
    assert ci.low == ci.point == ci.high == pytest.approx(0.1)
    assert stats.bootstrap_ci([3.25]) == Interval(3.25, 3.25, 3.25)
    single_run = np.array([[1.0, 2.0, 3.0]])  # one seed of three tasks
    assert stats.bootstrap_ci(single_run) == Interval(2.0, 2.0, 2.0)
    assert stats.poi_ci([2.0], [1.0]) == Interval(1.0, 1.0, 1.0)


def test_the_fast_iqm_path_equals_calling_the_statistic_on_each_resample():
    x = np.random.default_rng(4).normal(size=(9, 3))
    assert stats.bootstrap_ci(x, stats.iqm, seed=5) == stats.bootstrap_ci(
        x, lambda s: stats.iqm(s), seed=5
    )
    assert stats.bootstrap_ci(x[:, 0], stats.iqm, seed=5) == stats.bootstrap_ci(
        x[:, 0], lambda s: stats.iqm(s), seed=5
    )


def test_stratified_bootstrap_resamples_seeds_within_each_task_and_independently_across_tasks():
    n = 12
    # value = 100 * task + seed index, so a resampled value names both its column and its seed
    scores = np.stack([np.arange(n) + 100.0 * t for t in range(3)], axis=1)
    seen = []

    def record(sample):
        seen.append(sample)
        return float(sample.mean())

    ci = stats.bootstrap_ci(scores, record, resamples=200, seed=0)
    resamples = np.stack(seen[:-1])  # the last call is the statistic of the original sample
    np.testing.assert_array_equal(seen[-1], scores)
    assert resamples.shape == (200, n, 3)
    for t in range(3):
        column = resamples[:, :, t]
        # never leaves its column
        assert column.min() >= 100 * t and column.max() <= 100 * t + n - 1
        means = column.mean(axis=1)
        assert (means >= 100 * t).all() and (means <= 100 * t + n - 1).all()
    seed_indices = resamples - 100.0 * np.arange(3)
    assert len(np.unique(seed_indices[:, :, 0])) == n  # every seed turns up in some resample
    # tasks draw their own seeds
    assert (seed_indices[:, :, 0] != seed_indices[:, :, 1]).any(axis=1).all()
    assert ci.low < ci.point < ci.high


def test_one_dimensional_bootstrap_resamples_with_replacement():
    seen = []
    stats.bootstrap_ci(np.arange(10.0), lambda s: seen.append(s) or 0.0, resamples=100)
    resamples = np.stack(seen[:-1])
    assert resamples.shape == (100, 10)
    assert any(len(np.unique(r)) < 10 for r in resamples)  # some seed drawn twice


@pytest.mark.parametrize("shape", [(40,), (8, 4)])
def test_bootstrap_interval_agrees_with_scipy_percentile_bootstrap(shape):
    x = np.random.default_rng(6).normal(size=shape)
    ci = stats.bootstrap_ci(x, resamples=4000, seed=0)
    if x.ndim == 1:
        res = sps.bootstrap(
            (x,),
            scipy_iqm,
            n_resamples=4000,
            method="percentile",
            vectorized=True,
            rng=np.random.default_rng(123),
        )
    else:
        # scipy resamples each of several samples on its own, which is the stratified bootstrap
        # when each sample is one task's column
        res = sps.bootstrap(
            tuple(x.T),
            lambda *cols, axis: scipy_iqm(np.concatenate(cols, axis=-1)),
            n_resamples=4000,
            method="percentile",
            vectorized=True,
            rng=np.random.default_rng(123),
        )
    low, high = res.confidence_interval
    assert ci.low == pytest.approx(low, abs=0.1 * ci.width)
    assert ci.high == pytest.approx(high, abs=0.1 * ci.width)


def test_bootstrap_interval_covers_the_true_iqm_about_as_often_as_its_level():
    # the IQM of N(0, 1) is 0 by symmetry
    rng = np.random.default_rng(7)
    trials = 200
    hits = 0
    for i in range(trials):
        ci = stats.bootstrap_ci(rng.normal(size=40), resamples=500, seed=i)
        hits += ci.low <= 0.0 <= ci.high
    # percentile intervals run a little narrow at small n; a 90% or 99% interval would land outside
    assert 0.88 <= hits / trials <= 0.98


@pytest.mark.parametrize(
    "kwargs, problem",
    [
        (dict(level=0.0), "level"),
        (dict(level=95), "level"),
        (dict(resamples=0), "resamples"),
        (dict(resamples=2.5), "resamples"),
    ],
)
def test_bad_bootstrap_arguments_raise(kwargs, problem):
    with pytest.raises(ValueError, match=problem):
        stats.bootstrap_ci([1.0, 2.0], **kwargs)
    with pytest.raises(ValueError, match=problem):
        stats.poi_ci([1.0, 2.0], [0.0], **kwargs)


# --- probability of improvement --------------------------------------------------------------


@pytest.mark.parametrize(
    "x, y, expected",
    [
        ([3, 4], [1, 2], 1.0),  # every pair a win
        ([1, 2], [3, 4], 0.0),  # every pair a loss
        # pairs: 1v1 tie, 1v2 loss, 2v1 win, 2v2 tie -> (0.5 + 0 + 1 + 0.5) / 4
        ([1, 2], [1, 2], 0.5),
        ([1, 3], [2, 2], 0.5),  # 1 loses twice, 3 wins twice -> 2 / 4
        ([2, 2], [2, 2], 0.5),  # all ties
        ([1, 2, 3], [2], 0.5),  # loss, tie, win -> 1.5 / 3
        # 5v5 tie, 5v0 win, twice; 1v5 loss, 1v0 win -> (0.5+1)*2 + 1 = 4 of 6
        ([5, 5, 1], [5, 0], 4 / 6),
    ],
)
def test_probability_of_improvement_by_hand(x, y, expected):
    assert stats.probability_of_improvement(x, y) == pytest.approx(expected)
    # and P(Y > X) = 1 - P(X > Y), ties splitting evenly
    assert stats.probability_of_improvement(y, x) == pytest.approx(1.0 - expected)


def test_probability_of_improvement_matches_pairwise_counting_and_mann_whitney():
    rng = np.random.default_rng(8)
    for n, m in [(5, 5), (7, 3), (1, 9), (20, 11)]:
        # plenty of ties
        x, y = rng.integers(0, 6, n).astype(float), rng.integers(0, 6, m).astype(float)
        p = stats.probability_of_improvement(x, y)
        assert p == pytest.approx(pairwise_poi(x, y))
        assert p == pytest.approx(sps.mannwhitneyu(x, y).statistic / (n * m))


def test_probability_of_improvement_rejects_bad_input():
    with pytest.raises(ValueError, match="x are empty"):
        stats.probability_of_improvement([], [1.0])
    with pytest.raises(ValueError, match="y contain NaN"):
        stats.poi_ci([1.0], [np.nan])
    with pytest.raises(ValueError, match="1-D"):
        stats.probability_of_improvement(np.ones((2, 2)), [1.0])


def test_poi_interval_resamples_each_agent_on_its_own_and_agrees_with_scipy():
    rng = np.random.default_rng(9)
    x, y = rng.normal(0.5, 1.0, 10), rng.normal(0.0, 1.0, 14)
    ci = stats.poi_ci(x, y, resamples=4000)
    assert ci.point == pytest.approx(pairwise_poi(x, y))
    assert 0.0 <= ci.low < ci.point < ci.high <= 1.0
    res = sps.bootstrap(
        (x, y),
        lambda a, b, axis: pairwise_poi(a, b),
        n_resamples=4000,
        method="percentile",
        vectorized=True,
        rng=np.random.default_rng(123),
    )
    low, high = res.confidence_interval
    assert ci.low == pytest.approx(low, abs=0.1 * ci.width)
    assert ci.high == pytest.approx(high, abs=0.1 * ci.width)


def test_difference_interval_agrees_with_scipy_and_is_exact_for_constant_samples():
    """mean(X) - mean(Y) with each agent's seeds resampled on its own: scipy's two-sample
    percentile bootstrap gives about the same interval; constants give a zero-width one."""
    rng = np.random.default_rng(13)
    x, y = rng.normal(0.3, 0.2, 10), rng.normal(0.1, 0.1, 12)
    ci = stats.difference_ci(x, y, resamples=4000)
    assert ci.point == pytest.approx(x.mean() - y.mean())
    assert ci.low < ci.point < ci.high
    res = sps.bootstrap(
        (x, y),
        lambda a, b, axis: a.mean(axis) - b.mean(axis),
        n_resamples=4000,
        method="percentile",
        vectorized=True,
        rng=np.random.default_rng(5),
    )
    low, high = res.confidence_interval
    assert ci.low == pytest.approx(low, abs=0.1 * ci.width)
    assert ci.high == pytest.approx(high, abs=0.1 * ci.width)
    assert stats.difference_ci([0.78] * 5, [0.46] * 5) == Interval(
        pytest.approx(0.32), pytest.approx(0.32), pytest.approx(0.32)
    )
    with pytest.raises(ValueError, match="1-D"):
        stats.difference_ci(np.ones((2, 2)), [1.0])


def test_an_agent_against_itself_is_undecided_with_a_real_interval():
    x = np.random.default_rng(12).normal(size=10)
    ci = stats.poi_ci(x, x)
    assert ci.point == 0.5
    # resampling both sides with one set of indices would compare each resample with itself: always
    # 0.5
    assert ci.low < 0.4 and ci.high > 0.6
    assert not stats.decided(ci)


def test_poi_interval_of_separated_agents_is_decided_and_of_equal_agents_is_not():
    rng = np.random.default_rng(10)
    better, worse = rng.normal(10.0, 1.0, 10), rng.normal(0.0, 1.0, 10)
    assert stats.poi_ci(better, worse) == Interval(1.0, 1.0, 1.0)  # every resampled pair a win
    same = stats.poi_ci(rng.normal(size=10), rng.normal(size=10))
    assert not stats.decided(same) and stats.direction(same) == 0


# --- decided and the table text ----------------------------------------------------------------


@pytest.mark.parametrize(
    "interval, direction",
    [
        (Interval(0.92, 0.78, 1.00), 1),
        (Interval(0.10, 0.00, 0.30), -1),
        (Interval(0.60, 0.40, 0.80), 0),
        (Interval(0.70, 0.50, 0.90), 0),  # touching 0.5 does not exclude it
        (Interval(0.30, 0.10, 0.50), 0),
        (Interval(0.50, 0.50, 0.50), 0),
        (Interval(0.51, 0.501, 0.52), 1),
    ],
)
def test_decided_when_the_interval_excludes_one_half(interval, direction):
    assert stats.direction(interval) == direction
    assert stats.decided(interval) == (direction != 0)


@pytest.mark.parametrize(
    "interval, decided",
    [
        (Interval(-33.0, -57.0, -8.0), True),
        (Interval(2.0, 0.1, 4.0), True),
        (Interval(0.2, -0.1, 0.3), False),  # inside [0, 0.5]: a POI test would call it decided
        (Interval(1.0, 0.0, 2.0), False),  # touching 0 does not exclude it
    ],
)
def test_a_difference_is_decided_when_its_interval_excludes_zero(interval, decided):
    assert stats.difference_decided(interval) == decided


def test_ordering_text():
    assert (
        stats.ordering_text("composite", "ppo_rgb", Interval(0.92, 0.78, 1.0))
        == "P(composite > ppo_rgb) = 0.92 [0.78, 1.00]: decided"
    )
    assert (
        stats.ordering_text("a", "b", Interval(0.55, 0.3, 0.8))
        == "P(a > b) = 0.55 [0.30, 0.80]: undecided"
    )
    assert (
        stats.ordering_text("a", "b", Interval(0.05, 0.0, 0.2))
        == "P(a > b) = 0.05 [0.00, 0.20]: decided"
    )


def test_iqm_cell():
    assert stats.iqm_cell([7.0, 7.0, 7.0]) == "7.0 [7.0, 7.0]"
    assert stats.iqm_cell([-0.01]) == "0.0 [0.0, 0.0]"  # no "-0.0"
    assert stats.iqm_cell([1234.56], digits=0) == "1235 [1235, 1235]"
    x = np.random.default_rng(11).normal(400.0, 20.0, 10)
    ci = stats.bootstrap_ci(x)
    assert stats.iqm_cell(x) == f"{ci.point:.1f} [{ci.low:.1f}, {ci.high:.1f}]"
    assert stats.iqm_cell(x, seed=1) != stats.iqm_cell(x)
