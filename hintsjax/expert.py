"""Trained experts: the policy of an `expert_ppo` run, exported for DAgger and GAIL to learn from.

    python -m hintsjax.run env=pendulum agent=expert_ppo name=expert-pendulum   # train (5 seeds)
    python -m hintsjax.expert runs/expert-pendulum  # -> hintsjax/experts/pendulum

The export and the loading are hintsjax/algorithms/experts.py.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


from hintsjax.cli.arguments import ArgumentParser
from hintsjax.system.errors import command
from hintsjax.cli import choices
from hintsjax.algorithms.experts import EXPERT_JSON, export


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(
        prog="python -m hintsjax.expert",
        description=__doc__.splitlines()[0],
        epilog=choices.text(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run", type=Path, help="a finished run folder of agent=expert_ppo")
    parser.add_argument(
        "--out", type=Path, default=None, help="expert folder (default: hintsjax/experts/<env>)"
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="replace the expert in that folder (a packaged one, by default)",
    )
    args = parser.parse_args(argv)
    out = export(args.run, args.out, args.force)
    meta = json.loads((out / EXPERT_JSON).read_text())
    print(
        f"expert for {meta['env']}: seed {meta['seed_index']} of {args.run} "
        f"({meta['seed_eval_mean']:.2f} over {meta['episodes_per_seed']} episodes) -> {out}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
