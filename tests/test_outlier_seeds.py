"""Seeds that ended far below the others (hintsjax/evaluation/outliers.py): the rule on values
worked out by hand, on the issue's collapsed ant seed, on every committed Table 3 row at 20 seeds
(none named), on one, two and equal seeds; and a run's end, which names them in eval.json and in
one printed line."""

from __future__ import annotations

import json
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from hintsjax.evaluation.evaluator import EvalResult, variant_summary
from hintsjax.evaluation.outliers import K, far_below, spread
from hintsjax.settings.layers import run_config
from hintsjax.training.outputs import EVAL_JSON, write_results

ROOT = Path(__file__).resolve().parents[1]
# five ant seeds of one physics=warp command (issue 59)
ISSUE_59 = [1480.0, 984.0, 1027.0, -3006.0, 997.0]


def test_the_issues_collapsed_ant_seed_is_named():
    """Median 997; deviations 483, 13, 30, 4003, 0, so MAD 30 and 1.4826 MAD 44.5, below |median|:
    the spread is 997 and the bar 997 - 3 x 997 = -1994. -3006 is below it; 984 is not."""
    assert spread(ISSUE_59) == (997.0, 997.0)
    assert far_below(ISSUE_59) == [3]
    assert far_below([1480.0, 984.0, 1027.0, -1990.0, 997.0]) == []  # just above the bar


def test_negative_returns_and_a_spread_wider_than_the_median():
    """Pendulum-like returns: median -190, deviations 40, 10, 10, 1110 (MAD 25, 1.4826 MAD 37):
    spread 190, bar -760. Wide seeds: median 100, deviations 100, 100, 0, 50, 900 (MAD 100,
    1.4826 MAD 148.26 above |median|): bar 100 - 444.78 = -344.78."""
    assert far_below([-150.0, -200.0, -180.0, -1300.0]) == [3]
    assert far_below([-150.0, -200.0, -180.0, -750.0]) == []
    assert spread([0.0, 200.0, 100.0, 150.0, -800.0]) == (100.0, pytest.approx(148.26))
    assert far_below([0.0, 200.0, 100.0, 150.0, -344.0]) == [] and far_below(
        [0.0, 200.0, 100.0, 150.0, -345.0]
    ) == [4]


def test_one_two_and_equal_seeds_name_none_but_a_collapse_among_three_does():
    assert far_below([]) == [] and far_below([5.0]) == [] and far_below([-3000.0]) == []
    assert far_below([1000.0, -3000.0]) == []  # of two, neither is "the others"
    assert far_below([7.0] * 4) == [] and far_below([0.0] * 3) == []
    # near-identical: |median| is the spread
    assert far_below([991.0, 993.0, 994.0, 995.0, 996.0, 992.0]) == []
    assert far_below([1000.0, 1000.0, -3000.0]) == [2]  # MAD 0, spread 1000, bar -2000
    # a mean that is not a number is always named
    assert far_below([1000.0, float("nan"), 990.0]) == [1]


def test_no_seed_of_table3_at_20_seeds_is_named():
    """The committed Table 3 rows (locomotion and the car's learners at 20 seeds, the humanoid at
    10, the car's references at 5) name no seed; the largest shortfall, halfcheetah
    hints-fc-max_velocity's -502 against a median of 213, is 1.46 spreads, under half of K."""
    worst = 0.0
    rows = sorted((ROOT / "experiments/results/runs/table3_20").glob("*/*/eval.json"))
    assert len(rows) == 22
    for path in rows:
        for evaluation in json.loads(path.read_text())["evaluations"]:
            means = evaluation["seed_means"]
            assert far_below(means) == [], (path, means)
            median, width = spread(means)
            worst = max(worst, (median - min(means)) / width)
    assert 1.45 < worst < K / 2


def test_a_runs_end_names_the_seed_in_eval_json_and_one_line(tmp_path, capsys):
    cfg = run_config({"env": "pendulum", "seeds": 5, "eval_variants": ["swingto"]})
    returns = np.asarray(ISSUE_59)[:, None] + np.array([[-1.0, 1.0]])  # [S, E]: 2 episodes a seed
    collapsed = variant_summary(cfg, None, False, EvalResult(returns, np.full((5, 2), 1000)))
    fine = variant_summary(
        cfg, "swingto", False, EvalResult(returns[[0, 1, 2, 4, 4]], np.full((5, 2), 1000))
    )
    compiled = SimpleNamespace(
        seconds=1.0, trace_seconds=0.5, loaded=False, layout=SimpleNamespace(count=1)
    )
    training = SimpleNamespace(
        compiled=compiled, seconds=2.0, before=0.0, done=1, first=0, arrivals=()
    )
    write_results(cfg, tmp_path, training, [collapsed, fine], 0.1)
    saved = json.loads((tmp_path / EVAL_JSON).read_text())["evaluations"]
    assert [e["outlier_seeds"] for e in saved] == [[3], []]
    named = [line for line in capsys.readouterr().out.splitlines() if "far below" in line]
    assert named == [
        f"pendulum/swingup {cfg.label}: seed 3 ended far below the others (-3006 against a median "
        f"of 997, more than 3 x 997 short): one episode: python -m hintsjax.video {tmp_path} "
        "--seed 3"
    ]


def test_a_runs_end_says_which_collapsed_seed_had_a_kl_storm(tmp_path, capsys):
    """With a metrics.csv whose seed 3 blew up for 12 updates from update 5 (and seed 0 for 12
    from update 2, but it did not collapse), eval.json keeps every seed's storms and one more line
    names the collapsed seed's; without a KL column there is neither."""
    import csv

    cfg = run_config({"env": "pendulum", "seeds": 5})
    returns = np.asarray(ISSUE_59)[:, None] + np.array([[-1.0, 1.0]])
    collapsed = variant_summary(cfg, None, False, EvalResult(returns, np.full((5, 2), 1000)))
    compiled = SimpleNamespace(
        seconds=1.0, trace_seconds=0.5, loaded=False, layout=SimpleNamespace(count=1)
    )
    training = SimpleNamespace(
        compiled=compiled, seconds=2.0, before=0.0, done=1, first=0, arrivals=()
    )
    with (tmp_path / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["update", "seed", "env_steps", "episode_return", "approx_kl"])
        for update in range(1, 31):
            for seed in range(5):
                hot = (seed == 3 and 5 <= update < 17) or (seed == 0 and 2 <= update < 14)
                writer.writerow([update, seed, 64 * update, 0.0, 0.9 if hot else 0.01])
    write_results(cfg, tmp_path, training, [collapsed], 0.1)
    storms = json.loads((tmp_path / EVAL_JSON).read_text())["kl_storms"]
    assert storms == [
        {"first": 2, "longest": 12},
        *[{"first": None, "longest": 0}] * 2,
        {"first": 5, "longest": 12},
        {"first": None, "longest": 0},
    ]
    lines = capsys.readouterr().out.splitlines()
    assert lines[-1] == (
        f"pendulum/swingup {cfg.label}: KL storm (seed 3 from update 5 on: approx. KL above 0.5 "
        "for 10 or more updates in a row): PPO's steps blew up"
    )
    (tmp_path / "metrics.csv").unlink()
    write_results(cfg, tmp_path, training, [collapsed], 0.1)
    assert json.loads((tmp_path / EVAL_JSON).read_text())["kl_storms"] is None
    assert "KL storm" not in capsys.readouterr().out
