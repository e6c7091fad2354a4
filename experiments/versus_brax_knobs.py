"""Which unmatched knob explains hintsjax's PPO trailing Brax's on CartpoleSwingup (issue 61, item 3).

    python experiments/versus_brax_knobs.py --side brax    # Brax's PPO
    # hintsjax, as --versus-brax maps it:
    python experiments/versus_brax_knobs.py --side hintsjax --label baseline
    python experiments/versus_brax_knobs.py --side hintsjax --label no-grad-clip
                                            ppo.max_grad_norm=1e9
    python experiments/versus_brax_knobs.py --table        # the rows so far

A CPU-sized version of experiments/playground.py's --versus-brax: Playground's Brax settings for
CartpoleSwingup (dm_control_suite_params) with fewer envs and epochs (`CPU`, the same on both
sides), both trainers held to exactly `--updates` updates of the same batch per seed. hintsjax's
side takes `hintsjax_values`' mapping plus any `ppo.<key>=<value>` overrides (the knob under test).
Each side's final policy is evaluated both ways, deterministic (mean action) and stochastic, on
`EVAL_EPISODES` fresh episodes per seed: hintsjax by its own evaluator, Brax by its own Evaluator.
Each run appends one row to runs/versus_brax_knobs/rows.jsonl.
"""  # noqa: E501

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import yaml

# experiments/playground.py, a script beside this one
sys.path.insert(0, str(Path(__file__).resolve().parent))
import playground  # noqa: E402

ROWS = Path("runs/versus_brax_knobs/rows.jsonl")
EVAL_EPISODES = playground.EVAL_EPISODES  # 128, Brax's num_eval_envs
# Playground's settings scaled to 2 CPU cores, in two regimes. Both have 64 envs, each of which
# collects 16 unrolls of 30 steps per update (480 steps, as 2048 envs do on the GPU):
#   many: 96 updates of 16 minibatches of 64 unrolls, 4 epochs (not 16), 2.95 M env steps per seed;
#   few:  20 updates of 32 minibatches of 32 unrolls, 16 epochs: the GPU run's 20 updates of 512
#         gradient steps each, with minibatches 32 times smaller, 614,400 env steps per seed.
# and gpu: Playground's settings as they are (2048 envs), 61 updates (60 M env steps), on a GPU
REGIMES = {
    "gpu": (61, {}),
    "many": (
        96,
        dict(
            num_envs=64,
            batch_size=64,
            num_minibatches=16,
            unroll_length=30,
            num_updates_per_batch=4,
        ),
    ),
    "few": (
        20,
        dict(
            num_envs=64,
            batch_size=32,
            num_minibatches=32,
            unroll_length=30,
            num_updates_per_batch=16,
        ),
    ),
}


def settings(regime: str) -> dict:
    brax = playground.brax_settings(False)
    brax.update(REGIMES[regime][1])
    return brax


def parse_overrides(pairs: list[str]) -> dict:
    ppo = {}
    for pair in pairs:
        key, value = pair.split("=", 1)
        section, name = key.split(".", 1)
        assert section == "ppo", key
        value = yaml.safe_load(value)
        # YAML reads 1e9 as text
        ppo[name] = float(value) if isinstance(value, str) and value[:1].isdigit() else value
    return ppo


def train_hintsjax(regime: str, seeds: int, updates: int, overrides: dict) -> dict:
    return playground.train_hintsjax(settings(regime), seeds, updates, overrides, EVAL_EPISODES)


def train_brax(regime: str, seeds: int, updates: int) -> dict:
    return playground.train_brax(settings(regime), seeds, updates, EVAL_EPISODES)


def table() -> None:
    rows = [json.loads(line) for line in ROWS.read_text().splitlines()]
    mean = lambda xs: sum(xs) / len(xs)  # noqa: E731
    print(
        "| regime | side | knob | env steps per seed | deterministic return per seed (mean) | "
        "stochastic return per seed (mean) | wall-clock (s) |"
    )
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        det, sto = r["deterministic"], r["stochastic"]
        steps = r["env_steps_per_seed"]
        steps = steps if isinstance(steps, int) else "/".join(str(s) for s in sorted(set(steps)))
        print(
            f"| {r.get('regime', 'many')} | {r['side']} | {r['label']} | {steps} | "
            f"{', '.join(f'{x:.1f}' for x in det)} ({mean(det):.1f}) | "
            f"{', '.join(f'{x:.1f}' for x in sto)} ({mean(sto):.1f}) | {r['seconds']:.0f} |"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", choices=("hintsjax", "brax"))
    parser.add_argument("--label", default="baseline")
    parser.add_argument("--seeds", type=int, default=2)
    parser.add_argument("--regime", choices=tuple(REGIMES), default="many")
    parser.add_argument("--updates", type=int, default=None, help="default: the regime's")
    parser.add_argument("--table", action="store_true")
    parser.add_argument("overrides", nargs="*", help="hintsjax's knob: ppo.<key>=<value>")
    args = parser.parse_args()
    if args.table:
        return table()
    args.updates = args.updates or REGIMES[args.regime][0]
    if args.side == "brax":
        assert not args.overrides, "Brax's side takes no overrides"
        result = train_brax(args.regime, args.seeds, args.updates)
    else:
        result = train_hintsjax(
            args.regime, args.seeds, args.updates, parse_overrides(args.overrides)
        )
    row = {
        "side": args.side,
        "label": args.label,
        "regime": args.regime,
        "overrides": args.overrides,
        "seeds": args.seeds,
        "updates": args.updates,
        "date": time.strftime("%Y-%m-%d %H:%M"),
        **result,
    }
    ROWS.parent.mkdir(parents=True, exist_ok=True)
    with ROWS.open("a") as f:
        f.write(json.dumps(row) + "\n")
    print(
        json.dumps(
            {
                k: row[k]
                for k in (
                    "side",
                    "label",
                    "env_steps_per_seed",
                    "deterministic",
                    "stochastic",
                    "seconds",
                )
            }
        )
    )


if __name__ == "__main__":
    main()
