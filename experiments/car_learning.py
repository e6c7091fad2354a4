"""How the car learns under each policy head and reward scale (issue 26, item 2).

    python experiments/car_learning.py [--variants gaussian,tanh,sigmoid] [--seeds 5]
        # train (GPU); resumable
    python experiments/car_learning.py --report     # -> experiments/results/car_learning.md

Each variant is PPO-RGB on the car at its table's budget (ENV_DEFAULTS: 1000 episodes of 1000
steps) with a few settings changed (`VARIANTS`), trained by `python -m hintsjax.run` into
<runs>/car_racing/<variant> (a folder with checkpoints and no eval.json resumes; the variants that
differ only in numbers, the reward scale, train as one group: one program), then evaluated
as the run does (deterministic: the policy's mean; standard tracks and the hairpin deploy) and with
sampled actions, the authors' protocol (`python -m hintsjax.evaluate <folder> --stochastic`, both
tracks). The report gives per variant and evaluation the IQM [95% CI] of the per-seed mean
returns, the progress P, the training return (the last tenth of updates), the policy's std at the
end (from the logged entropy), and each variant against the first (`gaussian`, the defaults) as a
probability of improvement. `--report` archives the finished runs
(experiments/results/runs/car_learning).
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import shutil
from pathlib import Path

import numpy as np
from hintsjax.reproduce.archive import (
    ARCHIVE,
    SUMMARY_JSON,
    about_lines,
    archive_run,
    read_about,
    run_folder,
    training_seed_means,
)
from hintsjax.reproduce.markdown import markdown_table
from hintsjax.reproduce.report import iqm_cell, load, metric_cell, ordering, training_cell

RESULTS = Path(__file__).resolve().parent / "results"
ENV, AGENT = "car_racing", "ppo_rgb"
# Each variant's settings over the car's defaults (and STUDY's); the first is the reference the
# others are compared with. The heads are named, not left to the defaults, which these measurements
# chose (the sigmoid).
VARIANTS: dict[str, dict] = {
    # a Gaussian whose draws the env clips (gas and brake into [0, 1])
    "gaussian": {"ppo": {"action_head": "gaussian"}},
    "tanh": {"ppo": {"action_head": "tanh"}},  # squashed into the action range: nothing clipped
    # the authors' head: mean 2 sigmoid(x) - 1, std >= 0.01
    "sigmoid": {"ppo": {"action_head": "sigmoid"}},
    # rewards scaled for learning
    "gaussian-reward0.1": {"ppo": {"action_head": "gaussian", "reward_scale": 0.1}},
}
# Every variant's run evaluates with the policy's mean (its eval.json); the sampled evaluation is
# hintsjax.evaluate's, beside it.
STUDY = {"stochastic_eval": False}
STD_KEY = "policy_std_end"  # final_std's value, kept in an archived run's summary
# evaluations[0] and [1]: the training task, then the car's eval_variants
TRACKS = ("standard", "hairpin")
SMOKE = {
    "eval_episodes": 2,
    "ppo": {
        "total_env_steps": 2048,
        "num_envs": 8,
        "batch_size": 1024,
        "minibatch_size": 512,
        "epochs": 1,
    },
}


def stochastic_file(folder: Path, track: str) -> Path | None:
    """The run's stochastic evaluation on `track` (hintsjax.evaluate's file), if made."""
    found = sorted(folder.glob(f"eval-{track}-stochastic-*.json"))
    return found[-1] if found else None


def variant_settings(name: str, seeds: int, smoke: bool) -> dict:
    """A variant's run settings (RunConfig's values)."""
    values = {"env": ENV, "agent": AGENT, "seeds": seeds, **STUDY, **VARIANTS[name]}
    if smoke:
        values = {**values, **SMOKE, "ppo": {**SMOKE["ppo"], **VARIANTS[name].get("ppo", {})}}
    return values


def train(runs: Path, names: list[str], seeds: int, smoke: bool) -> None:
    """Train and evaluate each variant not finished yet (both evaluations); resumable. Variants
    that differ only in numbers (the reward scale: hintsjax.algorithms.group's Hyper) train as one
    group, in one program (<runs>/car_racing/_groups/<names>); the policy heads each need their
    own."""
    from hintsjax.system import checkpoint
    from hintsjax.settings.layers import run_config, save_run_config
    from hintsjax.algorithms.group import plan
    from hintsjax.training import pipeline
    from hintsjax import evaluate, run

    cfgs = [run_config(variant_settings(n, seeds, smoke)) for n in names]
    # a group with one member finished (cut while writing results) resumes whole
    for members in plan(cfgs):
        group = [names[i] for i in members]
        if all((runs / ENV / n / "eval.json").exists() for n in group):
            continue
        if len(group) == 1:
            folder = runs / ENV / group[0]
            values = (
                {"resume": str(folder)}
                if (folder / "config.yaml").exists()
                else {
                    **variant_settings(group[0], seeds, smoke),
                    "out_dir": str(runs / ENV),
                    "name": group[0],
                }
            )
            if run.main_from_values(values):
                raise SystemExit(f"{group[0]}: training failed (see above)")
            continue
        folder = runs / ENV / "_groups" / "+".join(group)
        for i in members:
            (runs / ENV / names[i]).mkdir(parents=True, exist_ok=True)
            save_run_config(runs / ENV / names[i], cfgs[i])
        pipeline.train_group(
            [cfgs[i] for i in members],
            folder,
            [runs / ENV / n for n in group],
            resume=checkpoint.latest_update(folder) is not None,
        )
    for name in names:
        folder = runs / ENV / name
        # one program for both
        missing = [track for track in TRACKS if stochastic_file(folder, track) is None]
        if missing and evaluate.main([str(folder), "--stochastic", "--variant", ",".join(missing)]):
            raise SystemExit(f"{name}: the stochastic evaluation on {', '.join(missing)} failed")


def final_std(folder: Path) -> str:
    """The policy's std at the end (geometric mean over the actions, mean over seeds), from the
    entropy of the last logged update of each seed: H = sum(log std) + A/2 (1 + log 2 pi); an
    archived run keeps it in its summary (its metrics.csv keeps the returns only)."""
    kept = folder / SUMMARY_JSON
    if kept.exists() and STD_KEY in (summary := json.loads(kept.read_text())):
        return summary[STD_KEY]
    path = folder / "metrics.csv"
    if not path.exists():
        return "-"
    last: dict[str, float] = {}
    with open(path) as f:
        for row in csv.DictReader(f):
            if row.get("entropy") not in (None, "", "nan"):
                last[row["seed"]] = float(row["entropy"])
    if not last:
        return "-"
    actions = 3  # steer, gas, brake
    stds = [math.exp(h / actions - 0.5 * (1.0 + math.log(2 * math.pi))) for h in last.values()]
    return f"{np.mean(stds):.2f}"


def evaluation_of(folder: Path, track: int, stochastic: bool) -> dict | None:
    """An eval.json-shaped result whose evaluations[0] is the run's on `track`: from its eval.json
    (deterministic) or hintsjax.evaluate's file (stochastic); None when not made."""
    path = stochastic_file(folder, TRACKS[track]) if stochastic else folder / "eval.json"
    if path is None or not path.exists():
        return None
    data = json.loads(path.read_text())
    return {"evaluations": [data if stochastic else data["evaluations"][track]]}


def report(runs: Path, out: Path) -> None:
    from hintsjax.reproduce import stats

    names = [n for n in VARIANTS if load(runs, ENV, n) is not None]
    for name in names:  # the archive keeps what the report reads, the stochastic evaluations too
        if (runs / ENV / name / "eval.json").exists():
            dest = archive_run(runs, ENV, name)
            summary = json.loads((dest / SUMMARY_JSON).read_text())
            (dest / SUMMARY_JSON).write_text(
                json.dumps({**summary, STD_KEY: final_std(runs / ENV / name)}) + "\n"
            )
            for track in TRACKS:
                if (found := stochastic_file(runs / ENV / name, track)) is not None:
                    shutil.copyfile(found, dest / found.name)
    header = [
        "variant",
        "settings",
        *(f"{t}, {m}" for t in TRACKS for m in ("deterministic", "stochastic")),
        "P hairpin (det.)",
        "training return",
        "policy std at the end",
    ]
    rows, comparisons = [], []
    for name in names:
        folder = run_folder(runs, ENV, name)
        cells = [
            iqm_cell(evaluation_of(folder, t, s)) for t in range(len(TRACKS)) for s in (False, True)
        ]
        rows.append(
            [
                name,
                json.dumps(VARIANTS[name]) if VARIANTS[name] else "defaults",
                *cells,
                metric_cell(load(runs, ENV, name), "progress", 1, percent=True),
                training_cell(runs, ENV, name),
                final_std(folder),
            ]
        )
    reference = names[0] if names else None
    first = (
        load(runs, ENV, reference)["evaluations"][0]
        if names
        else {"seeds": 0, "episodes_per_seed": 0}
    )
    for name in names[1:]:
        for t, track in enumerate(TRACKS):
            for stochastic in (False, True):
                a = evaluation_of(run_folder(runs, ENV, name), t, stochastic)
                b = evaluation_of(run_folder(runs, ENV, reference), t, stochastic)
                text = ordering(name, a, reference, b)
                if text:
                    comparisons.append(
                        f"- {track}, {'stochastic' if stochastic else 'deterministic'}: {text}"
                    )
        trained = [training_seed_means(run_folder(runs, ENV, n)) for n in (name, reference)]
        if None not in trained:  # the training episodes (sampled actions, last tenth of updates)
            comparisons.append(
                f"- training return: {stats.ordering_text(name, reference, stats.poi_ci(*trained))}"
            )
    lines = [
        "# The car's learning side: action heads, evaluation protocol, reward scale (issue 26)",
        "",
        "PPO-RGB on the car at its table's budget, one row per variant "
        "(`experiments/car_learning.py`); cells: IQM [95% CI] of the per-seed mean returns "
        f"({first['seeds']} seeds x {first['episodes_per_seed']} evaluation episodes). "
        "Deterministic: the policy's mean; stochastic: sampled actions (the authors' protocol). "
        f"Runs: experiments/results/runs/{runs.name}.",
        "",
        *markdown_table(header, rows),
        "",
        f"Each variant against `{reference}` (probability of improvement over seeds, 95% bootstrap "
        "interval; decided where it excludes 0.5):",
        "",
        *comparisons,
        "",
    ]
    lines += about_lines(read_about(ARCHIVE / runs.name))
    out.write_text("\n".join(lines))
    print(f"wrote {out}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--variants",
        default=",".join(VARIANTS),
        help=f"comma-separated subset of {', '.join(VARIANTS)}",
    )
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--runs", type=Path, default=Path("runs/car_learning"))
    parser.add_argument(
        "--smoke", action="store_true", help="tiny budgets: check the plumbing on a CPU"
    )
    parser.add_argument(
        "--report",
        action="store_true",
        help="only write the report (and archive the finished runs)",
    )
    parser.add_argument("--out", type=Path, default=RESULTS / "car_learning.md")
    args = parser.parse_args()
    names = [n for n in args.variants.split(",") if n]
    unknown = [n for n in names if n not in VARIANTS]
    if unknown or not names:
        parser.exit(2, f"error: unknown variant {unknown}; valid choices: {', '.join(VARIANTS)}\n")
    if args.seeds < 1:
        parser.exit(2, f"error: --seeds must be at least 1, got {args.seeds}\n")
    if args.report:
        report(args.runs, args.out)
    else:
        train(args.runs, names, args.seeds, args.smoke)


if __name__ == "__main__":
    main()
