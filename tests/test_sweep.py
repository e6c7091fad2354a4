"""The sweeps (hintsjax/reproduce/sweep.py, their --set: hintsjax/reproduce/sweep_settings.py), the
table scripts' command line (hintsjax/reproduce/table_script.py), the tables and reports
(hintsjax/reproduce/report.py, hintsjax/reproduce/markdown.py) and the archive
(hintsjax/reproduce/archive.py), and the table scripts of experiments/ (on pytest's path:
pyproject's pythonpath), on hand-written run folders."""

from __future__ import annotations

import csv
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from hintsjax.reproduce import archive, markdown, report, sweep, sweep_settings, table_script


def write_run(
    runs: Path,
    env: str,
    label: str,
    evaluations: list[dict] | None = None,
    returns=None,
    device: str = "NVIDIA H200",
) -> None:
    """A run folder: eval.json with `evaluations`, metrics.csv with `returns` [seeds][updates]."""
    folder = runs / env / label
    folder.mkdir(parents=True)
    if evaluations is not None:
        (folder / "eval.json").write_text(
            json.dumps({"evaluations": evaluations, "wall_seconds": 61.4, "device": device})
        )
    if returns is not None:
        with open(folder / "metrics.csv", "w", newline="") as f:
            writer = csv.DictWriter(f, ["update", "seed", "env_steps", "episode_return"])
            writer.writeheader()
            for seed, row in enumerate(returns):
                for update, value in enumerate(row):
                    writer.writerow(
                        {
                            "update": update,
                            "seed": seed,
                            "env_steps": 1024 * (update + 1),
                            "episode_return": value,
                        }
                    )


def evaluation(mean, std, seed_means, **extra):
    mu = sum(seed_means) / len(seed_means)
    return {
        "mean": mean,
        "std": std,
        "seed_means": seed_means,
        "seed_std": (sum((m - mu) ** 2 for m in seed_means) / len(seed_means)) ** 0.5,
        **extra,
    }


def test_cells_read_the_evaluations(tmp_path):
    write_run(
        tmp_path,
        "car_racing",
        "ppo_rgb",
        [
            evaluation(100.0, 20.0, [90.0, 110.0]),
            evaluation(
                50.0,
                5.0,
                [50.0, 50.0],
                progress_mean=0.25,
                progress_std=0.1,
                progress_seed_means=[0.2, 0.3],
            ),
        ],
    )
    result = report.load(tmp_path, "car_racing", "ppo_rgb")
    assert report.cell(result) == "100.0 ± 20.0 (10.0)"
    assert report.cell(result, 1) == "50.0 ± 5.0 (0.0)"
    assert report.metric_cell(result, "progress", 1, percent=True) == "25% ± 10 (5)"
    assert report.metric_cell(result, "progress", 0) == "-"  # not recorded on that variant
    assert report.cell(report.load(tmp_path, "car_racing", "hints-mc-composite")) == "-"  # not run
    assert report.wall_clock(result) == "61"
    # by python -m hintsjax.run
    trained_alone = {"evaluations": [evaluation(1.0, 0.0, [1.0])], "train_seconds": 53.7}
    assert report.wall_clock(trained_alone) == "54 (training only)"


def test_training_cell_averages_the_last_tenth_of_updates_per_seed(tmp_path):
    # 20 updates: the last 2 count. Seed 0 ends 10, 20 -> 15; seed 1 ends NaN (no episode
    # ended: the value before it carries forward, 30), 40 -> 35. Mean 25, std over seeds 10.
    nan = float("nan")
    write_run(
        tmp_path,
        "halfcheetah",
        "ppo_rgb",
        returns=[[0.0] * 18 + [10.0, 20.0], [0.0] * 17 + [30.0, nan, 40.0]],
    )
    assert report.training_cell(tmp_path, "halfcheetah", "ppo_rgb") == "25.0 ± 10.0"
    write_run(tmp_path, "halfcheetah", "ppo_state", returns=[[nan] * 20])
    assert report.training_cell(tmp_path, "halfcheetah", "ppo_state") == "-"  # no episode ended yet
    assert report.training_cell(tmp_path, "halfcheetah", "hints-fc-velocity") == "-"


def test_sweep_records_give_the_gpu_seconds_and_hardware(tmp_path):
    write_run(tmp_path, "halfcheetah", "ppo_rgb", [evaluation(1.0, 0.0, [1.0])])
    write_run(tmp_path, "halfcheetah", "ppo_state", [evaluation(1.0, 0.0, [1.0])], device="cpu")
    records = [
        {"table": "3-locomotion", "workers": 6, "seconds": 600.0, "gpus": ["0", "1"]},
        {"table": "3-locomotion", "workers": 1, "seconds": 900.0, "device": "cpu"},  # left out
        {"table": "3-car", "workers": 4, "seconds": 700.0, "gpus": []},
        {"table": "3-ant", "workers": 1, "seconds": 900.0, "gpus": ["1"]},
    ]
    (tmp_path / "sweeps.jsonl").write_text("".join(json.dumps(r) + "\n" for r in records))
    ids = ["halfcheetah/ppo_rgb", "halfcheetah/ppo_state"]
    assert archive.sweep_seconds(tmp_path, "3-locomotion") == pytest.approx(600.0)
    assert (
        report.sweep_hardware(tmp_path, "3-locomotion", ids)
        == "NVIDIA H200; 6 runs at once over 2 GPUs"
    )
    assert report.sweep_hardware(tmp_path, "3-car", ids) == "NVIDIA H200; 4 runs at once on one GPU"
    assert report.footer(tmp_path, "3-locomotion", ids).endswith(
        "600 s (NVIDIA H200; 6 runs at once over 2 GPUs)."
    )
    assert (
        report.sweep_hardware(tmp_path, "3-ant", ids) == "NVIDIA H200; 1 run at a time on one GPU"
    )
    assert report.sweep_hardware(tmp_path, "2", ids) == ""
    write_run(tmp_path, "halfcheetah", "ppo_fast", [evaluation(1.0, 0.0, [1.0])])
    eval_json = tmp_path / "halfcheetah" / "ppo_fast" / "eval.json"
    eval_json.write_text(json.dumps({**json.loads(eval_json.read_text()), "deterministic": False}))
    assert report.sweep_hardware(tmp_path, "3-locomotion", [*ids, "halfcheetah/ppo_fast"]).endswith(
        "over 2 GPUs; deterministic GPU ops off (1 runs)"
    )
    # Two sweeps side by side on one machine (10:00-10:20 and 10:05-10:30), then one at 11:00-11:10:
    # the overlap counts once, 30 + 10 minutes.
    side_by_side = [
        {
            "table": "3-locomotion",
            "workers": 1,
            "seconds": s,
            "finished": f"2026-11-22 {end}",
            "gpus": ["0"],
        }
        for s, end in ((1200.0, "10:20:00"), (1500.0, "10:30:00"), (600.0, "11:10:00"))
    ]
    (tmp_path / "sweeps.jsonl").write_text("".join(json.dumps(r) + "\n" for r in side_by_side))
    assert archive.sweep_seconds(tmp_path, "3-locomotion") == pytest.approx(2400.0)


@pytest.mark.parametrize(
    "flags, expected",
    [
        ("", False),
        ("--xla_gpu_deterministic_ops=true", True),
        ("--foo --xla_gpu_deterministic_ops=false", False),
        ("--xla_gpu_deterministic_ops=true --xla_gpu_deterministic_ops=false", False),
    ],
)
def test_deterministic_gpu_ops_reads_the_last_flag(monkeypatch, flags, expected):
    import hintsjax

    monkeypatch.setenv("XLA_FLAGS", flags)
    assert hintsjax.deterministic_gpu_ops() is expected


def test_run_values_invert_the_labels():
    assert sweep.run_values("car_racing", "hints-mc-on_track", 5) == {
        "env": "car_racing",
        "seeds": 5,
        "checkpoint_every": 50,
        "checkpoint_seconds": sweep.CHECKPOINT_SECONDS,
        "agent": "hints",
        "scheme": "mc",
        "hint": "on_track",
    }
    assert sweep.run_values("ant", "ppo_rgb", 2)["agent"] == "ppo_rgb"


def test_locomotion_references_train_their_expert_before_dagger_and_gail():
    import locomotion

    ids = locomotion.run_ids(["halfcheetah"])
    assert ids[:3] == ["halfcheetah/expert_ppo", "halfcheetah/dagger", "halfcheetah/gail"]
    assert (
        sweep.prerequisite("halfcheetah/dagger")
        == sweep.prerequisite("halfcheetah/gail")
        == "halfcheetah/expert_ppo"
    )
    assert sweep.prerequisite("halfcheetah/ppo_rgb") is None
    experts = Path("/somewhere/experts")
    assert sweep.run_values("halfcheetah", "dagger", 5, experts=experts)["expert"] == str(
        experts / "halfcheetah"
    )
    # The note reads the packaged expert's seed and the references' budgets from the config.
    note = report.references_note(Path("/nowhere"), "halfcheetah", locomotion.REFERENCES)
    assert (
        "5 M steps" in note
        and "250 K expert-labelled steps" in note
        and "hintsjax/experts/halfcheetah" in note
    )
    assert (
        "by PPO for 5 M steps on the discriminator's reward the log odds log D - log(1 - D)" in note
    )
    # The ant's episodes end when it falls: its GAIL is paid -log(1 - D) > 0, not the log odds.
    assert "PPO for 10 M steps on the discriminator's reward -log(1 - D)" in report.references_note(
        Path("/nowhere"), "ant", locomotion.REFERENCES
    )


def test_car_references_come_first_and_the_note_describes_gail():
    import car_racing

    assert car_racing.run_ids(["car_racing"])[:3] == [
        f"car_racing/{a}" for a in ("expert_ppo", "dagger", "gail")
    ]
    assert sweep.prerequisite("car_racing/gail") == "car_racing/expert_ppo"
    note = report.references_note(Path("/nowhere"), "car_racing", car_racing.REFERENCES)
    assert "2 M steps" in note and "250 K expert-labelled steps" in note
    assert (
        "gail learns from 16 of that expert's episodes, by PPO for 2 M steps on the "
        "discriminator's reward -log(1 - D)" in note
    )
    # Archived runs name their own expert_ppo's best seed, not the packaged expert that replaced it
    # (the car's of 2026-11-26, seed 0, was retrained on the per-wheel grip: seed 2, 866).
    assert "its best seed (seed 0, 839 over 50 episodes) over" in report.references_note(
        Path("runs/car_racing"), "car_racing", car_racing.REFERENCES
    )
    assert "its best seed (seed 2, 866 over 50 episodes) over" in report.references_note(
        Path("runs/table3_20"), "car_racing", car_racing.REFERENCES
    )


def test_car_findings_decide_o3_by_the_interval_of_the_difference_in_hairpin_progress(tmp_path):
    """O3 (composite hints lift hairpin progress above vision only) is decided when the bootstrap
    interval of the difference in mean progress over seeds excludes 0, undecided when it does
    not."""
    import car_racing

    def runs(rgb, composite):
        folder = tmp_path / f"runs{len(list(tmp_path.iterdir()))}"
        for label, progress in (("ppo_rgb", rgb), ("hints-mc-composite", composite)):
            hairpin = evaluation(
                1.0,
                0.0,
                [1.0] * len(progress),
                progress_mean=sum(progress) / len(progress),
                progress_std=0.1,
                progress_seed_means=progress,
                stochastic=True,
                episodes_per_seed=50,
            )
            write_run(
                folder,
                "car_racing",
                label,
                [
                    evaluation(
                        1.0, 0.0, [1.0] * len(progress), stochastic=True, episodes_per_seed=50
                    ),
                    hairpin,
                ],
            )
        return folder

    apart = runs([0.40, 0.45, 0.50, 0.42, 0.48], [0.75, 0.80, 0.78, 0.82, 0.76])
    text = car_racing.findings(apart, "car_racing")
    assert text.startswith(
        "Hairpin progress (O3): HINTS-MC composite 78% (5 seeds), PPO-RGB 45% (5 seeds); paper 78% "
        "against 46%. Composite minus vision only: +33.2 points [+"
    )
    assert text.endswith(": decided.")
    mixed = runs([0.10, 0.60, 0.20, 0.50, 0.30], [0.15, 0.55, 0.25, 0.45, 0.40])
    assert car_racing.findings(mixed, "car_racing").endswith(": undecided.")
    assert (
        car_racing.protocol(apart, "car_racing")
        == "5 training seeds x 50 evaluation episodes (sampled actions)"
    )
    # rows evaluated alike are named together: 10 seeds for the hint row, 5 for the others
    uneven = runs(
        [0.40, 0.45, 0.50, 0.42, 0.48], [0.75, 0.80, 0.78, 0.82, 0.76, 0.7, 0.7, 0.7, 0.7, 0.7]
    )
    write_run(
        uneven,
        "car_racing",
        "dagger",
        [evaluation(1.0, 0.0, [1.0] * 5, stochastic=True, episodes_per_seed=50)],
    )
    assert car_racing.protocol(uneven, "car_racing") == (
        "the row's training seeds x evaluation episodes (dagger, ppo_rgb: 5 training seeds x 50 "
        "evaluation episodes (sampled actions); hints-mc-composite: 10 training seeds x 50 "
        "evaluation episodes (sampled actions))"
    )


def test_locomotion_report_states_the_settings_each_row_was_trained_with(tmp_path):
    import locomotion
    from hintsjax.settings import layers

    labels = ["ppo_rgb", "hints-fc-speed", "ppo_state"]
    assert locomotion.settings_lines(tmp_path, "ant", labels) == [  # none run yet: today's defaults
        "PPO: 256 envs per seed, batches of 1024, 4 epochs of minibatches of 256, learning rates "
        "encoder 0.0003, actor 0.0003, critic 0.001, KL early stop at 0.05 with the learning rates "
        "adapted to the KL (not run yet; config.ENV_DEFAULTS)."
    ]
    for label, values in (
        ("ppo_rgb", {"agent": "ppo_rgb"}),
        (
            "hints-fc-speed",
            {
                "ppo": {
                    "encoder_lr": 1e-3,
                    "epochs": 8,
                    "target_kl": 0.1,
                    "kl_adaptive_lr": False,
                    "critic_trains_encoder": False,
                }
            },
        ),
    ):
        write_run(tmp_path, "ant", label, [evaluation(1.0, 0.0, [1.0])])
        layers.save_run_config(
            tmp_path / "ant" / label, layers.run_config({"env": "ant", **values})
        )
    assert locomotion.settings_lines(tmp_path, "ant", labels) == [
        "PPO, as each row was trained:",
        "",
        "- ppo_rgb: 256 envs per seed, batches of 1024, 4 epochs of minibatches of 256, learning "
        "rates encoder 0.0003, actor 0.0003, critic 0.001, KL early stop at 0.05 with the learning "
        "rates adapted to the KL (config.ENV_DEFAULTS).",
        "- hints-fc-speed: 256 envs per seed, batches of 1024, 8 epochs of minibatches of 256, "
        "learning rates encoder 0.001, actor 0.0003, critic 0.001, KL early stop at 0.1, the "
        "encoder trained by the actor alone (not today's config.ENV_DEFAULTS: epochs, encoder_lr, "
        "target_kl, critic_trains_encoder, kl_adaptive_lr differ).",
        "- ppo_state: 256 envs per seed, batches of 1024, 4 epochs of minibatches of 256, learning "
        "rates encoder 0.0003, actor 0.0003, critic 0.001, KL early stop at 0.05 with the learning "
        "rates adapted to the KL (not run yet; config.ENV_DEFAULTS).",
    ]


def test_a_report_states_a_critic_with_its_own_encoder_and_the_pictures_scale():
    from hintsjax.settings.layers import run_config

    cfg = run_config({"agent": "ppo_rgb"})
    assert "own encoder" not in report.ppo_text(cfg.ppo) and "pictures" not in report.ppo_text(
        cfg.ppo
    )
    own = run_config({"agent": "ppo_rgb", "ppo": {"critic_encoder": "own", "pixel_scale": 0.5}})
    assert report.ppo_text(own.ppo).endswith(
        "critic 0.001, the critic's own encoder, pictures in [-0.5, 0.5], rewards x 0.1"
    )
    brax = run_config(
        {
            "agent": "ppo_rgb",
            "ppo": {"activation": "swish", "std_head": "softplus", "bootstrap_truncated": False},
        }
    )
    assert report.ppo_text(brax.ppo).endswith(
        "critic 0.001, swish MLPs, a softplus std head, no bootstrap at the time limit, "
        "rewards x 0.1"
    )


def test_kl_cell_is_the_share_of_blown_up_updates(tmp_path):
    folder = tmp_path / "ant" / "hints-fc-speed"
    folder.mkdir(parents=True)
    # 2 seeds x 10 updates: seed 0 has 3 updates at 0.6, seed 1 one overflowed (inf): 4 of 20.
    # 0.5 is not above
    kl = {(0, 2): 0.6, (0, 5): 0.6, (0, 9): 0.6, (1, 7): float("inf"), (1, 8): 0.5}
    rows = [
        {"update": u, "seed": s, "env_steps": 1024 * u, "approx_kl": kl.get((s, u), 0.01)}
        for s in range(2)
        for u in range(1, 11)
    ]
    with open(folder / "metrics.csv", "w", newline="") as f:
        writer = csv.DictWriter(f, ["update", "seed", "env_steps", "approx_kl"])
        writer.writeheader()
        writer.writerows(rows)
    assert report.kl_cell(tmp_path, "ant", "hints-fc-speed") == "20.0%"
    assert report.kl_cell(tmp_path, "ant", "hints-fc-speed", above=0.05) == "25.0%"
    write_run(tmp_path, "ant", "dagger", returns=[[1.0]])  # no approx_kl column: not PPO
    assert report.kl_cell(tmp_path, "ant", "dagger") == "-"
    assert report.kl_cell(tmp_path, "ant", "ppo_rgb") == "-"  # not run


def test_only_picks_labels_and_names_the_valid_ones(capsys):
    import argparse

    parser = argparse.ArgumentParser()
    table_script.add_arguments(parser, "runs/x", ("ant", "halfcheetah"))
    ids = ["ant/ppo_rgb", "ant/hints-fc-speed", "halfcheetah/ppo_rgb"]
    assert table_script.chosen_runs(parser, parser.parse_args([]), ids) == ids
    assert table_script.chosen_runs(parser, parser.parse_args(["--only", "ppo_rgb"]), ids) == [
        "ant/ppo_rgb",
        "halfcheetah/ppo_rgb",
    ]
    with pytest.raises(SystemExit) as e:
        table_script.chosen_runs(parser, parser.parse_args(["--only", "ppo_rgb,nope"]), ids)
    assert e.value.code == 2
    assert (
        capsys.readouterr().err
        == "error: unknown run label ['nope']; valid choices: ppo_rgb, hints-fc-speed\n"
    )


@pytest.mark.parametrize("script", ["locomotion", "car_racing"])
def test_a_table_report_runs_end_to_end(script, tmp_path, monkeypatch):
    """The report of a table script builds every line (settings, references, findings) from a
    runs folder with one finished row, into a results folder of its own."""
    import importlib

    module = importlib.import_module(script)
    monkeypatch.setattr(module, "RESULTS", tmp_path / "results")
    env = module.ENVS[0]
    write_run(tmp_path / "runs", env, "ppo_rgb", [evaluation(1.0, 0.0, [1.0])] * 2)
    module.report(tmp_path / "runs")
    text = next((tmp_path / "results").glob("*.md")).read_text()
    assert "References (no budget limit): expert_ppo is PPO on the state" in text
    assert f"| ppo_rgb | {report.cell(report.load(tmp_path / 'runs', env, 'ppo_rgb'))} |" in text


def test_hint_ranking_s_report_rebuilds_the_committed_file_on_a_fresh_checkout(
    tmp_path, monkeypatch
):
    """`python experiments/hint_ranking.py --report` where --runs (runs/hint_ranking) holds no
    scores reads the committed ones (experiments/results/runs/hint_ranking): the pendulum's lines
    (the first env, so the same bootstrap draws) are the committed file's. A runs folder of its own
    is read before them."""
    import hint_ranking

    out, runs = tmp_path / "hint_ranking.md", tmp_path / "hint_ranking"
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "hint_ranking.py",
            "--report",
            "--envs",
            "pendulum",
            "--runs",
            str(runs),
            "--out",
            str(out),
        ],
    )
    hint_ranking.main()
    committed = (hint_ranking.RESULTS / "hint_ranking.md").read_text().splitlines()
    pendulum = [
        line
        for line in out.read_text().splitlines()
        if line.startswith(("| pendulum |", "| angular_velocity |"))
    ]
    assert len(pendulum) == 4 and set(pendulum) <= set(committed)
    assert "- hardware: one NVIDIA H100" in out.read_text()  # the committed about.json
    shutil.copytree(archive.ARCHIVE / "hint_ranking" / "idp", runs / "idp")
    scores = json.loads((runs / "idp" / "scores.json").read_text())
    # ranked backwards
    scores["scores"]["information"] = [[-x for x in row] for row in scores["scores"]["information"]]
    (runs / "idp" / "scores.json").write_text(json.dumps(scores))
    monkeypatch.setattr(hint_ranking, "RESAMPLES", 20)
    monkeypatch.setattr(
        sys,
        "argv",
        ["hint_ranking.py", "--report", "--envs", "idp", "--runs", str(runs), "--out", str(out)],
    )
    hint_ranking.main()
    idp = next(
        line for line in out.read_text().splitlines() if line.startswith("| idp | information |")
    )
    # the committed rho, 0.86, the other way round
    assert idp.split("|")[3].strip().startswith("-0.86")


def test_learned_hints_report_rebuilds_the_committed_file_on_a_fresh_checkout(
    tmp_path, monkeypatch
):
    """`python experiments/learned_hints.py --report` where --runs holds no finished case reads the
    committed runs (experiments/results/runs/learned_hints) and writes the committed file."""
    import learned_hints

    out = tmp_path / "learned_hints.md"
    monkeypatch.setattr(
        sys,
        "argv",
        [
            "learned_hints.py",
            "--report",
            "--runs",
            str(tmp_path / "learned_hints"),
            "--out",
            str(out),
        ],
    )
    learned_hints.main()
    assert out.read_text() == (learned_hints.RESULTS / "learned_hints.md").read_text()
    assert not (tmp_path / "learned_hints").exists()  # a report makes no runs folder


def test_an_archived_run_reads_as_the_run_did(tmp_path, monkeypatch):
    """archive_runs keeps what the tables need; with the run folder gone, the readers fall back
    to the archive and give the same cells (the curve averaged into CURVE_POINTS bins)."""
    from hintsjax.settings import layers
    from hintsjax.training.runlog import CURVE_POINTS, bin_means, read_curves

    runs, kept = tmp_path / "locomotion", tmp_path / "archive"
    monkeypatch.setattr(archive, "ARCHIVE", kept)
    nan = float("nan")
    rng = __import__("numpy").random.default_rng(0)
    # 600 updates, 2 seeds
    returns = [[nan] * 5 + list(rng.normal(100 * s, 10, 595)) for s in range(2)]
    write_run(runs, "ant", "ppo_rgb", [evaluation(7.0, 1.0, [6.0, 8.0])], returns)
    layers.save_run_config(
        runs / "ant" / "ppo_rgb", layers.run_config({"env": "ant", "agent": "ppo_rgb"})
    )
    rows = list(csv.DictReader((runs / "ant" / "ppo_rgb" / "metrics.csv").open()))
    for i, row in enumerate(rows):
        row["approx_kl"] = 0.9 if i % 4 == 0 else 0.01  # a quarter of the updates blew up
    with (runs / "ant" / "ppo_rgb" / "metrics.csv").open("w", newline="") as f:
        writer = csv.DictWriter(f, list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    (runs / "sweeps.jsonl").write_text(
        json.dumps({"table": "3-locomotion", "workers": 1, "seconds": 60.0}) + "\n"
    )
    before = [
        f(runs, "ant", "ppo_rgb")
        for f in (lambda *a: report.cell(report.load(*a)), report.training_cell, report.kl_cell)
    ]
    assert before[2] == "25.0%"
    binned = bin_means(*read_curves(runs / "ant" / "ppo_rgb" / "metrics.csv"))
    binned_kl = bin_means(*read_curves(runs / "ant" / "ppo_rgb" / "metrics.csv", "approx_kl"))[1]

    # ppo_state never ran
    assert archive.archive_runs(runs, ["ant/ppo_rgb", "ant/ppo_state"]) == ["ant/ppo_rgb"]
    import shutil

    shutil.rmtree(runs)
    assert [
        f(runs, "ant", "ppo_rgb")
        for f in (lambda *a: report.cell(report.load(*a)), report.training_cell, report.kl_cell)
    ] == before
    assert archive.run_folder(runs, "ant", "ppo_rgb") == kept / "locomotion" / "ant" / "ppo_rgb"
    assert (
        report.trained_ppo(runs, "ant", "ppo_rgb")
        == layers.run_config({"env": "ant", "agent": "ppo_rgb"}).ppo
    )
    steps, values = read_curves(report.metrics_path(runs, "ant", "ppo_rgb"))
    assert len(steps) == CURVE_POINTS and steps[-1] == 1024 * 600  # bins of 2 or 3 updates
    np.testing.assert_array_equal(steps, binned[0])
    np.testing.assert_allclose(values, binned[1], rtol=1e-5)  # written to 6 digits
    # the logged diagnostics come along, binned as the return (4 digits); unlogged ones are left out
    np.testing.assert_allclose(
        read_curves(report.metrics_path(runs, "ant", "ppo_rgb"), "approx_kl")[1],
        binned_kl,
        rtol=1e-3,
    )
    assert binned_kl.max() > 0.3  # bins of 2 or 3 updates, one of them blown up
    with pytest.raises(KeyError):
        read_curves(report.metrics_path(runs, "ant", "ppo_rgb"), "entropy")
    # the records came along
    assert archive.sweep_seconds(runs, "3-locomotion") == pytest.approx(60.0)
    assert report.cell(report.load(runs, "ant", "ppo_state")) == "-"


def test_a_report_keeps_the_rows_of_runs_it_cannot_read(tmp_path, monkeypatch):
    """Rows of runs in neither runs/ nor the archive stay as the committed report had them, marked;
    rows it has runs for are rebuilt; rows that were '-' are not kept."""
    import locomotion

    monkeypatch.setattr(locomotion, "RESULTS", tmp_path / "results")
    monkeypatch.setattr(archive, "ARCHIVE", tmp_path / "archive")
    (tmp_path / "results").mkdir()
    (tmp_path / "results" / locomotion.REPORT).write_text(
        "\n".join(
            [
                "## ant (5 M env steps per seed)",
                "",
                "PPO: 64 envs per seed, as the kept row trained (kept rows †; config.ENV_DEFAULTS "
                "when last reported).",
                "",
                "| agent | ours | paper | training return, last 10% | updates with KL > 0.5 | "
                "wall-clock (s) |",
                "|---|---|---|---|---|---|",
                "| ppo_rgb | 1081.5 ± 175.9 (170.2) | 1015.49 ± 3.3 | 1049.8 ± 88.7 | 0.0% | 915 |",
                "| ppo_state | 3764.1 ± 1089.3 (729.7) | 533.77 ± 254.7 | 2531.2 ± 611.6 | 0.0% | "
                "1226 |",
                "| hints-fc-speed | - | 1313.57 ± 57.6 | - | - | - |",
                "",
            ]
        )
    )
    write_run(tmp_path / "runs", "ant", "ppo_state", [evaluation(5.0, 1.0, [5.0])])
    write_run(tmp_path / "runs", "ant", "hints-fc-speed", [evaluation(2000.0, 1.0, [2000.0])])
    # ppo_state's stand-in run has no metrics.csv to fill its cells
    locomotion.report(tmp_path / "runs", force=True)
    text = (tmp_path / "results" / locomotion.REPORT).read_text()
    assert (
        f"| ppo_rgb {markdown.KEPT} | 1081.5 ± 175.9 (170.2) | 1015.49 ± 3.3 | 1049.8 ± 88.7 | "
        "0.0% | 915 |" in text
    )
    assert "| ppo_state | 5.0 ± 1.0 (0.0) |" in text and "3764.1" not in text
    assert (
        f"| hints-fc-speed {markdown.KEPT}" not in text and f"| dagger {markdown.KEPT}" not in text
    )
    assert "PPO-RGB 1081.5" in text  # the kept row's mean counts in the findings
    assert (
        "- ppo_rgb: 64 envs per seed, as the kept row trained "
        f"(kept rows {markdown.KEPT}; as last reported)." in text
    )
    locomotion.report(tmp_path / "runs", force=True)  # and again from the report just written
    assert (
        "- ppo_rgb: 64 envs per seed, as the kept row trained "
        f"(kept rows {markdown.KEPT}; as last reported)."
        in (tmp_path / "results" / locomotion.REPORT).read_text()
    )
    assert f"Rows marked {markdown.KEPT} are kept from the previous report" in text


def test_a_report_that_would_blank_committed_cells_is_refused(tmp_path, capsys):
    """write_report exits 2 naming the rows, and leaves the committed report as it was, when a
    cell it filled would go '-' (its run neither in runs/ nor the archive); --force rewrites."""
    path = tmp_path / "table.md"
    committed = [
        "## pendulum",
        "",
        "| scheme | angular_velocity | state |",
        "|---|---|---|",
        "| fc (ours) | -691.3 ± 516.1 (336.6) | -468.3 ± 483.7 (365.8) |",
        "| fc (paper) | -2895.88 ± 1767.0 | -6423.87 ± 597.8 |",
        "",
    ]
    path.write_text("\n".join(committed) + "\n")
    blanked = [line.replace("-468.3 ± 483.7 (365.8)", "-") for line in committed]
    with pytest.raises(SystemExit) as exit_info:
        markdown.write_report(path, blanked)
    assert exit_info.value.code == 2
    assert "pendulum/fc (ours)" in capsys.readouterr().err
    assert path.read_text() == "\n".join(committed) + "\n"
    refilled = [
        line.replace("-691.3 ± 516.1 (336.6)", "-650.0 ± 500.0 (300.0)") for line in committed
    ]
    markdown.write_report(path, refilled)  # a changed cell is no loss
    assert "-650.0 ± 500.0" in path.read_text()
    markdown.write_report(path, blanked, force=True)
    assert "-468.3" not in path.read_text()


def test_a_learners_report_that_would_blank_committed_cells_is_refused(tmp_path, capsys):
    """A learners report (write_section) refuses as write_report does, leaving the file as it was,
    the hand-written text above its section too: classic_seeds20.md holds Table 4 rows whose runs
    were lost, which `--learners-report` without --force used to drop."""
    path, marker = tmp_path / "seeds20.md", markdown.generated_marker("classic_control.py")
    committed = "\n".join(
        [
            "# Plan",
            "",
            "Written by hand.",
            "",
            marker,
            "",
            "## pendulum (20 seeds per row)",
            "",
            "| agent | ours |",
            "|---|---|",
            "| ppo_rgb | -1277.8 ± 69.9 (15.1) |",
            "",
        ]
    )
    path.write_text(committed)
    with pytest.raises(SystemExit) as exit_info:
        markdown.write_section(
            path,
            marker,
            [
                "## pendulum (20 seeds per row)",
                "",
                "| agent | ours |",
                "|---|---|",
                "| ppo_rgb | - |",
            ],
        )
    assert exit_info.value.code == 2 and "pendulum/ppo_rgb" in capsys.readouterr().err
    assert path.read_text() == committed
    markdown.write_section(
        path,
        marker,
        ["## pendulum (20 seeds per row)", "", "| agent | ours |", "|---|---|", "| ppo_rgb | - |"],
        force=True,
    )
    assert "-1277.8" not in path.read_text() and path.read_text().startswith(
        "# Plan\n\nWritten by hand.\n"
    )


def test_curves_beside_kept_rows_go_to_their_own_figure(tmp_path, monkeypatch):
    """While some rows are kept (no curves to draw), their committed figure stays as it was and
    the newer runs' curves get a sibling figure; with no kept rows the figure is redrawn."""
    monkeypatch.setattr(archive, "ARCHIVE", tmp_path / "archive")
    runs, out = tmp_path / "runs", tmp_path / "curves_ant.png"
    write_run(runs, "ant", "ppo_state", [evaluation(5.0, 1.0, [5.0])], [[1.0, 2.0, 3.0]])
    out.write_bytes(b"the kept runs' figure")
    lines = report.curve_lines(runs, "ant", ["ppo_rgb", "ppo_state"], out, "ant", kept=("ppo_rgb",))
    assert out.read_bytes() == b"the kept runs' figure"
    sibling = tmp_path / f"curves_ant{report.ARCHIVED_SUFFIX}.png"
    assert sibling.stat().st_size > 1000 and f"![ant learning curves]({out.name})" in lines
    assert any(sibling.name in line for line in lines)
    lines = report.curve_lines(runs, "ant", ["ppo_rgb", "ppo_state"], out, "ant")
    assert out.read_bytes()[:4] == b"\x89PNG" and lines == [
        f"![ant learning curves]({out.name})",
        "",
    ]


def test_classic_report_gives_iqm_cells_and_orderings_as_probabilities_of_improvement(
    tmp_path, monkeypatch
):
    """Table 2's last column is the IQM of the seed means with its interval; the findings state
    O1 and O5 as P(x > y) with an interval, decided only when it excludes 0.5 (hand values: every
    composite seed beats every ppo_rgb seed, so P = 1 with a zero-width interval; composite and
    state seeds interleave, P = 0.5)."""
    import classic_control

    monkeypatch.setattr(classic_control, "RESULTS", tmp_path / "results")
    runs = tmp_path / "classic"
    seeds = {
        "ppo_rgb": [-1300.0, -1200.0, -1250.0, -1400.0],
        "hints-fc-composite": [-250.0, -200.0, -300.0, -220.0],
        "hints-fc-state": [-260.0, -190.0, -310.0, -210.0],
    }
    for label, means in seeds.items():
        write_run(runs, "pendulum", label, [evaluation(float(np.mean(means)), 10.0, means)] * 2)
    text = classic_control.findings(runs, "pendulum")
    assert "- O1: P(composite > ppo_rgb) = 1.00 [1.00, 1.00]: decided" in text
    assert "- O5: P(composite > state) = 0.50 [" in text and text.split("P(composite > state)")[
        1
    ].split("\n")[0].endswith("undecided")
    row = report.iqm_cell(report.load(runs, "pendulum", "hints-fc-composite"))
    assert row.startswith("-235.0 [")  # the middle two of -300, -250, -220, -200
    monkeypatch.setattr(classic_control, "refuse_lost_cells", lambda *a: None)
    monkeypatch.setattr(
        classic_control,
        "write_report",
        lambda path, lines, force=False: path.write_text("\n".join(lines)),
    )
    (tmp_path / "results").mkdir()
    classic_control.report(runs, force=True)
    table = (tmp_path / "results" / "classic_table2.md").read_text()
    assert f"| {row} |" in table and "IQM of seed means [95% CI]" in table


def test_a_later_table_leaves_out_the_finished_runs_an_earlier_one_trains(
    tmp_path, monkeypatch, capsys
):
    """classic_control.py's --table 4 (table_script.table_main): its fc row is Table 2's runs, so a
    finished one is left out of Table 4's sweep while an unfinished one trains; Table 2 keeps its
    own; without --table, one line and exit 2."""
    import classic_control

    # main() sets it for the parent; restored after the test
    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    calls = []
    monkeypatch.setattr(
        table_script,
        "sweep",
        lambda runs, ids, workers, seeds, table, *rest: calls.append((ids, table)),
    )
    write_run(tmp_path, "pendulum", "hints-fc-composite", [evaluation(1.0, 0.0, [1.0])])
    argv = ["classic_control.py", "--runs", str(tmp_path), "--envs", "pendulum", "--only"]
    for table, only in (
        (4, "hints-fc-composite,hints-fc-state,hints-lc-composite"),
        (2, "hints-fc-composite,hints-fc-state"),
    ):
        monkeypatch.setattr(sys, "argv", [*argv, only, "--table", str(table)])
        classic_control.main()
    assert calls == [
        (["pendulum/hints-fc-state", "pendulum/hints-lc-composite"], 4),
        (["pendulum/hints-fc-composite", "pendulum/hints-fc-state"], 2),
    ]
    monkeypatch.setattr(sys, "argv", argv[:-1])
    with pytest.raises(SystemExit) as e:
        classic_control.main()
    assert (
        e.value.code == 2
        and capsys.readouterr().err == "error: give --table 2, --table 4 or --report\n"
    )


def test_seeds_below_one_get_one_line(capsys):
    import argparse

    parser = argparse.ArgumentParser()
    table_script.add_arguments(parser, "runs/x", ("pendulum",), seeds=20)
    assert parser.parse_args([]).seeds == 20
    with pytest.raises(SystemExit) as e:
        table_script.chosen_envs(parser, parser.parse_args(["--seeds", "0"]), ("pendulum",))
    assert (
        e.value.code == 2
        and capsys.readouterr().err == "error: --seeds must be at least 1, got 0\n"
    )
    assert parser.parse_args(["--alone"]).group_size == 1 and parser.parse_args([]).group_size == 0
    with pytest.raises(SystemExit) as e:
        table_script.chosen_envs(parser, parser.parse_args(["--group-size", "-1"]), ("pendulum",))
    assert e.value.code == 2 and capsys.readouterr().err.startswith(
        "error: --group-size must be at least 1"
    )


def test_plan_jobs_groups_the_classic_table_by_shape():
    import classic_control

    ids = [f"pendulum/{label}" for label in classic_control.table_runs(2, "pendulum")]
    jobs = sweep.plan_jobs(ids, seeds=20, smoke=False)
    # references and PPO-RGB alone; PPO-x twice; HINTS-FC x 6
    assert sorted(map(len, jobs)) == [1, 1, 1, 1, 2, 6]
    assert ["pendulum/ppo_state", "pendulum/ppo_noisy_state"] in jobs
    assert sweep.plan_jobs(ids, 20, False, group_size=1) == [[r] for r in ids]
    capped = sweep.plan_jobs(ids, 20, False, group_size=4)
    assert sorted(map(len, capped)) == [1, 1, 1, 1, 2, 2, 4]  # HINTS-FC x 6 cut into 4 + 2
    assert sorted(r for job in capped for r in job) == sorted(ids)


def test_a_worker_on_a_folder_another_run_writes_is_refused_before_it_writes(tmp_path):
    """One writer a folder, for a sweep's workers too: with a member's folder held (another sweep,
    or a run command, training there), a group's worker is refused naming the holder, its other
    folders' locks let go and nothing written; once the holder is gone the locks are free."""
    import cue_env  # noqa: F401  (tests/cue_env.py: the "cue" env and its hints)
    from hintsjax.system import folder_lock
    from hintsjax.system.errors import UsageError

    ids = ["cue/hints-fc-cue", "cue/hints-fc-cue_pair"]
    (tmp_path / ids[1]).mkdir(parents=True)
    held = folder_lock.acquire(tmp_path / ids[1])
    try:
        with pytest.raises(UsageError, match="is being written by another run .*pid"):
            sweep.train_one(tmp_path, ids, seeds=2, smoke=True, experts=None)
    finally:
        held.release()
    assert not (tmp_path / ids[0] / "config.yaml").exists()
    assert not (tmp_path / ids[1] / "config.yaml").exists()
    group = sweep.group_folder(tmp_path, ids)
    assert sorted(p.name for p in group.iterdir()) == []  # its lock taken, then let go
    with folder_lock.holding([group, tmp_path / ids[0], tmp_path / ids[1]]):
        pass  # every lock free again


# 34 s on 2 cores: in the slow tier, to keep `make test` within its minutes (plan_jobs' splits stay
# above)
@pytest.mark.slow
def test_a_group_trains_into_each_runs_folder_and_splits_when_too_big(tmp_path, monkeypatch):
    """A sweep's group job writes each run's eval.json (with the group and the sweep's fields)
    and keeps its checkpoints in the group's folder; a group that does not fit is split in
    halves."""
    import cue_env  # noqa: F401  (tests/cue_env.py: the "cue" env and its hints)
    from hintsjax.training import compilation, loop, pipeline

    ids = ["cue/hints-fc-cue", "cue/hints-fc-cue_pair"]
    sweep.train_one(tmp_path, ids, seeds=2, smoke=True, experts=None)
    for run_id in ids:
        result = json.loads((tmp_path / run_id / "eval.json").read_text())
        assert (
            result["group"] == [r.split("/")[1] for r in ids]
            and result["device"]
            and "wall_seconds" in result
        )
    folder = sweep.group_folder(tmp_path, ids)
    assert (
        json.loads((folder / "group.json").read_text())["runs"] == ids
        and (folder / "checkpoints").is_dir()
    )

    # A group cut while it wrote its members' results resumes whole from its final checkpoint (its
    # unfinished member alone would be a new group, trained from the start): the same numbers.
    first = json.loads((tmp_path / ids[1] / "eval.json").read_text())
    (tmp_path / ids[1] / "eval.json").unlink()
    assert sweep.todo_jobs(tmp_path, ids, 2, True) == [ids]
    assert sweep.todo_jobs(tmp_path, ids[1:], 2, True) == [ids]  # --only the unfinished run
    # another seed count: not that group
    assert sweep.todo_jobs(tmp_path, ids, 3, True) == [[ids[1]]]
    sweep.train_one(tmp_path, ids, seeds=2, smoke=True, experts=None)
    again = json.loads((tmp_path / ids[1] / "eval.json").read_text())
    # no update retrained
    assert again["evaluations"] == first["evaluations"] and again["train_env_steps_per_s"] == 0

    # A group that does not fit trains its halves as jobs of their own: here each member alone,
    # through the single run's path (stubbed: a lone run's training is tested elsewhere, and two
    # more compiles cost this test half its time)
    def too_big(compiled, what):
        raise compilation.GroupTooBig(f"{what} needs 99 GiB")

    alone = []

    def train_alone(cfg, folder, resume, progress):
        alone.append((cfg.label, folder.relative_to(tmp_path / "split").as_posix(), resume))
        return {"label": cfg.label}

    monkeypatch.setattr(loop, "check_fits", too_big)
    monkeypatch.setattr(pipeline, "train", train_alone)
    sweep.train_one(tmp_path / "split", ids, seeds=2, smoke=True, experts=None)
    assert alone == [(r.split("/")[1], r, False) for r in ids]
    for run_id in ids:
        saved = json.loads((tmp_path / "split" / run_id / "eval.json").read_text())
        assert (
            saved["label"] == run_id.split("/")[1]
            and "group" not in saved
            and "wall_seconds" in saved
        )


def test_car_learning_report_sets_each_variant_beside_the_defaults(tmp_path, monkeypatch):
    """experiments/car_learning.py's report, on hand-written runs: per variant the IQM of each
    evaluation (the run's deterministic eval.json, hintsjax.evaluate's stochastic files), the
    policy's std from the last logged entropy (std 0.5 on 3 actions), and P(variant > gaussian)
    (every tanh seed above every gaussian seed: 1.00, decided)."""
    import math

    import car_learning
    from hintsjax.settings import layers

    monkeypatch.setattr(archive, "ARCHIVE", tmp_path / "archive")
    runs = tmp_path / "car_learning"
    entropy = 3 * (math.log(0.5) + 0.5 * (1 + math.log(2 * math.pi)))
    for name, base in (("gaussian", 100.0), ("tanh", 400.0)):
        means = [base, base + 10, base + 20, base + 30]
        write_run(
            runs,
            "car_racing",
            name,
            [evaluation(base, 5.0, means, seeds=4, episodes_per_seed=50)] * 2,
            returns=[[base] * 20] * 4,
        )
        layers.save_run_config(
            runs / "car_racing" / name, layers.run_config({"env": "car_racing", "agent": "ppo_rgb"})
        )
        rows = list(csv.DictReader((runs / "car_racing" / name / "metrics.csv").open()))
        with (runs / "car_racing" / name / "metrics.csv").open("w", newline="") as f:
            writer = csv.DictWriter(f, [*rows[0], "entropy"])
            writer.writeheader()
            writer.writerows({**row, "entropy": entropy} for row in rows)
        for track in car_learning.TRACKS:
            (runs / "car_racing" / name / f"eval-{track}-stochastic-50.json").write_text(
                json.dumps(evaluation(base - 50, 5.0, [m - 50 for m in means]))
            )
    car_learning.report(runs, tmp_path / "car_learning.md")
    text = (tmp_path / "car_learning.md").read_text()
    tanh_row = next(line for line in text.splitlines() if line.startswith("| tanh |"))
    assert (
        tanh_row.count("415.0 [") == 2
        and tanh_row.count("365.0 [") == 2
        and tanh_row.endswith("| 0.50 |")
    )
    assert "(4 seeds x 50 evaluation episodes)" in text
    assert "- hairpin, stochastic: P(tanh > gaussian) = 1.00 [1.00, 1.00]: decided" in text
    archived = tmp_path / "archive" / "car_learning" / "car_racing" / "tanh"
    assert (archived / "eval-hairpin-stochastic-50.json").exists()
    # kept in its summary: the archived metrics.csv has no entropy
    assert car_learning.final_std(archived) == "0.50"


def test_learned_hints_runs_only_the_parts_asked_for(tmp_path, monkeypatch):
    """--parts: each piece of a case alone (one per device lease), the generator first whenever
    it is missing; every piece in order by default."""
    import learned_hints

    calls = []
    monkeypatch.setattr(
        learned_hints,
        "train_generator",
        lambda runs, env, hint, k, s: calls.append("generator") or runs / "g",
    )
    monkeypatch.setattr(
        learned_hints, "train_agent", lambda runs, name, values: calls.append(name) or runs / name
    )
    monkeypatch.setattr(
        learned_hints, "deploy_with", lambda folder, source: calls.append(f"deploy {folder.name}")
    )
    learned_hints.run_case(tmp_path, "halfcheetah", "velocity", 2, 5, 5, ("ppo_rgb",))
    assert calls == ["generator", "halfcheetah-ppo_rgb"]
    calls.clear()
    learned_hints.run_case(tmp_path, "halfcheetah", "velocity", 2, 5, 5)
    assert calls == [
        "generator",
        "halfcheetah-velocity-programmatic",
        "deploy halfcheetah-velocity-programmatic",
        "halfcheetah-ppo_rgb",
        "halfcheetah-velocity-learned-k2",
    ]
    calls.clear()
    learned_hints.run_case(tmp_path, "pendulum", "composite", 2, 5, 5, ("ppo_rgb", "learned"))
    # the pendulum's PPO-RGB is archived
    assert calls == ["generator", "pendulum-composite-learned-k2"]


def test_learned_hints_compares_with_the_archived_ppo_rgb_or_trains_its_own(tmp_path):
    """experiments/learned_hints.py: the pendulum's PPO-RGB is its archived 20-seed row; the
    halfcheetah's table row predates the archive, so the case trains one beside it."""
    import learned_hints

    assert (
        learned_hints.rgb_folder(tmp_path, "pendulum")
        == learned_hints.PPO_RGB / "pendulum" / "ppo_rgb"
    )
    assert (learned_hints.rgb_folder(tmp_path, "pendulum") / "eval.json").is_file()
    assert learned_hints.rgb_folder(tmp_path, "halfcheetah") == tmp_path / "halfcheetah-ppo_rgb"


def test_set_gives_every_run_of_a_sweep_a_setting_and_bad_ones_are_one_line(tmp_path, capsys):
    """--set physics=warp --set seed=10 reach each run's values (and so its config.yaml: seeds
    10-19 of a row are a part of its own); what is not KEY=VALUE, or what RunConfig refuses, is
    one line and exit 2."""
    import argparse

    import cue_env  # noqa: F401  (tests/cue_env.py: the "cue" env and its hints)

    def parsed(*items: str) -> dict:
        parser = argparse.ArgumentParser()
        sweep_settings.add_settings(parser)
        return sweep_settings.chosen_settings(
            parser, parser.parse_args([f"--set={item}" for item in items])
        )

    assert parsed("physics=warp", "seed=10") == {"physics": "warp", "seed": 10}
    assert (
        sweep.run_values("ant", "ppo_rgb", 2, settings={"physics": "warp", "seed": 10})["physics"]
        == "warp"
    )
    for bad, message in [
        ("physics", "--set takes KEY=VALUE, got 'physics'"),
        ("physics=mujoco", "unknown physics 'mujoco'"),
        ("seedz=3", "unknown config keys ['seedz']"),
    ]:
        with pytest.raises(SystemExit) as exit_:
            parsed(bad)
        err = capsys.readouterr().err.strip().splitlines()
        assert exit_.value.code == 2 and len(err) == 1 and message in err[0], err
    sweep.train_one(
        tmp_path, ["cue/hints-fc-cue"], seeds=2, smoke=True, experts=None, settings={"seed": 10}
    )
    assert "seed: 10\n" in (tmp_path / "cue/hints-fc-cue" / "config.yaml").read_text()


WORKER_SETTINGS = """
import argparse, os, sys
from hintsjax.reproduce import sweep_settings
parser = argparse.ArgumentParser()
sweep_settings.add_settings(parser)
settings = sweep_settings.worker_settings(parser, parser.parse_args(sys.argv[1:]))
from jax._src import xla_bridge
print(xla_bridge.backends_are_initialized(), "--xla_gpu_deterministic_ops=false" in os.environ["XLA_FLAGS"].split())
"""  # noqa: E501


@pytest.mark.parametrize("physics, dropped", [("warp", True), ("jax", False)])
def test_a_warp_sweeps_worker_drops_deterministic_ops_before_jax_starts(physics, dropped):
    """The check of --set starts JAX's backend (it resolves the physics), so a Warp worker drops
    deterministic ops before it; a JAX worker keeps them."""
    import os
    import subprocess

    env = {
        k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "HINTSJAX_XLA_FLAGS_ADDED")
    }
    out = subprocess.run(
        [sys.executable, "-c", WORKER_SETTINGS, f"--set=physics={physics}"],
        env={**env, "JAX_PLATFORMS": "cpu"},
        cwd=Path(__file__).resolve().parents[1],
        capture_output=True,
        text=True,
        check=True,
    )
    assert out.stdout.split() == ["True", str(dropped)], out.stderr[-2000:]


def test_the_playground_side_by_side_gives_hintsjax_brax_s_settings_and_the_report_its_cells(
    tmp_path,
):
    """experiments/playground.py: Playground's published Brax PPO settings for CartpoleSwingup
    mapped onto hintsjax's (an update of batch_size x num_minibatches x unroll_length = 1024 x 32 x
    30 env steps over 2048 envs, minibatches of 1024 x 30, 16 epochs), a config hintsjax accepts;
    and the report's row of hand-written runs: IQMs and P(HINTS > PPO-RGB)."""
    pytest.importorskip(
        "mujoco_playground", reason="the Playground adapter needs the playground extra"
    )
    import playground

    from hintsjax.settings.layers import run_config

    values = playground.hintsjax_values(
        playground.brax_settings(smoke=False), seeds=5, steps=60_000_000, smoke=False
    )
    cfg = run_config(values)
    assert (
        cfg.ppo.batch_size,
        cfg.ppo.num_envs,
        cfg.ppo.rollout_length,
        cfg.ppo.minibatch_size,
        cfg.ppo.epochs,
    ) == (983_040, 2048, 480, 30_720, 16)
    assert (cfg.ppo.gamma, cfg.ppo.actor_lr, cfg.ppo.reward_scale, cfg.ppo.normalize_state) == (
        0.995,
        1e-3,
        10.0,
        True,
    )
    # 60 M steps in whole updates of 983,040
    assert cfg.agent == "ppo_state" and cfg.ppo.num_updates == 61
    # Brax clips no gradient unless told to (its max_grad_norm None; Playground's DM Control
    # settings name none)
    assert (
        "max_grad_norm" not in playground.brax_settings(smoke=False)
        and cfg.ppo.max_grad_norm == playground.NO_CLIP
    )
    assert (
        run_config(
            playground.hintsjax_values(
                {**playground.brax_settings(False), "max_grad_norm": 1.0}, 5, 60_000_000, False
            )
        ).ppo.max_grad_norm
        == 1.0
    )
    runs = tmp_path / "playground"
    env = "playground:CartpoleSwingup"
    write_run(runs, env, "ppo_rgb", [evaluation(100.0, 10.0, [90.0, 95.0, 100.0, 105.0, 110.0])])
    write_run(
        runs,
        env,
        "hints-fc-pole_angle",
        [evaluation(300.0, 10.0, [280.0, 290.0, 300.0, 310.0, 320.0])],
    )
    out = tmp_path / "playground.md"
    playground.report(runs, True, out)
    row = next(
        line for line in out.read_text().splitlines() if line.startswith("| CartpoleSwingup")
    )
    assert (
        "| 100.0 [" in row
        and "| 300.0 [" in row
        and "P(HINTS > PPO-RGB) = 1.00 [1.00, 1.00]: decided" in row
    )
    # playground_vision.py's section below it stays when the report is written again
    section = markdown.generated_marker("playground_vision.py", "--report")
    markdown.write_section(out, section, ["## Pixel PPO", "", "its cells"])
    before = out.read_text()
    assert before.count(section) == 1 and before.endswith(
        f"{section}\n\n## Pixel PPO\n\nits cells\n"
    )
    playground.report(runs, True, out)
    assert out.read_text() == before


def test_the_side_by_side_holds_brax_to_the_same_updates_and_reports_both_sides(tmp_path):
    """Brax's `train` runs num_evals_after_init x max(num_resets_per_eval, 1) x ceil(num_timesteps /
    (that product x env steps per training step)) training steps
    (brax/training/agents/ppo/train.py): `brax_schedule` makes that exactly the updates hintsjax
    takes, for any count (Playground's own 10 and 10 gave 90 for 61); and the report puts both
    sides' returns, steps and rates in one table."""
    import math

    import playground

    for updates in range(1, 130):
        s = playground.brax_schedule(updates)
        after_init, resets = max(s["num_evals"] - 1, 1), max(s["num_resets_per_eval"], 1)
        assert after_init * resets * math.ceil(updates / (after_init * resets)) == updates, (
            updates,
            s,
        )
    assert playground.brax_schedule(61) == {"num_evals": 2, "num_resets_per_eval": 61}
    side = lambda trainer, steps, det, seconds: {  # noqa: E731
        "trainer": trainer,
        "env_steps_per_seed": steps,
        "deterministic": det,
        "stochastic": det,
        "seconds": seconds,
        "eval_episodes": 128,
        "device": "NVIDIA H200",
        "date": "2026-11-28 21:40",
        "command": "python x",
    }
    record = {
        "task": "CartpoleSwingup",
        "seeds": 3,
        "updates": 2,
        "env_steps_per_seed": 2000,
        "smoke": False,
        "results": {
            "hintsjax": side("hintsjax ppo_state", 2000, [800.0, 810.0, 820.0], 10.0),
            "brax": side("brax.training ppo", [2000, 2000, 2000], [500.0, 510.0, 520.0], 60.0),
        },
    }
    (tmp_path / playground.VERSUS_JSON).write_text(json.dumps(record))
    text = "\n".join(playground.versus_lines(tmp_path))
    assert "3 seeds x 2 updates of 1,000 env steps (2,000 a seed)" in text
    # 6,000 steps in 10 s
    assert "| hintsjax ppo_state | 2,000 | 810.0 [" in text and "| 10 | 600 |" in text
    assert "| brax.training ppo | 2,000 | 510.0 [" in text and "| 60 | 100 |" in text
    assert text.count("P(hintsjax ppo_state > brax.training ppo) = 1.00 [1.00, 1.00]: decided") == 2


def test_locomotion_learners_report_gives_each_ordering_its_verdict(tmp_path, monkeypatch):
    """Table 3 at any seed count (`--learners-report`), on hand-written halfcheetah runs of 6 seeds:
    the state hint's seeds all lie above PPO-RGB's (O1 decided for) and all below PPO on the state
    (O4 decided against), and the reward hint's interleave with the state hint's (O5 undecided);
    the plan above the marker is kept, and a row not trained reads '-'."""
    import locomotion

    monkeypatch.setattr(archive, "ARCHIVE", tmp_path / "archive")
    monkeypatch.setattr(locomotion, "ARCHIVE", tmp_path / "archive")
    monkeypatch.setattr(locomotion, "RESULTS", tmp_path)
    runs = tmp_path / "runs" / "t20"
    seeds = {
        "ppo_rgb": [0.0, 10, 20, 30, 40, 50],
        "ppo_state": [900.0, 910, 920, 930, 940, 950],
        "hints-fc-state": [500.0, 510, 520, 530, 540, 550],
        "hints-fc-reward": [495.0, 505, 515, 525, 535, 545],
        "hints-fc-velocity": [100.0, 110, 120, 130, 140, 150],
    }
    for label, means in seeds.items():
        write_run(runs, "halfcheetah", label, [evaluation(float(np.mean(means)), 10.0, means)])
    path = tmp_path / "table3.md"
    path.write_text(f"# The plan\n\nRows and budgets.\n\n{locomotion.GENERATED}\n\nstale table\n")
    locomotion.learners_report(runs, ["halfcheetah"], path)
    text = path.read_text()
    assert text.startswith("# The plan\n\nRows and budgets.\n") and "stale table" not in text
    assert "halfcheetah (1 M env steps per seed, 6 seeds per row)" in text
    assert (
        "- O1 (hints beat vision only): P(hints-fc-state > ppo_rgb) = 1.00 [1.00, 1.00]: decided "
        "for" in text
    )
    assert (
        "- O4 (hints close the gap to PPO on the state): P(hints-fc-state > ppo_state) = 0.00 "
        "[0.00, 0.00]: decided against" in text
    )
    assert "P(hints-fc-reward > hints-fc-state) = 0.4" in text and text.count(": undecided") == 1
    assert "| hints-fc-max_velocity | - | - | - |" in text  # not trained
    locomotion.learners_report(runs, ["halfcheetah"], path)
    assert path.read_text() == text  # the report rewrites only its own part


def test_car_learners_report_gives_o1_and_o3_their_verdicts_beside_the_locomotion_section(
    tmp_path, monkeypatch
):
    """The car's Table 3 at any seed count, on hand-written runs of 6 seeds: on standard tracks the
    on_track hint's seeds all lie above PPO-RGB's (O1 decided for, the best hint by IQM), on
    hairpins the composite's all lie below (O3 decided against), and the progress difference reads
    as the car's findings do. The car's section and the locomotion section share one file: each
    rewrite keeps the other section and the plan above both, and changes nothing on a second run."""
    import car_racing
    import locomotion

    for module in (archive, car_racing, locomotion):
        monkeypatch.setattr(module, "ARCHIVE", tmp_path / "archive")
    for module in (car_racing, locomotion):
        monkeypatch.setattr(module, "RESULTS", tmp_path)
    runs = tmp_path / "runs" / "t20"
    seeds = {  # label: (standard seed means, hairpin seed means, hairpin progress seed means)
        "ppo_rgb": (
            [100.0, 110, 120, 130, 140, 150],
            [300.0, 310, 320, 330, 340, 350],
            [0.50, 0.52, 0.54, 0.56, 0.58, 0.60],
        ),
        "hints-mc-on_track": (
            [400.0, 410, 420, 430, 440, 450],
            [305.0, 315, 325, 335, 345, 355],
            [0.5] * 6,
        ),
        "hints-mc-composite": (
            [200.0, 210, 220, 230, 240, 250],
            [0.0, 10, 20, 30, 40, 50],
            [0.30, 0.32, 0.34, 0.36, 0.38, 0.40],
        ),
    }
    for label, (standard, hairpin, progress) in seeds.items():
        write_run(
            runs,
            "car_racing",
            label,
            [
                evaluation(float(np.mean(standard)), 10.0, standard),
                evaluation(
                    float(np.mean(hairpin)),
                    10.0,
                    hairpin,
                    progress_mean=float(np.mean(progress)),
                    progress_std=0.1,
                    progress_seed_means=progress,
                ),
            ],
        )
    write_run(runs, "halfcheetah", "ppo_rgb", [evaluation(5.0, 1.0, [4.0, 6.0])])
    path = tmp_path / "table3.md"
    path.write_text("# The plan\n\nRows and budgets.\n")
    locomotion.learners_report(runs, ["halfcheetah"], path)
    car_racing.learners_report(runs, ["car_racing"], path)
    text = path.read_text()
    loco, car = text.index(locomotion.GENERATED), text.index(car_racing.GENERATED)
    assert text.startswith("# The plan\n\nRows and budgets.\n") and loco < car
    assert "halfcheetah (1 M env steps per seed, 2 seeds per row)" in text[loco:car]
    section = text[car:]
    assert (
        "car_racing (1 M env steps per seed, 6 seeds per row)" in section
        and "halfcheetah" not in section
    )
    assert (
        "- O1 (hints beat vision only; standard tracks): P(hints-mc-on_track > ppo_rgb) = 1.00 "
        "[1.00, 1.00]: decided for"
    ) in section
    assert (
        "- O3 (composite hints carry the car round hairpins; hairpin tracks): P(hints-mc-composite "
        "> ppo_rgb) = 0.00 [0.00, 0.00]: decided against"
    ) in section
    assert "Composite minus vision only: -20.0 points" in section and ": decided." in section
    assert "| hints-mc-curvature | - | - | - | - | - | - |" in section  # not trained
    assert "| hints-mc-on_track | 425.0 [" in section and "| 1.00 [1.00, 1.00] | - | " in section
    locomotion.learners_report(runs, ["halfcheetah"], path)
    assert path.read_text() == text  # the locomotion rewrite keeps the car's section
    car_racing.learners_report(runs, ["car_racing"], path)
    assert path.read_text() == text


def test_archive_flag_archives_the_finished_runs_and_nothing_else(tmp_path, monkeypatch, capsys):
    """`--archive` (what a GPU machine runs before sending its runs back): the finished run's
    eval.json, config and binned curve go to the archive; the unfinished run and no report do."""
    import locomotion

    monkeypatch.setattr(archive, "ARCHIVE", tmp_path / "archive")
    runs = tmp_path / "runs" / "t20"
    write_run(
        runs,
        "ant",
        "ppo_rgb",
        [evaluation(5.0, 1.0, [4.0, 6.0])],
        returns=[[1.0, 2.0, 3.0], [2.0, 3.0, 4.0]],
    )
    (runs / "ant" / "ppo_rgb" / "config.yaml").write_text("env: ant\n")
    write_run(runs, "ant", "ppo_state", returns=[[1.0, 2.0]])  # not finished: no eval.json
    monkeypatch.setattr(sys, "argv", ["locomotion.py", "--archive", "--runs", str(runs)])
    locomotion.main()
    archived = tmp_path / "archive" / "t20"
    assert sorted(p.name for p in (archived / "ant").iterdir()) == ["ppo_rgb"]
    assert sorted(p.name for p in (archived / "ant" / "ppo_rgb").iterdir()) == [
        "config.yaml",
        "eval.json",
        "metrics.csv",
        "summary.json",
    ]
    assert "archived 1 finished run(s)" in capsys.readouterr().out


def test_physics_learning_pools_the_seeds_of_several_runs_and_compares_training_at_equal_steps(
    tmp_path,
):
    """experiments/physics_learning.py with about.json's `arms`: jax's two 5-seed runs pooled into
    10 seeds against warp's one, the evaluation compared (every warp seed 100 below: decided), and
    the training return taken over the last 10 % of the env steps that both physics reached: a warp
    run cut at 10 updates is compared with jax's updates 10 and 9 (steps 9216 to 10240), not with
    jax's end."""
    import physics_learning

    runs = tmp_path / "physics"
    jax_returns = [[float(u) for u in range(20)]] * 5  # return = the update's index, every seed
    write_run(
        runs,
        "ant",
        "jax-s0",
        [evaluation(1000.0, 5.0, [1000.0 + i for i in range(5)])],
        returns=jax_returns,
    )
    write_run(
        runs,
        "ant",
        "jax-s5",
        [evaluation(1000.0, 5.0, [1005.0 + i for i in range(5)])],
        returns=jax_returns,
    )
    write_run(
        runs,
        "ant",
        "warp",
        [evaluation(900.0, 5.0, [900.0 + i for i in range(10)])],
        returns=[[float(u) for u in range(10)]] * 10,
    )
    (runs / "about.json").write_text(
        json.dumps(
            {
                "what": "test",
                "hardware": "none",
                "date": "today",
                "commands": {},
                "notes": [],
                "arms": {"ant": {"jax": ["ant/jax-s0", "ant/jax-s5"], "warp": ["ant/warp"]}},
            }
        )
    )
    lines = physics_learning.report(runs)
    evaluation_row = next(
        line
        for line in lines
        if line.startswith("| ant |") and "10 / 10" in line and "none / none" in line
    )
    assert evaluation_row.endswith("| - / - |")  # no approx_kl logged: no record of storms
    assert (
        "1004.5 [" in evaluation_row
        and "904.5 [" in evaluation_row
        and "0.00 [0.00, 0.00]" in evaluation_row
    )
    assert (
        "- ant, evaluation: decided: warp scores below jax (the difference's interval excludes 0)"
        in lines
    )
    training_row = next(line for line in lines if line.startswith("| ant | 10,240 |"))
    # both physics: update 9's return (steps 10240), the window's one
    assert training_row.count("9.0 [9.0, 9.0]") == 2
    assert training_row.endswith("| - / - |")  # no entropy logged
    metrics = runs / "ant" / "warp" / "metrics.csv"
    rows = list(csv.DictReader(metrics.open()))
    # seeds 0-2: the entropy rises after update 0; the others: it falls
    with metrics.open("w", newline="") as f:
        writer = csv.DictWriter(f, [*rows[0], "entropy"])
        writer.writeheader()
        writer.writerows(
            {**r, "entropy": 11.0 + (1 if int(r["seed"]) < 3 else -1) * int(r["update"])}
            for r in rows
        )
    training_row = next(
        line for line in physics_learning.report(runs) if line.startswith("| ant | 10,240 |")
    )
    assert training_row.endswith("| - / 3 of 10 |")
    (runs / "ant" / "jax-s5" / "eval.json").unlink()  # a run brought back before its evaluation
    lines = physics_learning.report(runs)
    assert any(line.startswith("| ant | - | - | - | 904.5 [") for line in lines)
    assert not any(line.startswith("- ant, evaluation") for line in lines)


def test_kl_storms_are_counted_per_seed_and_kept_in_the_archive(tmp_path, monkeypatch):
    """A storm is STORM_UPDATES updates in a row with approx. KL above KL_ABOVE: seed 0 has one of
    15 updates from update 101 (inf counts as above) and a burst of 6 later; seed 1 only bursts, so
    no storm. archive_run keeps them in summary.json, which the archived run answers from."""
    from hintsjax.settings import layers

    monkeypatch.setattr(archive, "ARCHIVE", tmp_path / "archive")
    runs = tmp_path / "runs"
    write_run(runs, "ant", "hints", [evaluation(1.0, 0.0, [1.0, 1.0])], [[0.0] * 300, [0.0] * 300])
    layers.save_run_config(runs / "ant" / "hints", layers.run_config({"env": "ant"}))
    path = runs / "ant" / "hints" / "metrics.csv"
    rows = list(csv.DictReader(path.open()))
    for row in rows:
        update, seed = int(row["update"]) + 1, int(row["seed"])  # write_run numbers updates from 0
        hot = (seed == 0 and (101 <= update <= 115 or 200 <= update <= 205)) or (
            seed == 1 and update % 7 < 5
        )
        row["approx_kl"] = ("inf" if update == 110 else 0.9) if hot else 0.01
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    rows = list(csv.DictReader(path.open()))
    # seed 1, update 12, after a burst of 5: a NaN KL is not a blown-up update
    rows[300 + 11]["approx_kl"] = "nan"
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, list(rows[0]))
        writer.writeheader()
        writer.writerows(rows)
    expected = [{"first": 101, "longest": 15}, {"first": None, "longest": 5}]
    assert archive.kl_storms(runs / "ant" / "hints") == expected
    dest = archive.archive_run(runs, "ant", "hints")
    assert json.loads((dest / "summary.json").read_text())["kl_storms"] == expected
    assert archive.kl_storms(dest) == expected
    assert archive.kl_storms(tmp_path / "nowhere") is None
    # a run cut short keeps its log and storms, and no evaluation
    (runs / "ant" / "hints" / "eval.json").unlink()
    dest = archive.archive_run(runs, "ant", "hints")
    assert not (dest / "eval.json").exists() and archive.kl_storms(dest) == expected


def test_kl_storms_compares_arms_at_equal_updates(tmp_path, capsys, monkeypatch):
    """experiments/kl_storms.py --at N: a storm counts once its STORM_UPDATES-th update is logged by
    N; each seed's return is its episodes' mean over updates N-99..N; Fisher's one-sided p is the
    hypergeometric tail (scipy's fisher_exact the oracle); a log that ends before N is refused."""
    import kl_storms
    from scipy.stats import fisher_exact

    def run(name, kl, returns):  # kl [seeds][updates], one episode_return a seed (updates from 1)
        folder = tmp_path / name
        folder.mkdir()
        with (folder / "metrics.csv").open("w", newline="") as f:
            writer = csv.writer(f)
            writer.writerow(["update", "seed", "env_steps", "episode_return", "approx_kl"])
            writer.writerows(
                [u + 1, s, 1024 * (u + 1), returns[s](u + 1), kl[s][u]]
                for s in range(len(kl))
                for u in range(200)
            )
        return folder

    hot = [0.9 if 101 <= u <= 130 else 0.01 for u in range(1, 201)]
    base = run("base", [hot, [0.01] * 200], [lambda u: float(u), lambda u: "nan" if u % 2 else 7.0])
    calm = run("calm", [[0.01] * 200] * 2, [lambda u: 1000.0, lambda u: 2000.0])
    assert kl_storms.stormed_by(base, 109) == [False, False] and kl_storms.stormed_by(
        base, 110
    ) == [True, False]
    assert kl_storms.returns_by(base, 150) == [np.mean(np.arange(51, 151)), 7.0]
    lines = kl_storms.arms_report({"base": [base], "calm": [calm]}, 150)
    assert lines[-2].startswith("| base | base | 2 | 1 | - | ")
    assert lines[-1].startswith(
        "| calm | calm | 2 | 0 | 0.5 | 1500 [1000, 2000] | P(calm > base) = 1.00 "
    )
    for hits, n, base_hits, base_n in ((0, 10, 8, 20), (2, 10, 8, 20), (3, 5, 1, 7), (0, 1, 0, 3)):
        oracle = fisher_exact(
            [[hits, n - hits], [base_hits, base_n - base_hits]], alternative="less"
        )[1]
        assert kl_storms.fisher_fewer(hits, n, base_hits, base_n) == pytest.approx(oracle)
    with pytest.raises(SystemExit, match="ends at update 200, before --at 201"):
        kl_storms.returns_by(base, 201)
    # the final evaluation, where every run of the arms ended at N and was evaluated; '-' otherwise
    for folder, means in ((base, [10.0, 20.0]), (calm, [1000.0, 3000.0])):
        (folder / "eval.json").write_text(json.dumps({"evaluations": [{"seed_means": means}]}))
    assert (
        kl_storms.evaluation_by(calm, 200) == [1000.0, 3000.0]
        and kl_storms.evaluation_by(calm, 150) is None
    )
    assert lines[-1].endswith("| - | - |")
    lines = kl_storms.arms_report({"base": [base], "calm": [calm]}, 200)
    assert lines[-2].endswith("| 15 [10, 20] | - |")
    assert "| 2000 [1000, 3000] | P(calm > base) = 1.00 " in lines[-1]
    (base / "eval.json").unlink()  # one arm cut short: neither arm's evaluation is compared
    lines = kl_storms.arms_report({"base": [base], "calm": [calm]}, 200)
    assert lines[-2].endswith("| - | - |") and lines[-1].endswith("| 2000 [1000, 3000] | - |")
    monkeypatch.setattr(sys, "argv", ["kl_storms.py", "--at", "150", "--arm", f"base={base}"])
    with pytest.raises(SystemExit):
        kl_storms.main()
    assert "two or more --arm" in capsys.readouterr().err


def test_a_resumed_sweep_run_keeps_the_physics_it_began_with(tmp_path):
    """sweep.saved_physics: what a run folder's config.yaml trained with (jax where it predates the
    setting), so a sweep resumed after auto changed its mind goes on as it began; no folder: the
    default."""
    assert sweep.saved_physics(tmp_path / "nowhere", "auto") == "auto"
    for saved, physics in (
        ("physics: jax\n", "jax"),
        ("physics: warp\n", "warp"),
        ("env: pendulum\n", "jax"),
    ):
        (tmp_path / "config.yaml").write_text(saved)
        assert sweep.saved_physics(tmp_path, "auto") == physics


def test_the_privileged_baselines_report_sets_hints_fc_against_each_baseline(tmp_path, monkeypatch):
    """privileged_baselines.py: an env's five rows (their labels parse back to their agents) and the
    learned generator's row; P(HINTS-FC > row) with its verdict (hand values: every HINTS-FC seed
    beats every PPO-RGB seed, P = 1 decided; asym_ac's seeds interleave with HINTS-FC's, P = 0.5,
    undecided); what each row needs at deployment."""
    import privileged_baselines as pb

    from hintsjax.settings.layers import run_config

    assert pb.labels("pendulum") == [
        "ppo_rgb",
        "asym_ac-composite",
        "pi_dropout-fc-composite",
        "hint_aux-composite",
        "hints-fc-composite",
    ]
    for run_id in pb.run_ids(["pendulum", "ant"]):
        env, label = run_id.split("/")
        cfg = run_config(sweep.run_values(env, label, 2))
        assert cfg.label == label and (label == "ppo_rgb" or cfg.hint == pb.SIGNAL[env]), run_id
    # a name the archive lacks: no row falls back to archived runs
    runs = tmp_path / "privileged_handmade"
    seeds = {
        "ppo_rgb": [-1300.0, -1200.0, -1250.0, -1400.0],
        "asym_ac-composite": [-260.0, -190.0, -310.0, -210.0],
        "hints-fc-composite": [-250.0, -200.0, -300.0, -220.0],
    }
    for label, means in seeds.items():
        write_run(runs, "pendulum", label, [evaluation(float(np.mean(means)), 10.0, means)] * 2)
    monkeypatch.setattr(pb, "OUT", tmp_path / "privileged_baselines.md")
    monkeypatch.setattr(pb, "LEARNED", tmp_path / "learned")
    write_run(
        tmp_path / "learned",
        ".",
        "pendulum-composite-learned-k2",
        [evaluation(-400.0, 10.0, [-400.0, -410.0])],
    )
    pb.report(runs)
    text = (tmp_path / "privileged_baselines.md").read_text()
    assert (
        "| PPO-RGB | nothing | pictures | -1287.5 ± 74.0 |" in text
        and "| 1.00 [1.00, 1.00] decided for | - |" in text
    )
    asym = next(
        line for line in text.splitlines() if line.startswith("| asymmetric actor-critic |")
    )
    assert "| 0.50 [" in asym and asym.endswith("undecided | 1.00 [1.00, 1.00] decided for |")
    assert (
        "| hint input dropout (FiLM) | the policy, dropped with p = ppo.hint_dropout | pictures "
        "| - |" in text
    )
    # the learned generator against the baselines with runs, not the blank row
    learned = next(line for line in text.splitlines() if line.startswith("P(learned generator"))
    assert "asymmetric actor-critic " in learned and "dropout" not in learned, learned
    hints_row = next(
        line
        for line in text.splitlines()
        if line.startswith("| HINTS-FC | the policy and the critic |")
    )
    assert hints_row.endswith("| 4 | - | 1.00 [1.00, 1.00] decided for |")
    assert "| HINTS-FC, learned generator | " in text and "| -405.0 ± 5.0 |" in text
    assert "## ant" not in text


def test_the_privileged_baselines_report_rebuilds_the_committed_file_on_a_fresh_checkout(
    tmp_path, monkeypatch
):
    """`python experiments/privileged_baselines.py --report` with no runs/privileged reads the
    archived runs (experiments/results/runs/privileged) and writes the committed file, byte for
    byte."""
    import privileged_baselines as pb

    committed = pb.OUT.read_text()
    monkeypatch.setattr(pb, "OUT", tmp_path / "privileged_baselines.md")
    monkeypatch.chdir(tmp_path)
    pb.report(Path("runs/privileged"))
    assert (tmp_path / "privileged_baselines.md").read_text() == committed
