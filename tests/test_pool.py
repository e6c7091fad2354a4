"""A row trained in parts of its seeds, pooled (hintsjax/reproduce/pool.py, a table script's
--pool): the parts, each archived and pooled, give what archiving the whole row gives, every file
and every report cell; parts that cannot be one row are one line naming why, exit 2."""

from __future__ import annotations

import csv
import importlib
import json
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml

from hintsjax.evaluation.evaluator import EvalResult, summarize
from hintsjax.reproduce import archive, report
from hintsjax.settings import layers
from hintsjax.training import runlog
from hintsjax.training.runlog import KL_ABOVE, STORM_UPDATES

SEEDS, UPDATES, EPISODES = 6, 300, 8
RUN = "car_racing/ppo_rgb"


def row(rng) -> dict:
    """One row's seeds: evaluation episodes on two variants (return, length, progress), and each
    update's training return (NaN where no episode ended) and approx. KL, seed 5 with a KL storm."""
    kl = rng.uniform(0.0, 0.02, (SEEDS, UPDATES))
    kl[5, 100 : 100 + 2 * STORM_UPDATES] = 10 * KL_ABOVE
    returns = np.where(
        rng.uniform(size=(SEEDS, UPDATES)) < 0.3,
        np.nan,
        rng.normal(100.0, 30.0, (SEEDS, UPDATES)) + np.arange(SEEDS)[:, None] * 50,
    )
    returns[:, :5] = np.nan
    episodes = [
        EvalResult(
            rng.normal(500, 150, (SEEDS, EPISODES)) - 2000 * (np.arange(SEEDS) == 2)[:, None],
            rng.integers(100, 1000, (SEEDS, EPISODES)),
            {"progress": rng.uniform(0, 1, (SEEDS, EPISODES))},
        )
        for _ in range(2)
    ]
    return {"kl": kl, "returns": returns, "episodes": episodes}


def write_run(
    runs: Path, data: dict, seed: int, seeds: int, wall: float, device: str = "NVIDIA H200"
) -> None:
    """A finished run folder of seeds seed..seed+seeds-1 of `data`, as a sweep leaves it."""
    folder = runs / RUN
    folder.mkdir(parents=True)
    part = slice(seed, seed + seeds)
    cfg = layers.run_config({"env": "car_racing", "agent": "ppo_rgb", "seed": seed, "seeds": seeds})
    layers.save_run_config(folder, cfg)
    evaluations = [
        {
            "variant": variant,
            "stochastic": True,
            **summarize(
                EvalResult(
                    e.episode_return[part],
                    e.episode_length[part],
                    {k: v[part] for k, v in e.metrics.items()},
                )
            ),
        }
        for variant, e in zip(("standard", "hairpin"), data["episodes"])
    ]
    with (folder / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["update", "seed", "env_steps", "episode_return", "approx_kl"])
        writer.writerows(
            [u + 1, s, 1024 * (u + 1), data["returns"][seed + s, u], data["kl"][seed + s, u]]
            for u in range(UPDATES)
            for s in range(seeds)
        )
    # with each seed's KL storms, as training.outputs writes them
    (folder / "eval.json").write_text(
        json.dumps(
            {
                "label": "ppo_rgb",
                "env": "car_racing",
                "train_seconds": wall - 20,
                "wall_seconds": wall,
                "device": device,
                "train_env_steps_per_s": 1e6 / wall,
                "env_steps": 1024 * UPDATES,
                "deterministic": True,
                "evaluations": evaluations,
                "kl_storms": runlog.kl_storms(folder / "metrics.csv"),
                # trained in a group
                "group": ["ppo_rgb"],
                "group_dir": f"{runs.name}/car_racing/_groups/0a",
                "group_env_steps_per_s": 2e6 / wall,
            }
        )
    )
    (runs / "sweeps.jsonl").write_text(
        json.dumps(
            {"table": "3-car", "seconds": wall, "finished": f"2026-11-29 0{seed % 10}:00:00"}
        )
        + "\n"
    )


@pytest.fixture
def parts(tmp_path, monkeypatch):
    """The whole row (seeds 0-5) in runs/whole, and the same seeds in two parts: seeds 0-3 in
    runs/part0 and 4-5 (`--set seed=4`) in runs/part4; the archive in tmp_path/archive."""
    monkeypatch.setattr(archive, "ARCHIVE", tmp_path / "archive")
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")  # table_main sets it; restored after the test
    data = row(np.random.default_rng(0))
    runs = tmp_path / "runs"
    write_run(runs / "whole", data, 0, SEEDS, 500.0)
    write_run(runs / "part0", data, 0, 4, 300.0)
    write_run(runs / "part4", data, 4, 2, 200.0, device="NVIDIA H100")
    return runs


def pool_command(argv: list[str]) -> None:
    """car_racing.py's command line (a table script's table_main) with `argv`."""
    module = importlib.import_module("car_racing")
    old = sys.argv
    sys.argv = ["car_racing.py", *argv]
    try:
        module.main()
    finally:
        sys.argv = old


def test_parts_pool_into_what_archiving_the_whole_row_gives(parts, capsys):
    archive.archive_runs(parts / "whole", [RUN])
    # any order
    pool_command(
        ["--pool", f"{parts / 'part4'},{parts / 'part0'}", "--runs", str(parts / "pooled")]
    )
    assert capsys.readouterr().out.startswith(
        f"pooled 1 run(s) finished in every part of {parts / 'part4'}"
    )
    whole, pooled = (archive.ARCHIVE / name / RUN for name in ("whole", "pooled"))
    # the binned curves, seeds 0-5
    assert (pooled / "metrics.csv").read_text() == (whole / "metrics.csv").read_text()
    assert yaml.safe_load((pooled / "config.yaml").read_text()) == yaml.safe_load(
        (whole / "config.yaml").read_text()
    )
    kept, want = (json.loads((f / "summary.json").read_text()) for f in (pooled, whole))
    assert kept["kl_storms"] == want["kl_storms"] and kept["kl_storms"][5]["first"] == 101
    np.testing.assert_allclose(
        kept["training_return_seed_means"], want["training_return_seed_means"], rtol=1e-12
    )
    assert kept["kl_share"] == pytest.approx(want["kl_share"], rel=1e-12)
    got, expected = (json.loads((f / "eval.json").read_text()) for f in (pooled, whole))
    for e, w in zip(got["evaluations"], expected["evaluations"], strict=True):
        assert e.keys() == w.keys() and e["outlier_seeds"] == w["outlier_seeds"] == [2]
        for key, value in w.items():
            if isinstance(value, (str, bool, int)):
                assert e[key] == value, key
            else:  # float statistics: pooled from the parts' own
                np.testing.assert_allclose(e[key], value, rtol=1e-12, err_msg=key)
    assert (
        got["kl_storms"] == expected["kl_storms"]
        and len(got["kl_storms"]) == SEEDS
        and got["kl_storms"][5]["first"] == 101
    )
    assert got["wall_seconds"] == 500.0 and got["device"] == "NVIDIA H200 + NVIDIA H100"
    assert [
        (p["folder"], p["seed"], p["seeds"], p["train_env_steps_per_s"]) for p in got["parts"]
    ] == [
        ("part0/car_racing/ppo_rgb", 0, 4, 1e6 / 300),
        ("part4/car_racing/ppo_rgb", 4, 2, 1e6 / 200),
    ]
    assert [p["group_dir"] for p in got["parts"]] == [
        "part0/car_racing/_groups/0a",
        "part4/car_racing/_groups/0a",
    ]
    # a part's own, not the pooled run's
    assert "train_env_steps_per_s" not in got and "group_dir" not in got
    cells = [
        report.cell,
        report.iqm_cell,
        lambda r: report.metric_cell(r, "progress", 1, percent=True),
    ]
    pooled_result, whole_result = (
        report.load(parts / n, "car_racing", "ppo_rgb") for n in ("pooled", "whole")
    )
    assert [c(pooled_result) for c in cells] == [c(whole_result) for c in cells]
    assert [
        f(parts / "pooled", "car_racing", "ppo_rgb") for f in (report.training_cell, report.kl_cell)
    ] == [
        f(parts / "whole", "car_racing", "ppo_rgb") for f in (report.training_cell, report.kl_cell)
    ]
    # both parts' sweeps
    assert archive.sweep_seconds(parts / "pooled", "3-car") == pytest.approx(500.0)


@pytest.mark.parametrize(
    "change, message",
    [
        ({"seed": 5}, "do not follow on"),  # a gap: seeds 0-3, then 5-6
        ({"seed": 3}, "do not follow on"),  # an overlap: seed 3 twice
        ({"ppo": {"epochs": 2}}, "other settings than"),
        ({"eval_episodes": 10}, "other settings than"),
        ({"seeds": 0}, "names no seeds to pool (seed 4, seeds 0)"),
        ({"seed": "4"}, "names no seeds to pool (seed '4', seeds 2)"),
    ],
)
def test_parts_that_cannot_be_one_row_are_one_line(parts, capsys, change, message):
    path = parts / "part4" / RUN / "config.yaml"
    values = yaml.safe_load(path.read_text())
    for key, value in change.items():
        values[key] = {**values[key], **value} if isinstance(value, dict) else value
    path.write_text(yaml.safe_dump(values))
    status, err = pool_refused(parts, capsys)
    assert status == 2 and err.count("\n") == 1 and err.startswith("error: ") and message in err
    assert "hintsjax-pool-" not in err, err  # the parts' own folders named, not the staging one
    assert not archive.ARCHIVE.exists()  # nothing written, the parts' archives neither


@pytest.mark.parametrize("later", ["default", "other"])
def test_a_part_saved_before_a_setting_existed_pools_where_the_other_has_its_default(
    parts, capsys, later
):
    """The archived part (seeds 0-3) was saved before `frames`, `colour` and `ppo.pixel_scale`
    existed; the later part wrote them. At their defaults the parts are one row (as the
    humanoid's archived 10 seeds and 10 trained since, table3_seeds20.md); a part that set one
    otherwise is not."""
    old = parts / "part0" / RUN / "config.yaml"
    values = yaml.safe_load(old.read_text())
    del values["frames"], values["colour"], values["ppo"]["pixel_scale"]
    old.write_text(yaml.safe_dump(values))
    if later == "other":
        new = parts / "part4" / RUN / "config.yaml"
        values = yaml.safe_load(new.read_text())
        values["ppo"]["pixel_scale"] = 0.5
        new.write_text(yaml.safe_dump(values))
        status, err = pool_refused(parts, capsys)
        assert status == 2 and "other settings than" in err and err.endswith(": ppo\n"), err
        return
    pool_command(
        ["--pool", f"{parts / 'part0'},{parts / 'part4'}", "--runs", str(parts / "pooled")]
    )
    assert capsys.readouterr().out.startswith("pooled 1 run(s)")
    pooled = yaml.safe_load((archive.ARCHIVE / "pooled" / RUN / "config.yaml").read_text())
    assert pooled["seeds"] == SEEDS and "pixel_scale" not in pooled["ppo"]  # the first part's


def pool_refused(parts: Path, capsys) -> tuple[int, str]:
    """Pooling part0 and part4 into `pooled`, which must refuse (SystemExit): its exit status and
    what it printed on stderr."""
    with pytest.raises(SystemExit) as e:
        pool_command(
            ["--pool", f"{parts / 'part0'},{parts / 'part4'}", "--runs", str(parts / "pooled")]
        )
    return e.value.code, capsys.readouterr().err


@pytest.mark.parametrize(
    "damage, message",
    [
        (lambda run: (run / "eval.json").write_text("{not json"), "eval.json cannot be read"),
        (lambda run: (run / "eval.json").write_text("[1, 2]"), "eval.json is not a mapping"),
        (
            lambda run: (run / "eval.json").write_text('{"label": "ppo_rgb", "evaluations": []}'),
            "eval.json holds no evaluations",
        ),
        (lambda run: (run / "config.yaml").write_text("env: [\n"), "config.yaml cannot be read"),
        (lambda run: (run / "metrics.csv").unlink(), "has a learning curve"),
        (lambda run: (run / "metrics.csv").write_text("update,seed\n1\n"), "cannot be archived"),
    ],
)
def test_a_damaged_part_is_one_line_naming_its_file_and_nothing_is_written(
    parts, capsys, damage, message
):
    damage(parts / "part4" / RUN)
    status, err = pool_refused(parts, capsys)
    assert status == 2 and err.count("\n") == 1 and err.startswith("error: ") and message in err
    assert "hintsjax-pool-" not in err, err  # the parts' own folders named, not the staging one
    assert not archive.ARCHIVE.exists()  # nothing written, the parts' archives neither


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--pool", "{runs}/part0", "--runs", "{runs}/pooled"], "give two or more parts"),
        (
            ["--pool", "{runs}/part0,{runs}/pooled", "--runs", "{runs}/pooled"],
            "other folder names than --runs (pooled)",
        ),
        (["--pool", "{runs}/part0,{runs}/nowhere", "--runs", "{runs}/pooled"], "no runs folder at"),
        (
            ["--pool", "{runs}/part0,{runs}/part4", "--runs", "{runs}/whole"],
            "the reports would read it rather than the pooled run",
        ),
    ],
)
def test_bad_parts_are_one_line(parts, capsys, argv, message):
    argv = [a.format(runs=parts) for a in argv]
    with pytest.raises(SystemExit) as e:
        pool_command(argv)
    err = capsys.readouterr().err
    assert e.value.code == 2 and err.count("\n") == 1 and message in err
    assert not (archive.ARCHIVE / Path(argv[-1]).name).exists()  # nothing pooled


def test_a_part_still_training_is_left_out_until_it_finishes(parts, capsys):
    (parts / "part4" / RUN / "eval.json").unlink()  # its seeds are still training
    pool_command(
        ["--pool", f"{parts / 'part0'},{parts / 'part4'}", "--runs", str(parts / "pooled")]
    )
    assert capsys.readouterr().out.rstrip().endswith(": none")
    assert not (archive.ARCHIVE / "pooled" / RUN).exists()


def test_archiving_a_runs_folder_that_is_not_there_is_refused(parts, capsys):
    with pytest.raises(SystemExit) as e:
        pool_command(["--archive", "--runs", str(parts / "nope")])
    assert e.value.code == 2 and capsys.readouterr().err == (
        f"error: no runs folder at {parts / 'nope'}: nothing to archive\n"
    )
    with pytest.raises(SystemExit) as e:
        pool_command(["--report", "--runs", str(parts / "nope")])
    assert e.value.code == 2 and capsys.readouterr().err == (
        f"error: no runs folder at {parts / 'nope'} and no archived one at "
        f"{archive.ARCHIVE / 'nope'}\n"
    )
    assert not archive.ARCHIVE.exists()


def test_an_archive_that_takes_no_file_is_one_line_exit_1(parts, capsys, monkeypatch, unwritable):
    """A results folder the machine refuses (read-only, immutable) is the machine's refusal as
    for every command: one line naming the path, exit 1, no traceback."""
    monkeypatch.delenv("HINTSJAX_DEBUG")
    archive.ARCHIVE.mkdir()
    unwritable(archive.ARCHIVE)
    with pytest.raises(SystemExit) as e:
        pool_command(["--archive", "--runs", str(parts / "whole")])
    err = capsys.readouterr().err.strip().splitlines()
    assert e.value.code == 1 and len(err) == 1, err
    assert err[0].startswith(f"error: could not write {archive.ARCHIVE / 'whole'}"), err
