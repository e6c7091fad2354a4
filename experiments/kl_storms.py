"""PPO's KL storms, seed by seed, beside each seed's evaluation: which seeds had one, where the
first began and how long the longest lasted (experiments/results/locomotion_ppo_stability.md).

    python experiments/kl_storms.py RUN [RUN ...] [--out FILE.md]

RUN: a run folder (its metrics.csv and eval.json) or an archived one (the storms kept in its
summary.json by hintsjax.reproduce.archive). A storm is archive.STORM_UPDATES or more updates in
a row whose approx. KL (the mean over the update's minibatch steps) exceeds archive.KL_ABOVE: with
the KL early stop on, each of them is the update's first minibatch step alone.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from hintsjax.reproduce.archive import KL_ABOVE, STORM_UPDATES, kl_storms


def row(folder: Path) -> str:
    """One run's markdown row."""
    storms = kl_storms(folder)
    evaluation = json.loads((folder / "eval.json").read_text())["evaluations"][0] if (folder / "eval.json").exists() else None
    means = ", ".join(f"{m:.0f}" for m in evaluation["seed_means"]) if evaluation else "-"
    below = ", ".join(str(s) for s in evaluation.get("outlier_seeds", [])) if evaluation else "-"
    if storms is None:
        return f"| {folder.name} | - | - | - | - | {means} | {below or 'none'} |"
    hit = [(seed, s) for seed, s in enumerate(storms) if s["first"] is not None]
    starts = ", ".join(f"{seed}: {s['first']}" for seed, s in hit) or "-"
    longest = max((s["longest"] for s in storms), default=0)
    return f"| {folder.name} | {len(storms)} | {len(hit)} | {starts} | {longest} | {means} | {below or 'none'} |"


def report(folders: list[Path]) -> list[str]:
    return [
        f"KL storms: {STORM_UPDATES} or more updates in a row with approx. KL above {KL_ABOVE}.",
        "",
        "| run | seeds | seeds with a storm | seed: update its first storm began | longest storm, updates | evaluation per seed | seeds far below |",
        "|---|---|---|---|---|---|---|",
        *(row(f) for f in folders),
    ]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", type=Path, nargs="+", help="run folders, live or archived")
    parser.add_argument("--out", type=Path, help="a markdown file to write the table to")
    args = parser.parse_args()
    text = "\n".join(report(args.runs)) + "\n"
    if args.out:
        args.out.write_text(text)
    print(text, end="")


if __name__ == "__main__":
    main()
