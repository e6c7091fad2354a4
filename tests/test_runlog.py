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


def logged(tmp_path, updates: int, seeds: int = 2) -> None:
    log = RunLog(tmp_path)
    steps = np.tile(np.arange(1, updates + 1, dtype=np.float64) * 8, (seeds, 1))
    log.write({"env_steps": steps, "episode_return": steps / 8}, 0)
    log.close()


def rows_of(tmp_path) -> list[tuple[str, str]]:
    with (tmp_path / METRICS_CSV).open() as f:
        return [(r["update"], r["seed"]) for r in csv.DictReader(f)]


def test_a_resumed_log_drops_a_row_cut_off_mid_write_and_names_the_updates_it_lacks(
    tmp_path, capsys
):
    """A stop while a chunk's rows were appended leaves a row cut short: a resume drops it (it
    read as a value-less row, and ended the run in a ValueError once trained), says in one line
    which updates now lack a row, and logs on after them."""
    logged(tmp_path, 4)
    text = (tmp_path / METRICS_CSV).read_text()
    (tmp_path / METRICS_CSV).write_text(text[: text.rindex("\n", 0, -1) + 6])  # update 4, seed 1
    log = RunLog(tmp_path, resume_update=4)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "lacks the rows of updates 4 " in err[0], err
    log.write({"env_steps": np.full((2, 1), 40.0), "episode_return": np.full((2, 1), 5.0)}, 4)
    log.close()
    expected = [(str(u), str(s)) for u in range(1, 4) for s in (0, 1)] + [("4", "0")]
    assert rows_of(tmp_path) == expected + [("5", "0"), ("5", "1")]


def test_an_empty_or_header_only_log_resumes_saying_which_updates_it_lacks(tmp_path, capsys):
    """An empty metrics.csv (a stop as it was first written) starts anew, header and all; one
    whose rows are gone names the updates the checkpoint holds that it lacks, once."""
    (tmp_path / METRICS_CSV).write_text("")
    RunLog(tmp_path, resume_update=0).close()
    assert capsys.readouterr().err == "" and not (tmp_path / METRICS_CSV).exists()
    logged(tmp_path, 3)
    header = (tmp_path / METRICS_CSV).read_text().splitlines()[0]
    (tmp_path / METRICS_CSV).write_text(header + "\n")
    log = RunLog(tmp_path, resume_update=32)
    assert "lacks the rows of updates 1-32 " in capsys.readouterr().err
    log.write({"env_steps": np.full((2, 1), 8.0), "episode_return": np.full((2, 1), 1.0)}, 32)
    log.close()
    assert rows_of(tmp_path) == [("33", "0"), ("33", "1")]
    (tmp_path / METRICS_CSV).write_text("")
    RunLog(tmp_path, resume_update=2).close()
    assert "lacks the rows of updates 1-2 " in capsys.readouterr().err


def test_a_seconds_file_that_cannot_be_read_counts_from_zero_in_one_line(tmp_path, capsys):
    from hintsjax.training.loop import SECONDS_JSON, seconds_trained

    assert seconds_trained(tmp_path) == 0.0 and capsys.readouterr().err == ""
    (tmp_path / SECONDS_JSON).write_text('{"update": 2, "seconds": 12.5}')
    assert seconds_trained(tmp_path) == 12.5
    for damaged in ("", "{}", '{"seconds": "soon"}', '{"seconds": -1}', "[1, 2]"):
        (tmp_path / SECONDS_JSON).write_text(damaged)
        assert seconds_trained(tmp_path) == 0.0, damaged
        err = capsys.readouterr().err.strip().splitlines()
        assert len(err) == 1 and err[0].startswith(f"warning: {tmp_path / SECONDS_JSON} "), err


def test_a_file_written_whole_keeps_what_was_there_when_its_write_stops(tmp_path):
    """paths.write_whole: a write stopped midway (Ctrl-C, a full disk) leaves the old file and no
    part of the new one."""
    import pytest

    from hintsjax.system import paths

    path = tmp_path / "eval.json"
    paths.write_text_whole(path, '{"old": 1}')

    def stopped(part):
        part.write_text('{"new": ')
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        paths.write_whole(path, stopped)
    assert path.read_text() == '{"old": 1}' and [p.name for p in tmp_path.iterdir()] == [path.name]


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
