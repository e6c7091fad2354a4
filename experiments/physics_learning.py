"""Does learning on MJX-Warp match learning on MJX-JAX? The archived pairs of runs, compared.

    python experiments/physics_learning.py [--runs experiments/results/runs/physics_compare]

Reads `<env>-jax` and `<env>-warp` run folders (eval.json, the same command but `physics`) and
writes experiments/results/physics_learning.md: per env, each physics' IQM over seeds with its
95 % bootstrap CI, P(warp > jax) and the difference of means with their CIs (hintsjax.reproduce.stats),
the training rate and compile seconds, and whether the difference is decided.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from hintsjax.reproduce import stats

HERE = Path(__file__).resolve().parent
RUNS = HERE / "results" / "runs" / "physics_compare"
OUT = HERE / "results" / "physics_learning.md"


def seed_means(folder: Path) -> tuple[np.ndarray, dict]:
    result = json.loads((folder / "eval.json").read_text())
    return np.array(result["evaluations"][0]["seed_means"]), result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, default=RUNS)
    args = parser.parse_args()
    about = json.loads((args.runs / "about.json").read_text())
    lines = ["# Learning on MJX-Warp against MJX-JAX", "",
             f"{about['what']}. Hardware: {about['hardware']} ({about['date']}). Written by "
             "`python experiments/physics_learning.py` from the runs in "
             f"[{args.runs.relative_to(HERE.parent)}]({args.runs.relative_to(OUT.parent)}).", "",
             "| env | env steps per seed | seeds | jax: IQM [95 % CI] | warp: IQM [95 % CI] | P(warp > jax) | "
             "warp - jax, mean [95 % CI] | training env steps/s, jax / warp | training compile s, jax / warp |",
             "|---|---|---|---|---|---|---|---|---|"]
    verdicts = []
    for env in sorted({p.name.rsplit("-", 1)[0] for p in args.runs.iterdir() if p.is_dir()}):
        (jx, rj), (wp, rw) = seed_means(args.runs / f"{env}-jax"), seed_means(args.runs / f"{env}-warp")
        poi, diff = stats.poi_ci(wp, jx), stats.difference_ci(wp, jx)
        lines.append(f"| {env} | {rj['env_steps']:,} | {len(jx)} | {stats.iqm_cell(jx)} | {stats.iqm_cell(wp)} | "
                     f"{poi.point:.2f} [{poi.low:.2f}, {poi.high:.2f}] | {diff.point:+.1f} [{diff.low:+.1f}, {diff.high:+.1f}] | "
                     f"{rj['train_env_steps_per_s'] / 1e3:.1f} K / {rw['train_env_steps_per_s'] / 1e3:.1f} K | "
                     f"{rj['compile_seconds']['train']:.0f} / {rw['compile_seconds']['train']:.0f} |")
        verdicts.append(f"- {env}: " + (f"decided: warp scores {'below' if diff.high < 0 else 'above'} jax "
                                         f"(the difference's interval excludes 0)" if stats.difference_decided(diff)
                                         else "undecided: the difference's interval holds 0"))
    lines += ["", "Verdicts (difference of means, 95 % bootstrap CI over seeds):", *verdicts, "",
              "Commands:", *[f"- {name}: `{cmd}`" for name, cmd in about["commands"].items()], "",
              "Notes:", *[f"- {note}" for note in about["notes"]], ""]
    OUT.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
