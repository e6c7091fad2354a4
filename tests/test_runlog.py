"""Learning-curve statistics: the bootstrap confidence band of the mean over seeds; the metrics
file of a resumed run."""

from __future__ import annotations

import csv

import numpy as np

from hintsjax.training.runlog import METRICS_CSV, RunLog, bin_means, mean_confidence_band


def test_a_resumed_run_gains_the_columns_of_metrics_added_since_it_began(tmp_path):
    """A run begun before a metric existed resumes: the metric gets a column, NaN in earlier rows,
    and rows after the checkpoint resumed from are dropped."""
    log = RunLog(tmp_path)
    log.write(
        {"env_steps": np.array([[8.0, 16.0, 24.0]]), "episode_return": np.array([[1.0, 2.0, 3.0]])},
        0,
    )
    log.close()
    log = RunLog(tmp_path, resume_update=2)  # the checkpoint was at update 2: update 3 is dropped
    log.write(
        {
            "env_steps": np.array([[24.0]]),
            "episode_return": np.array([[5.0]]),
            "step_reward": np.array([[0.5]]),
        },
        2,
    )
    log.close()
    with (tmp_path / METRICS_CSV).open() as f:
        rows = list(csv.DictReader(f))
    assert list(rows[0]) == ["update", "seed", "env_steps", "episode_return", "step_reward"]
    assert [(r["update"], r["episode_return"], r["step_reward"]) for r in rows] == [
        ("1", "1.0", "nan"),
        ("2", "2.0", "nan"),
        ("3", "5.0", "0.5"),
    ]


def test_band_brackets_the_mean_and_shrinks_with_agreement():
    rng = np.random.default_rng(0)
    spread = rng.normal(0.0, 10.0, (5, 40))
    mean, low, high = mean_confidence_band(spread)
    np.testing.assert_allclose(mean, spread.mean(0))
    assert np.all(low <= mean) and np.all(mean <= high)
    # Seeds that agree give a zero-width band; a band never exceeds the seeds' own range.
    same = np.tile(np.arange(40.0), (5, 1))
    _, low_same, high_same = mean_confidence_band(same)
    np.testing.assert_allclose(low_same, same[0])
    np.testing.assert_allclose(high_same, same[0])
    assert np.all(low >= spread.min(0)) and np.all(high <= spread.max(0))
    # For 5 normal seeds the 95% band of the mean is about +-2 sigma/sqrt(5) wide on each side.
    width = np.median(high - low)
    assert 0.5 * 2 * 1.96 * 10 / np.sqrt(5) < width < 1.5 * 2 * 1.96 * 10 / np.sqrt(5)


def test_nan_seeds_are_ignored():
    values = np.array([[np.nan, 1.0, 2.0], [np.nan, 3.0, np.nan]])
    mean, low, high = mean_confidence_band(values)
    assert np.isnan(mean[0]) and mean[1] == 2.0 and mean[2] == 2.0
    assert low[1] >= 1.0 and high[1] <= 3.0


def test_bin_means_average_runs_of_updates_and_skip_nans():
    steps = np.arange(1.0, 8.0) * 10  # 7 updates
    values = np.array(
        [[np.nan, np.nan, 1.0, 3.0, 5.0, np.nan, 7.0], [0.0, 2.0, 4.0, 6.0, 8.0, 10.0, 12.0]]
    )
    # edges 0, 2, 5, 7 (linspace 0, 2.33, 4.67, 7 rounded)
    x, y = bin_means(steps, values, points=3)
    np.testing.assert_array_equal(x, [20.0, 50.0, 70.0])  # each bin's last update
    np.testing.assert_allclose(y, [[np.nan, 3.0, 7.0], [1.0, 6.0, 11.0]])
    same_x, same_y = bin_means(steps, values, points=7)  # as many points as updates: unchanged
    np.testing.assert_array_equal(same_x, steps)
    np.testing.assert_array_equal(same_y, values)
