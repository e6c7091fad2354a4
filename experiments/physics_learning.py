"""Does learning on MJX-Warp match learning on MJX-JAX? Archived runs of the two physics, compared.

    python experiments/physics_learning.py [--runs experiments/results/runs/physics_compare]
                                           [--out FILE.md]

Reads the runs folder's about.json and its run folders: by default `<env>-jax` and `<env>-warp`
(the same command but `physics`); about.json's `arms` may instead name, per env and physics,
several run folders (relative to the runs folder) whose seeds are pooled, e.g. two 5-seed runs
started at seed=0 and seed=5. Writes per env:
- the evaluation (eval.json's per-seed means): each physics' IQM over seeds with its 95 %
  bootstrap CI, P(warp > jax) and the difference of means with their CIs (hintsjax.reproduce.stats),
  and whether the difference is decided; '-' where a run has no eval.json (cut short);
- the training return at equal env steps: each seed's mean over the training episodes logged in
  the last 10 % of the env steps that every run of the env reached (metrics.csv), compared the same
  way, so a run brought back before its end still counts;
- the seeds that ended far below the others (hintsjax/evaluation/outliers.py), the seeds that had
  a KL storm (hintsjax.reproduce.archive.kl_storms), the seeds whose
  policy's std (its logged entropy) ended above where it started: with actions clipped to the
  box, a std that grows saturates them, which costs a locomotion task's control cost in training
  but not its deterministic evaluation; and the training rate and compile seconds of each run.
"""

from __future__ import annotations

import argparse
import json
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path

import numpy as np

from hintsjax.evaluation.outliers import far_below
from hintsjax.reproduce import stats
from hintsjax.reproduce.archive import kl_storms
from hintsjax.training.runlog import read_curves

HERE = Path(__file__).resolve().parent
RUNS = HERE / "results" / "runs" / "physics_compare"
OUT = HERE / "results" / "physics_learning.md"
PHYSICS = ("jax", "warp")
LAST = 0.1  # the share of the equal env steps whose training episodes make a seed's training return


@dataclass(frozen=True)
class Arm:
    """One physics' runs of one env, seeds pooled in the order the folders are named."""

    folders: tuple[Path, ...]

    @cached_property
    def results(self) -> list[dict | None]:
        """Each run's eval.json (None where it has none), read once."""
        return [
            json.loads((f / "eval.json").read_text()) if (f / "eval.json").exists() else None
            for f in self.folders
        ]

    def seed_means(self) -> np.ndarray | None:
        """[S] evaluation means over every folder's seeds; None when a run was not evaluated."""
        results = self.results
        if any(r is None for r in results):
            return None
        return np.concatenate([r["evaluations"][0]["seed_means"] for r in results])

    @cached_property
    def curves(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """Each run's training return (env_steps [U], values [S, U]), read once."""
        return [read_curves(f / "metrics.csv") for f in self.folders]

    def training_means(self, up_to: float) -> np.ndarray:
        """[S] each seed's mean training return over the episodes logged in (1 - LAST) x up_to to
        up_to env steps."""
        means = []
        for steps, values in self.curves:
            window = (steps > (1 - LAST) * up_to) & (steps <= up_to)
            means.append(np.nanmean(values[:, window], axis=1))
        return np.concatenate(means)

    def std_grown(self, up_to: float) -> str:
        """'k of S': the seeds whose policy entropy (so its std: a Gaussian's entropy grows with its
        log std) over the last LAST of up_to env steps is above its first logged value; '-' when a
        run's metrics.csv has no entropy (archived runs keep the return alone)."""
        grown, seeds = 0, 0
        for f in self.folders:
            try:
                steps, entropy = read_curves(f / "metrics.csv", "entropy")
            except KeyError:
                return "-"
            window = (steps > (1 - LAST) * up_to) & (steps <= up_to)
            grown += int(np.sum(np.nanmean(entropy[:, window], axis=1) > entropy[:, 0]))
            seeds += entropy.shape[0]
        return f"{grown} of {seeds}"

    def storm_seeds(self) -> str:
        """'k of S': the seeds that had a KL storm (hintsjax.reproduce.archive.kl_storms); '-' when
        a run has no record of them (no approx_kl logged, or archived before they were kept)."""
        storms = [kl_storms(f) for f in self.folders]
        if any(s is None for s in storms):
            return "-"
        return (
            f"{sum(s['first'] is not None for run in storms for s in run)} of "
            f"{sum(len(run) for run in storms)}"
        )

    def reached(self) -> float:
        """The env steps per seed that every run of the arm logged."""
        return min(float(steps[-1]) for steps, _ in self.curves)

    def runs_text(self, key: str, scale: float = 1.0, unit: str = "") -> str:
        values = [
            ("-" if r is None or r.get(key) is None else f"{_value(r[key]) / scale:.1f}{unit}")
            for r in self.results
        ]
        return ", ".join(values)


def _value(entry) -> float:
    return entry["train"] if isinstance(entry, dict) else entry


def arms_of(runs: Path, about: dict) -> dict[str, dict[str, Arm]]:
    """{env: {physics: Arm}} from about.json's `arms`, or the `<env>-<physics>` folders."""
    if "arms" in about:
        return {
            env: {p: Arm(tuple(runs / f for f in named[p])) for p in PHYSICS}
            for env, named in about["arms"].items()
        }
    envs = sorted({p.name.rsplit("-", 1)[0] for p in runs.iterdir() if p.is_dir()})
    return {env: {p: Arm((runs / f"{env}-{p}",)) for p in PHYSICS} for env in envs}


def comparison(warp: np.ndarray, jax: np.ndarray) -> tuple[str, str, str]:
    """(P(warp > jax) cell, difference cell, verdict) of two [S] score arrays."""
    poi, diff = stats.poi_ci(warp, jax), stats.difference_ci(warp, jax)
    verdict = (
        f"decided: warp scores {'below' if diff.high < 0 else 'above'} jax (the difference's "
        "interval excludes 0)"
        if stats.difference_decided(diff)
        else "undecided: the difference's interval holds 0"
    )
    return (
        f"{poi.point:.2f} [{poi.low:.2f}, {poi.high:.2f}]",
        f"{diff.point:+.1f} [{diff.low:+.1f}, {diff.high:+.1f}]",
        verdict,
    )


def outliers_text(scores: np.ndarray | None) -> str:
    if scores is None:
        return "-"
    flagged = far_below(scores)
    return "none" if not flagged else ", ".join(f"seed {i} ({scores[i]:.0f})" for i in flagged)


def report(runs: Path) -> list[str]:
    about = json.loads((runs / "about.json").read_text())
    where = runs.relative_to(HERE.parent) if runs.is_relative_to(HERE.parent) else runs
    lines = [
        "# Learning on MJX-Warp against MJX-JAX",
        "",
        f"{about['what']}. Hardware: {about['hardware']} ({about['date']}). Written by "
        f"`python experiments/physics_learning.py --runs {where}` from the runs in that folder.",
        "",
        "## The evaluation (deterministic policy, each seed's mean over its episodes)",
        "",
        "| env | env steps per seed | seeds, jax / warp | jax: IQM [95 % CI] | "
        "warp: IQM [95 % CI] | P(warp > jax) | warp - jax, mean [95 % CI] | "
        "seeds far below, jax / warp | seeds with a KL storm, jax / warp |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    training = [
        "",
        "## The training return at equal env steps (sampled actions, each seed's mean over the "
        f"episodes logged in the last {LAST:.0%} of the steps both physics reached)",
        "",
        "| env | env steps per seed | seeds, jax / warp | jax: IQM [95 % CI] | "
        "warp: IQM [95 % CI] | P(warp > jax) | warp - jax, mean [95 % CI] | "
        "seeds whose policy std ended above its start, jax / warp |",
        "|---|---|---|---|---|---|---|---|",
    ]
    speed = [
        "",
        "## Each run's training rate and compile",
        "",
        "| env | training env steps/s, jax | training env steps/s, warp | "
        "training compile s, jax | training compile s, warp |",
        "|---|---|---|---|---|",
    ]
    verdicts = []
    for env, arms in arms_of(runs, about).items():
        jx, wp = arms["jax"].seed_means(), arms["warp"].seed_means()
        steps = {
            r["env_steps"]
            for p in PHYSICS
            for r in arms[p].results
            if r is not None and "env_steps" in r
        }
        if jx is not None and wp is not None:
            poi, diff, verdict = comparison(wp, jx)
            lines.append(
                f"| {env} | {', '.join(f'{s:,}' for s in sorted(steps)) or '-'} | "
                f"{len(jx)} / {len(wp)} | {stats.iqm_cell(jx)} | {stats.iqm_cell(wp)} | "
                f"{poi} | {diff} | {outliers_text(jx)} / {outliers_text(wp)} | "
                f"{arms['jax'].storm_seeds()} / {arms['warp'].storm_seeds()} |"
            )
            verdicts.append(f"- {env}, evaluation: {verdict}")
        else:
            lines.append(
                f"| {env} | - | - | {'-' if jx is None else stats.iqm_cell(jx)} | "
                f"{'-' if wp is None else stats.iqm_cell(wp)} | - | - | - | - |"
            )
        up_to = min(arms[p].reached() for p in PHYSICS)
        tj, tw = arms["jax"].training_means(up_to), arms["warp"].training_means(up_to)
        poi, diff, verdict = comparison(tw, tj)
        training.append(
            f"| {env} | {up_to:,.0f} | {len(tj)} / {len(tw)} | "
            f"{stats.iqm_cell(tj)} | {stats.iqm_cell(tw)} | {poi} | {diff} | "
            f"{arms['jax'].std_grown(up_to)} / {arms['warp'].std_grown(up_to)} |"
        )
        verdicts.append(f"- {env}, training return at {up_to:,.0f} env steps: {verdict}")
        speed.append(
            f"| {env} | {arms['jax'].runs_text('train_env_steps_per_s', 1e3, ' K')} | "
            f"{arms['warp'].runs_text('train_env_steps_per_s', 1e3, ' K')} | "
            f"{arms['jax'].runs_text('compile_seconds')} | "
            f"{arms['warp'].runs_text('compile_seconds')} |"
        )
    return [
        *lines,
        *training,
        *speed,
        "",
        "Verdicts (difference of means, 95 % bootstrap CI over seeds):",
        *verdicts,
        "",
        "Commands:",
        *[f"- {name}: `{cmd}`" for name, cmd in about["commands"].items()],
        "",
        "Notes:",
        *[f"- {note}" for note in about["notes"]],
        "",
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--runs", type=Path, default=RUNS, help="a folder of runs with its about.json"
    )
    parser.add_argument("--out", type=Path, default=OUT, help="the markdown file to write")
    args = parser.parse_args()
    text = "\n".join(report(args.runs.resolve()))
    args.out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
