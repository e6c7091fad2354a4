"""How far a cheap hint-utility score agrees with the full tables (issue 25).

    python experiments/hint_ranking.py --envs pendulum,acrobot,idp,halfcheetah --seeds 5
        # scores (GPU); resumable
    python experiments/hint_ranking.py --report     # -> experiments/results/hint_ranking.md

Scores every hint of an env's table (Table 2 for the classic envs, Table 3 for halfcheetah, the
one locomotion env with 4 hint rows) with `python -m hintsjax.rank` (both scores) into
--runs/<env>, then compares each score's ranking with the ranking by the full-budget evaluation:
the IQM of the archived 20-seed rows (experiments/results/runs/classic20) where they exist, else
the 5-seed table's means (classic_table2.md, locomotion_table3.md; no per-seed data: no interval
on the table's side). Spearman's rho with a
95% bootstrap interval (the table's seeds resampled per row, the score's seeds resampled jointly
over the candidates), and each score's cost against the table's hint rows: in env steps, and in
seconds (compile included) against the rows' recorded wall-clock.
"""

from __future__ import annotations

import argparse
import json
import re
from pathlib import Path

import numpy as np
from classic_control import TABLE2_HINTS
from locomotion import HINTS as LOCOMOTION_HINTS
from hintsjax.reproduce import archive
from hintsjax.reproduce.markdown import markdown_table

RESULTS = Path(__file__).resolve().parent / "results"
ARCHIVE = RESULTS / "runs" / "classic20"
# the envs scored; --report reports each one found
ENVS = ("pendulum", "acrobot", "idp", "halfcheetah")
TABLE_HINTS = {**TABLE2_HINTS, "halfcheetah": LOCOMOTION_HINTS["halfcheetah"]}
# the 5-seed means, where no 20-seed archive is whole
TABLE_FILES = {
    **{env: "classic_table2.md" for env in TABLE2_HINTS},
    "halfcheetah": "locomotion_table3.md",
}
# Seconds the table's hint rows took on one GPU. Classic (20 seeds, one H100, classic_seeds20.md's
# group wall-clock): pendulum's one group of 6; acrobot's group of 6 plus the state row alone; the
# idp's group of 7 trained 195 updates in 459 s after a 64 s compile, 2026-11-25, before its
# evaluation was cut. Halfcheetah (5 seeds, locomotion_table3.md): its 4 hint rows' wall-clock
# (1144 + 1156 + 1156 + 1149 s), each its own process, trained several at a time on one H200.
TABLE_SECONDS = {
    "pendulum": 616,
    "acrobot": 677 + 141,
    "idp": 459 + 64,
    "halfcheetah": 1144 + 1156 + 1156 + 1149,
}
TABLE_SEEDS = {"pendulum": 20, "acrobot": 20, "idp": 20, "halfcheetah": 5}
RESAMPLES = 2000


DEFAULT_FRACTION = 0.1


def score_folder(runs: Path, env: str, fraction: float = DEFAULT_FRACTION) -> Path:
    return runs / (env if fraction == DEFAULT_FRACTION else f"{env}-probe{fraction:g}")


def run_scores(runs: Path, env: str, seeds: int, fraction: float, scores: str) -> None:
    from hintsjax import rank

    folder = score_folder(runs, env, fraction)
    if (folder / "scores.json").is_file():
        return
    argv = [
        f"env={env}",
        f"hints={','.join(TABLE_HINTS[env])}",
        f"seeds={seeds}",
        f"probe_fraction={fraction}",
        f"scores={scores}",
        f"out_dir={runs}",
        f"name={folder.name}",
    ]
    if rank.main(argv):
        raise SystemExit(f"ranking {env} failed")


def table_rows(env: str) -> dict[str, np.ndarray]:
    """Per hint the full-budget per-seed mean returns ([20]) from the archive, or [1] (the 5-seed
    mean) from the env's table file."""
    rows = {}
    for hint in TABLE_HINTS[env]:
        path = ARCHIVE / env / f"hints-fc-{hint}" / "eval.json"
        if path.is_file():
            rows[hint] = np.asarray(json.loads(path.read_text())["evaluations"][0]["seed_means"])
    if len(rows) == len(TABLE_HINTS[env]):
        return rows
    text = re.split(
        rf"^## {env}\b.*\n", (RESULTS / TABLE_FILES[env]).read_text(), maxsplit=1, flags=re.M
    )[1]
    text = text.split("\n## ", 1)[0]
    for hint in TABLE_HINTS[env]:
        match = re.search(rf"^\| hints-fc-{hint}(?: †)? \| (-?[\d.]+) ±", text, re.M)
        rows[hint] = np.asarray([float(match.group(1))])
    return rows


def spearman(x: np.ndarray, y: np.ndarray) -> float:
    from scipy.stats import spearmanr

    return float(spearmanr(x, y).statistic)


def rho_interval(
    score: np.ndarray, rows: list[np.ndarray], rng: np.random.Generator
) -> tuple[float, float, float]:
    """rho between the score's means over seeds ([S, K]) and the rows' IQMs, with a 95% bootstrap
    interval (the score's seeds and the rows' seeds resampled; rows of one number, a table's means,
    stay as they are: the interval then says how far the score's own seeds move rho)."""
    from hintsjax.reproduce.stats import iqm

    point = spearman(score.mean(axis=0), [iqm(r) for r in rows])
    draws = []
    for _ in range(RESAMPLES):
        s = score[rng.integers(0, len(score), len(score))].mean(axis=0)
        t = [iqm(r[rng.integers(0, len(r), len(r))]) for r in rows]
        if np.ptp(s) > 0 and np.ptp(t) > 0:
            draws.append(spearman(s, t))
    if not draws:
        return point, np.nan, np.nan
    low, high = np.percentile(draws, [2.5, 97.5])
    return point, float(low), float(high)


def scored(runs: Path, env: str) -> Path:
    """The runs folder holding `env`'s scores: --runs where it was scored there, else the committed
    copy of that folder (archive.ARCHIVE/<its name>), so --report on a fresh checkout rebuilds the
    file."""
    return (
        runs if (score_folder(runs, env) / "scores.json").is_file() else archive.ARCHIVE / runs.name
    )


def report(runs: Path, env_list: list[str], out: Path) -> None:
    from hintsjax.reproduce import stats

    rng = np.random.default_rng(0)
    lines = [
        "# Which hint is worth giving: cheap scores against the full tables",
        "",
        "Written by `python experiments/hint_ranking.py --report` from `python "
        "experiments/hint_ranking.py --envs ... --seeds 5` (hintsjax.rank on every hint of the "
        "env's table; commands and hardware below). Full ranking: the IQM of each HINTS-FC row's "
        "per-seed evaluation returns at the full budget (20 seeds, "
        "experiments/results/runs/classic20; halfcheetah: the 5-seed means of "
        "locomotion_table3.md, whose interval resamples the score's seeds only). rho: Spearman's "
        "rank correlation between a score's mean over its seeds and that ranking, with a 95% "
        "bootstrap interval; `probe f`: the short training probe at the fraction f of the budget. "
        "Cost: the score's env steps and seconds (compile included, one H100) against the table's "
        "hint rows (TABLE_SECONDS in experiments/hint_ranking.py says where each table's seconds "
        "come from).",
        "",
    ]
    summary, per_env = [], []
    rhos: dict[str, list[float]] = {}
    for env in env_list:
        root = scored(runs, env)
        path = score_folder(root, env) / "scores.json"
        if not path.is_file():
            continue
        result = json.loads(path.read_text())
        # the probe at other fractions of the budget
        for folder in sorted(root.glob(f"{env}-probe*")):
            extra = json.loads((folder / "scores.json").read_text())
            label = f"probe {folder.name.split('-probe')[1]}"
            result["scores"][label] = extra["scores"]["probe"]
            result["seconds"][label] = extra["seconds"]["probe"]
            result.setdefault("steps", {})[label] = extra["probe_env_steps_per_run"]
        result["scores"]["probe 0.1"] = result["scores"].pop("probe")
        result["seconds"]["probe 0.1"] = result["seconds"].pop("probe")
        result.setdefault("steps", {})["probe 0.1"] = result["probe_env_steps_per_run"]
        full = table_rows(env)
        hints = result["candidates"]
        rows = [full[h] for h in hints]
        per_env += [f"## {env}", ""]
        header = [
            "hint",
            f"full: IQM [95% CI] ({len(rows[0])} seeds)"
            if len(rows[0]) > 1
            else "full: mean of 5 seeds",
        ]
        cells = [
            [h, stats.iqm_cell(r) if len(r) > 1 else f"{r[0]:.1f}"] for h, r in zip(hints, rows)
        ]
        for name, values in result["scores"].items():
            values = np.asarray(values)
            header.append(f"{name}: mean ± std ({len(values)} seeds)")
            for cell, mean, std in zip(cells, values.mean(axis=0), values.std(axis=0)):
                cell.append(f"{mean:.3g} ± {std:.2g}")
            point, low, high = rho_interval(values, rows, rng)
            rhos.setdefault(name, []).append(point)
            steps = _score_env_steps(name, result, score_folder(root, env), len(hints))
            seconds = result["seconds"][name]
            full_steps = _table_env_steps(env, len(hints))
            summary.append(
                [
                    env,
                    name,
                    f"{point:.2f}" + ("" if np.isnan(low) else f" [{low:.2f}, {high:.2f}]"),
                    f"{steps:,} ({steps / full_steps:.1%})",
                    f"{seconds:.0f} ({seconds / TABLE_SECONDS[env]:.1%})",
                ]
            )
        per_env += [*markdown_table(header, cells), ""]
        if result.get("probe_measure") == "step_reward":
            per_env += [
                "The probe's score here is the mean reward per step over the short run's updates: "
                f"no {env} episode ended within it (hintsjax.rank's `learning_curve_area`).",
                "",
            ]
    lines += [
        "## Agreement and cost",
        "",
        *markdown_table(
            [
                "env",
                "score",
                "rho [95% CI]",
                "env steps (of the table's)",
                "seconds (of the table's)",
            ],
            summary,
        ),
        "",
    ]
    lines += [
        "Where a rho lies outside its interval, tied scores (e.g. the pendulum's three hints that "
        "carry the angular velocity) are ordered differently by the resampled seeds than by the "
        "means. Mean rho over the envs: "
        + ", ".join(f"{n} {np.mean(v):.2f}" for n, v in rhos.items())
        + " (target: 0.7 at 10% of the cost).",
        "",
    ]
    lines += per_env
    about = archive.read_about(runs) or archive.read_about(archive.ARCHIVE / runs.name)
    lines += [
        "## Where these numbers come from",
        "",
        *(f"- {k}: {v}" for k, v in about.items()),
        "",
    ]
    out.write_text("\n".join(lines))
    print(f"wrote {out}")


def _table_env_steps(env: str, hints: int) -> int:
    from hintsjax.settings.layers import run_config

    return TABLE_SEEDS[env] * hints * run_config({"env": env, "agent": "hints"}).ppo.total_env_steps


def _score_env_steps(name: str, result: dict, folder: Path, hints: int) -> int:
    """The env steps a score used: every candidate's short runs, or the information score's
    rollouts."""
    import yaml

    seeds = len(result["scores"][name])
    if name.startswith("probe"):
        return seeds * hints * result["steps"][name]
    cfg = yaml.safe_load((folder / "config.yaml").read_text())
    return seeds * (cfg["info_envs"] + cfg["info_held_out_envs"]) * cfg["info_steps"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--envs",
        default=None,
        help="scoring: pendulum,acrobot,idp unless given; --report: all "
        f"of {','.join(ENVS)} that were scored",
    )
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--probe-fraction", type=float, default=DEFAULT_FRACTION)
    parser.add_argument("--scores", default="information,probe")
    parser.add_argument("--runs", type=Path, default=Path("runs/hint_ranking"))
    parser.add_argument("--report", action="store_true")
    parser.add_argument("--out", type=Path, default=RESULTS / "hint_ranking.md")
    args = parser.parse_args()
    env_list = args.envs.split(",") if args.envs else list(ENVS if args.report else ENVS[:3])
    if args.report:
        report(args.runs, env_list, args.out)
        return
    args.runs.mkdir(parents=True, exist_ok=True)
    for env in env_list:
        run_scores(args.runs, env, args.seeds, args.probe_fraction, args.scores)


if __name__ == "__main__":
    main()
