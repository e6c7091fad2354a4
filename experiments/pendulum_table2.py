"""Pendulum row of the paper's Table 2: PPO-RGB, PPO-x and HINTS-FC per hint, 5 seeds x 50 episodes.

    python experiments/pendulum_table2.py --runs runs/table2 [--only ppo_rgb,hints-fc-composite]
    python experiments/pendulum_table2.py --runs runs/table2 --table experiments/results/pendulum_table2.md

Each configuration is one `python -m hintsjax.run` run (the paper's budget: 1000 episodes of 200
steps), trained with all seeds vmapped in one call; its folder holds eval.json. `--table` only
collects finished folders into the markdown table, beside the paper's numbers, with wall-clock.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

CONFIGS: dict[str, dict] = {
    "ppo_rgb": {"agent": "ppo_rgb"},
    "ppo_state": {"agent": "ppo_state"},
    "hints-fc-angular_velocity": {"agent": "hints", "scheme": "fc", "hint": "angular_velocity"},
    "hints-fc-goal_distance": {"agent": "hints", "scheme": "fc", "hint": "goal_distance"},
    "hints-fc-composite": {"agent": "hints", "scheme": "fc", "hint": "composite"},
    "hints-fc-partial_state": {"agent": "hints", "scheme": "fc", "hint": "partial_state"},
    "hints-fc-state": {"agent": "hints", "scheme": "fc", "hint": "state"},
}

# The paper's Table 2, Pendulum Swingup row (mean +- std, n=50), and its Swingto deploy row.
PAPER = {
    "ppo_rgb": ("-1352.82 ± 169.6", "21.26 ± 138.9"),
    "ppo_state": ("-1270.86 ± 77.3", "120.15 ± 85.3"),
    "hints-fc-angular_velocity": ("-250.31 ± 164.0", "111.08 ± 186.4"),
    "hints-fc-goal_distance": ("-1203.08 ± 307.6", "-"),
    "hints-fc-composite": ("-241.14 ± 178.5", "-118.48 ± 72.0"),
    "hints-fc-partial_state": ("-1304.77 ± 180.1", "-"),
    "hints-fc-state": ("-1248.46 ± 150.5", "18.76 ± 105.5"),
}


def train_all(runs: Path, only: list[str], seeds: int) -> None:
    from hintsjax import run
    from hintsjax.config import run_config, to_dict

    import yaml

    for name in only:
        folder = runs / name
        if (folder / "eval.json").exists():
            print(f"{name}: done already, skipped", flush=True)
            continue
        cfg = run_config({"env": "pendulum", "seeds": seeds, "eval_variants": ["swingto"],
                          "checkpoint_every": 50, **CONFIGS[name]})
        folder.mkdir(parents=True, exist_ok=True)
        (folder / "config.yaml").write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))
        t = time.time()
        results = run.train(cfg, folder, progress=False)
        results["wall_seconds"] = time.time() - t
        (folder / "eval.json").write_text(json.dumps(results, indent=1))
        print(f"{name}: {results['wall_seconds']:.0f} s", flush=True)


def table(runs: Path, out: Path) -> None:
    lines = [
        "# Pendulum swing-up: the paper's Table 2 row, reproduced",
        "",
        "Each cell: mean ± std of the episode return over all 5 training seeds x 50 evaluation episodes",
        "(deterministic policy); in brackets the std of the 5 per-seed means. Budget: 1000 episodes",
        "(200 K env steps) per seed. Swingto: the same agents deployed on goals in [-pi/2, pi/2]",
        "(our finite swing-to reward, see envs/pendulum.py; the paper's reward differs, so only the",
        "ordering compares).",
        "",
        "| agent | swing-up (ours) | swing-up (paper) | swingto deploy (ours) | swingto (paper) | wall-clock (s) |",
        "|---|---|---|---|---|---|",
    ]
    total = 0.0
    for name in CONFIGS:
        path = runs / name / "eval.json"
        if not path.exists():
            continue
        r = json.loads(path.read_text())
        cells = [f"{e['mean']:.1f} ± {e['std']:.1f} ({e['seed_std']:.1f})" for e in r["evaluations"]]
        total += r.get("wall_seconds", r["train_seconds_this_call"])
        lines.append(f"| {name} | {cells[0]} | {PAPER[name][0]} | {cells[1]} | {PAPER[name][1]} | "
                     f"{r.get('wall_seconds', r['train_seconds_this_call']):.0f} |")
    lines += ["", f"Total wall-clock for the rows above: {total:.0f} s (training, evaluation and compilation).",
              "", f"![learning curves]({out.with_suffix('.png').name})"]
    out.write_text("\n".join(lines) + "\n")
    from hintsjax.runlog import plot_curves, read_curves

    curves = {n: read_curves(runs / n / "metrics.csv") for n in CONFIGS if (runs / n / "metrics.csv").exists()}
    plot_curves(curves, out.with_suffix(".png"), "pendulum swing-up, 5 seeds (mean ± std)")
    print("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=Path, default=Path("runs/pendulum_table2"))
    parser.add_argument("--only", default=",".join(CONFIGS), help=f"comma-separated subset of {list(CONFIGS)}")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--table", type=Path, default=None, help="only write the markdown table here")
    args = parser.parse_args()
    if args.table:
        table(args.runs, args.table)
        return
    only = [n.strip() for n in args.only.split(",") if n.strip()]
    unknown = [n for n in only if n not in CONFIGS]
    if unknown:
        parser.exit(2, f"error: unknown configuration {unknown}; valid choices: {', '.join(CONFIGS)}\n")
    train_all(args.runs, only, args.seeds)


if __name__ == "__main__":
    main()
