"""Statistics for the result tables, after Agarwal et al. (2021), "Deep RL at the edge of the
statistical precipice" (the method the rliable library implements).

A table cell reports the interquartile mean (IQM) of the per-seed scores with a 95% percentile
bootstrap confidence interval; comparisons between two agents report the probability of
improvement P(X > Y) with its own bootstrap interval, and call the ordering "decided" only when
that interval excludes 0.5.

Scores are [seeds] or [seeds, tasks]. With tasks, the IQM pools every run of every task (as
rliable's aggregate IQM does, so tasks should be normalised to a common scale first) and the
bootstrap is stratified: seeds are resampled independently within each task, because the
seeds of different tasks are separate runs, not one run measured on several tasks.

numpy and scipy only, so the tables can be built without extra dependencies.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.stats import rankdata

LEVEL = 0.95
RESAMPLES = 2000


@dataclass(frozen=True)
class Interval:
    """A point estimate with a confidence interval [low, high] (floats)."""

    point: float
    low: float
    high: float

    @property
    def width(self) -> float:
        return self.high - self.low


def _scores(scores, name: str = "scores", ndims: tuple[int, ...] = (1, 2)) -> np.ndarray:
    """array-like -> float64 array of ndim in `ndims`, non-empty and finite (else ValueError)."""
    a = np.asarray(scores, dtype=np.float64)
    if a.ndim not in ndims:
        want = " or ".join(f"{d}-D" for d in ndims)
        raise ValueError(f"{name} must be {want}, got shape {a.shape}")
    if a.size == 0:
        raise ValueError(f"{name} are empty (shape {a.shape})")
    if np.isnan(a).any():
        raise ValueError(f"{name} contain NaN")
    if not np.isfinite(a).all():
        # an infinite return is a logging bug, and it would make the IQM or its interval infinite
        raise ValueError(f"{name} contain an infinite value")
    return a


def _check_bootstrap_args(level: float, resamples: int) -> None:
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie strictly between 0 and 1, got {level}")
    if int(resamples) != resamples or resamples < 1:
        raise ValueError(f"resamples must be a positive integer, got {resamples}")


def _iqm_rows(rows: np.ndarray) -> np.ndarray:
    """[batch, n] -> [batch]: the IQM of each row."""
    n = rows.shape[-1]
    # the same cut as scipy.stats.trim_mean(x, 0.25): int(0.25 n) values off each end, so for
    # n < 4 nothing is cut and the IQM is the mean
    cut = int(0.25 * n)
    return np.sort(rows, axis=-1)[:, cut : n - cut].mean(axis=-1)


def iqm(scores) -> float:
    """[seeds] or [seeds, tasks] -> float: the mean of the middle 50% of all the scores."""
    a = _scores(scores)
    return float(_iqm_rows(a.reshape(1, -1))[0])


def _resample(a: np.ndarray, rng: np.random.Generator, resamples: int) -> np.ndarray:
    """[seeds] -> [resamples, seeds]; [seeds, tasks] -> [resamples, seeds, tasks], each task on its
    own."""
    n = a.shape[0]
    if a.ndim == 1:
        return a[rng.integers(0, n, size=(resamples, n))]
    tasks = a.shape[1]
    # a separate draw of seed indices per task column (rliable's StratifiedBootstrap)
    idx = rng.integers(0, n, size=(resamples, n, tasks))
    return a[idx, np.arange(tasks)]


def _percentile_interval(point: float, stats: np.ndarray, level: float) -> Interval:
    low, high = np.quantile(stats, [(1.0 - level) / 2.0, (1.0 + level) / 2.0])
    return Interval(point=float(point), low=float(low), high=float(high))


def bootstrap_ci(
    scores,
    statistic: Callable[[np.ndarray], float] = iqm,
    level: float = LEVEL,
    resamples: int = RESAMPLES,
    seed: int = 0,
) -> Interval:
    """[seeds] or [seeds, tasks] -> Interval: percentile bootstrap CI of statistic(scores), seeds
    resampled per task."""
    a = _scores(scores)
    _check_bootstrap_args(level, resamples)
    rng = np.random.default_rng(seed)
    samples = _resample(a, rng, int(resamples))
    if statistic is iqm:
        # one sort over the whole batch instead of `resamples` Python calls
        stats = _iqm_rows(samples.reshape(samples.shape[0], -1))
    else:
        stats = np.array([float(statistic(s)) for s in samples])
    return _percentile_interval(statistic(a), stats, level)


def _poi_rows(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """[batch, n], [batch, m] -> [batch]: P(X > Y) + P(X = Y) / 2 for each row pair."""
    n, m = x.shape[-1], y.shape[-1]
    # Mann-Whitney U from rank sums: average ranks give a tie between x and y exactly half a win,
    # and it costs a sort of n + m values rather than n * m comparisons
    ranks = rankdata(np.concatenate([x, y], axis=-1), method="average", axis=-1)
    u = ranks[:, :n].sum(axis=-1) - n * (n + 1) / 2.0
    return u / (n * m)


def probability_of_improvement(x, y) -> float:
    """[n], [m] -> float: P(X > Y) with ties counted 1/2, over all n * m pairs of seeds."""
    a = _scores(x, "x", ndims=(1,))
    b = _scores(y, "y", ndims=(1,))
    return float(_poi_rows(a[None], b[None])[0])


def _two_agent_resamples(x, y, level: float, resamples: int, seed: int):
    """[n], [m] -> (x, y, [resamples, n], [resamples, m]) as checked float arrays and their
    bootstrap resamples. The two agents' seeds are independent runs, so each is resampled on its own
    (stratified by agent), x's draws first from one generator seeded with `seed`."""
    a = _scores(x, "x", ndims=(1,))
    b = _scores(y, "y", ndims=(1,))
    _check_bootstrap_args(level, resamples)
    rng = np.random.default_rng(seed)
    return a, b, _resample(a, rng, int(resamples)), _resample(b, rng, int(resamples))


def poi_ci(x, y, level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0) -> Interval:
    """[n], [m] -> Interval: percentile bootstrap CI of P(X > Y), x and y resampled
    independently."""
    a, b, xs, ys = _two_agent_resamples(x, y, level, resamples, seed)
    return _percentile_interval(probability_of_improvement(a, b), _poi_rows(xs, ys), level)


def difference_ci(
    x, y, level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0
) -> Interval:
    """[n], [m] -> Interval: percentile bootstrap CI of mean(X) - mean(Y), x and y resampled
    independently (a difference in the units of the scores, e.g. the car's hairpin progress)."""
    a, b, xs, ys = _two_agent_resamples(x, y, level, resamples, seed)
    return _percentile_interval(a.mean() - b.mean(), xs.mean(axis=-1) - ys.mean(axis=-1), level)


def direction(interval: Interval) -> int:
    """Interval of P(X > Y) -> +1 if it lies wholly above 0.5 (X better), -1 if wholly below, else
    0."""
    # strict: an interval that touches 0.5 does not exclude it
    if interval.low > 0.5:
        return 1
    if interval.high < 0.5:
        return -1
    return 0


def decided(interval: Interval) -> bool:
    """Interval of P(X > Y) -> whether it excludes 0.5, i.e. the ordering of X and Y is settled."""
    return direction(interval) != 0


def difference_decided(interval: Interval) -> bool:
    """Interval of mean(X) - mean(Y) (`difference_ci`) -> whether it excludes 0 (strictly)."""
    return interval.low > 0 or interval.high < 0


def _fmt(value: float, digits: int) -> str:
    # + 0.0 turns the -0.0 that rounding a small negative gives into 0.0
    return f"{round(value, digits) + 0.0:.{digits}f}"


def ordering_text(name_x: str, name_y: str, interval: Interval, digits: int = 2) -> str:
    """Interval of P(X > Y) -> 'P(x > y) = 0.92 [0.78, 1.00]: decided' (or ': undecided')."""
    verdict = "decided" if decided(interval) else "undecided"
    return (
        f"P({name_x} > {name_y}) = {_fmt(interval.point, digits)} "
        f"[{_fmt(interval.low, digits)}, {_fmt(interval.high, digits)}]: {verdict}"
    )


def iqm_cell(
    scores, digits: int = 1, level: float = LEVEL, resamples: int = RESAMPLES, seed: int = 0
) -> str:
    """[seeds] or [seeds, tasks] -> 'IQM [low, high]' table cell, e.g. '412.3 [398.1, 430.0]'."""
    ci = bootstrap_ci(scores, iqm, level=level, resamples=resamples, seed=seed)
    return f"{_fmt(ci.point, digits)} [{_fmt(ci.low, digits)}, {_fmt(ci.high, digits)}]"
