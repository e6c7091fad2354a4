"""Which hint is worth giving: cheap utility scores of candidate hints, before paying for training.

    python -m hintsjax.rank env=pendulum                                # every registered hint
    python -m hintsjax.rank env=acrobot hints=joint,composite,angular_velocity_1+goal_distance

The scores (`information` and `probe`) are hintsjax/hints/ranking.py. The run folder holds
config.yaml, scores.json (per score, candidate and seed), ranking.csv and ranking.png.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import sys
import time
from pathlib import Path
from typing import Any

import jax
import numpy as np
import yaml

from hintsjax.system import paths
from hintsjax.system.errors import command
from hintsjax.system.refusals import writing_to
from hintsjax.cli.arguments import parse_key_values
from hintsjax.training.runlog import fresh_folder
from hintsjax.hints.ranking import RankConfig, SCORES, rank_hints, ranking


def write_folder(folder: Path, cfg: RankConfig, result: dict[str, Any]) -> list[list[str]]:
    """scores.json, ranking.csv and ranking.png; the table's rows."""
    (folder / "scores.json").write_text(
        json.dumps({**result, "device": jax.devices()[0].device_kind}, indent=1)
    )
    rows = []
    for name, values in result["scores"].items():
        values = np.asarray(values)
        for hint, rank, mean, std in zip(
            cfg.candidates, ranking(values), values.mean(axis=0), values.std(axis=0)
        ):
            rows.append([name, hint, str(rank), f"{mean:.4g}", f"{std:.3g}"])
    with (folder / "ranking.csv").open("w", newline="") as f:
        csv.writer(f).writerows([["score", "hint", "rank", "mean", "std_over_seeds"], *rows])
    plot(folder / "ranking.png", cfg, result)
    return rows


def plot(path: Path, cfg: RankConfig, result: dict[str, Any]) -> None:
    # here: matplotlib takes about a second to import, and only the written report draws
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = list(result["scores"])
    fig, axes = plt.subplots(
        1, len(names), figsize=(5 * len(names), 0.5 * len(cfg.candidates) + 1.5), squeeze=False
    )
    for ax, name in zip(axes[0], names):
        values = np.asarray(result["scores"][name])
        y = np.arange(len(cfg.candidates))
        ax.barh(y, values.mean(axis=0), xerr=values.std(axis=0), color="tab:blue")
        ax.set_yticks(y, cfg.candidates)
        ax.invert_yaxis()
        ax.set_title(f"{name} ({cfg.seeds} seeds)")
        ax.set_xlabel(SCORES[name])
    fig.suptitle(f"{cfg.env}: hint utility")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


@command
def main(argv: list[str] | None = None) -> int:
    cfg = parse_key_values(
        RankConfig,
        sys.argv[1:] if argv is None else argv,
        "python -m hintsjax.rank",
        __doc__.splitlines()[0],
    ).validate()
    paths.check_folder(cfg.out_dir, "out_dir")  # before anything is trained
    print(
        f"ranking {len(cfg.candidates)} hints of {cfg.env} by {cfg.scores}, {cfg.seeds} seeds",
        flush=True,
    )
    folder = Path(cfg.out_dir) / (cfg.name or f"rank-{cfg.env}-{time.strftime('%Y%m%d-%H%M%S')}")
    with writing_to(folder):  # a full disk or read-only folder: one line naming it
        folder = fresh_folder(folder)
        (folder / "config.yaml").write_text(
            yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False)
        )
        result = rank_hints(cfg)
        rows = write_folder(folder, cfg, result)
    width = max(len(h) for h in cfg.candidates)
    for name in result["scores"]:
        print(f"{name} ({result['seconds'][name]:.0f} s):")
        for score, hint, rank, mean, std in sorted(
            (r for r in rows if r[0] == name), key=lambda r: int(r[2])
        ):
            print(f"  {rank:>2}. {hint:<{width}}  {mean} +- {std}")
    print(f"-> {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
