"""PPO's KL storms, seed by seed, beside each seed's evaluation: which seeds had one, where the
first began and how long the longest lasted (experiments/results/locomotion_ppo_stability.md).

    python experiments/kl_storms.py RUN [RUN ...] [--out FILE.md]
    python experiments/kl_storms.py --at N --arm NAME=RUN[,RUN ...] --arm ... [--out FILE.md]

RUN: a run folder (its metrics.csv and eval.json) or an archived one (the storms kept in its
summary.json by hintsjax.reproduce.archive). A storm is archive.STORM_UPDATES or more updates in
a row whose approx. KL (the mean over the update's minibatch steps) exceeds archive.KL_ABOVE: with
the KL early stop on, each of them is the update's first minibatch step alone.

With --at N, arms (each the seeds of its runs pooled) are compared as far as update N, so that a
run cut short stands beside full ones at equal steps: the seeds whose first storm had begun by
N (beside the first arm's, with Fisher's exact one-sided p that the arm has no more storms by
chance), and each seed's training return over updates N-99..N, IQM [95% CI] and P(arm > first arm).
Where N is every run's last update and each was evaluated (eval.json), the final evaluation's seed
means are compared too; an arm with a run cut short shows '-' there.
"""

from __future__ import annotations

import argparse
import json
import math
from pathlib import Path

import numpy as np

from hintsjax.reproduce.archive import KL_ABOVE, STORM_UPDATES, kl_storms
from hintsjax.reproduce.stats import iqm_cell, ordering_text, poi_ci
from hintsjax.training.runlog import read_log

SPAN = 100  # updates before --at whose training episodes give a seed's return there


def row(folder: Path) -> str:
    """One run's markdown row."""
    storms = kl_storms(folder)
    evaluation = (
        json.loads((folder / "eval.json").read_text())["evaluations"][0]
        if (folder / "eval.json").exists()
        else None
    )
    means = ", ".join(f"{m:.0f}" for m in evaluation["seed_means"]) if evaluation else "-"
    below = ", ".join(str(s) for s in evaluation.get("outlier_seeds", [])) if evaluation else "-"
    if storms is None:
        return f"| {folder.name} | - | - | - | - | {means} | {below or 'none'} |"
    hit = [(seed, s) for seed, s in enumerate(storms) if s["first"] is not None]
    starts = ", ".join(f"{seed}: {s['first']}" for seed, s in hit) or "-"
    longest = max((s["longest"] for s in storms), default=0)
    return (
        f"| {folder.name} | {len(storms)} | {len(hit)} | {starts} | {longest} | {means} "
        f"| {below or 'none'} |"
    )


def report(folders: list[Path]) -> list[str]:
    return [
        f"KL storms: {STORM_UPDATES} or more updates in a row with approx. KL above {KL_ABOVE}.",
        "",
        "| run | seeds | seeds with a storm | seed: update its first storm began "
        "| longest storm, updates | evaluation per seed | seeds far below |",
        "|---|---|---|---|---|---|---|",
        *(row(f) for f in folders),
    ]


def stormed_by(folder: Path, at: int) -> list[bool]:
    """Per seed, whether its first KL storm had begun by update `at` (its STORM_UPDATES-th
    update)."""
    storms = kl_storms(folder)
    if storms is None:
        raise SystemExit(
            f"error: {folder} has no PPO log (metrics.csv with approx_kl, or an archived "
            "summary.json)"
        )
    return [s["first"] is not None and s["first"] + STORM_UPDATES - 1 <= at for s in storms]


def returns_by(folder: Path, at: int) -> list[float]:
    """Per seed, the mean return of the training episodes logged in updates at-SPAN+1..at (an
    archived log's bins are numbered by their last update)."""
    log = read_log(folder / "metrics.csv", ("episode_return",))
    if log.updates[-1] < at:
        raise SystemExit(
            f"error: {folder}'s log ends at update {log.updates[-1]}, before --at {at}"
        )
    window = (log.updates > at - SPAN) & (log.updates <= at)
    return [float(x) for x in np.nanmean(log.columns["episode_return"][:, window], axis=1)]


def evaluation_by(folder: Path, at: int) -> list[float] | None:
    """Per seed, the final evaluation's mean return (the first evaluated variant) where the run
    trained to update `at` and was evaluated; None otherwise (cut short, or --at before its end)."""
    path = folder / "eval.json"
    if not path.exists() or read_log(folder / "metrics.csv", ("episode_return",)).updates[-1] != at:
        return None
    return [float(m) for m in json.loads(path.read_text())["evaluations"][0]["seed_means"]]


def fisher_fewer(hits: int, n: int, base_hits: int, base_n: int) -> float:
    """One-sided Fisher exact p: the chance of `hits` or fewer storms among an arm's n seeds when
    the hits + base_hits storms fell at random among all n + base_n seeds (hypergeometric)."""
    total, drawn = hits + base_hits, n + base_n
    return sum(
        math.comb(n, k) * math.comb(base_n, total - k)
        for k in range(0, hits + 1)
        if total - k <= base_n
    ) / math.comb(drawn, total)


def arms_report(arms: dict[str, list[Path]], at: int) -> list[str]:
    """The arms' pooled seeds as far as update `at`, the first arm the base."""

    def evaluated(fs: list[Path]) -> list[float] | None:
        means = [evaluation_by(f, at) for f in fs]
        return None if None in means else [x for m in means for x in m]

    pooled = {
        name: (
            [x for f in fs for x in stormed_by(f, at)],
            [x for f in fs for x in returns_by(f, at)],
            evaluated(fs),
        )
        for name, fs in arms.items()
    }
    base_name, (base_storms, base_returns, base_evals) = next(iter(pooled.items()))
    lines = [
        f"As far as update {at}: seeds whose first KL storm ({STORM_UPDATES} or more updates in a "
        f"row with approx. KL above {KL_ABOVE}) had begun, each seed's training return over "
        f"updates {at - SPAN + 1}-{at}, and where every run of an arm ended there, its final "
        "evaluation (each seed's mean).",
        "",
        f"| arm | runs | seeds | seeds with a storm by {at} "
        f"| Fisher p (fewer than {base_name} by chance) "
        f"| training return, IQM [95% CI] | P(arm > {base_name}) | evaluation, IQM [95% CI] "
        f"| P(arm > {base_name}), evaluation |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for name, (storms, returns, evals) in pooled.items():
        if name == base_name:
            p, poi = "-", "-"
        else:
            p = f"{fisher_fewer(sum(storms), len(storms), sum(base_storms), len(base_storms)):.3g}"
            poi = ordering_text(name, base_name, poi_ci(returns, base_returns))
        eval_poi = (
            "-"
            if name == base_name or evals is None or base_evals is None
            else ordering_text(name, base_name, poi_ci(evals, base_evals))
        )
        lines.append(
            f"| {name} | {', '.join(f.name for f in arms[name])} | {len(storms)} | {sum(storms)} "
            f"| {p} | {iqm_cell(returns, digits=0)} | {poi} "
            f"| {'-' if evals is None else iqm_cell(evals, digits=0)} "
            f"| {eval_poi} |"
        )
    return lines


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="*", help="run folders, live or archived")
    parser.add_argument("--at", type=int, help="compare --arm's arms as far as this update")
    parser.add_argument(
        "--arm",
        action="append",
        default=[],
        metavar="NAME=RUN[,RUN...]",
        help="with --at: an arm's runs, pooled (the first arm is the base)",
    )
    parser.add_argument("--out", type=Path, help="a markdown file to write the table to")
    args = parser.parse_args()
    if args.at is not None or args.arm:
        if (
            args.at is None
            or args.at < 1
            or len(args.arm) < 2
            or args.runs
            or not all("=" in a for a in args.arm)
        ):
            parser.error(
                "--at N (N >= 1) takes two or more --arm NAME=RUN[,RUN...] and no other runs"
            )
        arms = {
            a.split("=", 1)[0]: [Path(r) for r in a.split("=", 1)[1].split(",")] for a in args.arm
        }
        text = "\n".join(arms_report(arms, args.at)) + "\n"
    elif args.runs:
        text = "\n".join(report(args.runs)) + "\n"
    else:
        parser.error("name run folders, or --at N with --arm's")
    if args.out:
        args.out.write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
