"""How many configurations x seeds of a table's HINTS-FC group fit on this device.

    python experiments/group_memory.py [--envs pendulum,idp] [--sizes 1x20,2x20,4x20] [--out FILE]

For each env and each K x S (K hint configurations of Table 2, S seeds) it compiles the group's
training chunk (`compilation.compile_training`, what the sweeps run) without running it and reads
XLA's memory analysis: arguments + outputs + temporaries, the figure `compilation.check_fits`
compares with 90 % of the device's memory. The need grows linearly in K x S (the rows show it);
the last line per env extrapolates the number of runs that fit.
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import jax

from hintsjax.settings.layers import run_config
from hintsjax.algorithms.group import make_group, make_group_trainer
from hintsjax.training import compilation

from classic_control import TABLE2_HINTS  # experiments/, beside this script

HINTS = TABLE2_HINTS  # Table 2's hint rows per classic env


def need_bytes(env: str, configs: int, seeds: int) -> int:
    cfgs = [
        run_config(
            {
                "env": env,
                "agent": "hints",
                "scheme": "fc",
                "hint": HINTS[env][k % len(HINTS[env])],
                "seeds": seeds,
            }
        )
        for k in range(configs)
    ]
    group = make_group(cfgs)
    compiled = compilation.compile_training(
        make_group_trainer(group), group.cfgs[0].seed_keys(), 10
    )
    a = compiled.run_chunk.memory_analysis()
    return a.temp_size_in_bytes + a.argument_size_in_bytes + a.output_size_in_bytes


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--envs", default="pendulum,idp", help=f"comma-separated subset of {', '.join(HINTS)}"
    )
    parser.add_argument(
        "--sizes", default="1x20,2x20,4x20", help="comma-separated KxS: configurations x seeds"
    )
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    names = [e for e in args.envs.split(",") if e]
    if not names or any(e not in HINTS for e in names):
        parser.exit(2, f"error: --envs takes a comma-separated subset of {', '.join(HINTS)}\n")
    try:
        sizes = [tuple(int(n) for n in s.split("x")) for s in args.sizes.split(",")]
    except ValueError:
        sizes = []
    if not sizes or not all(len(s) == 2 and min(s) > 0 for s in sizes):
        parser.exit(2, "error: --sizes takes KxS pairs of positive numbers, e.g. 1x20,2x20\n")
    stats = jax.devices()[0].memory_stats() or {}
    limit = stats.get("bytes_limit")
    rows = []
    for env in names:
        points = []
        for k, s in sizes:
            need = need_bytes(env, k, s)
            points.append((k * s, need))
            rows.append(
                {"env": env, "configs": k, "seeds": s, "runs": k * s, "need_gib": need / 2**30}
            )
            print(
                f"{env}: {k} configurations x {s} seeds = {k * s} runs need {need / 2**30:.2f} GiB",
                flush=True,
            )
        if limit and len(points) >= 2:
            (r0, b0), (r1, b1) = points[0], points[-1]
            per_run = (b1 - b0) / (r1 - r0)
            fit = int((0.9 * limit - (b0 - per_run * r0)) // per_run)
            rows.append(
                {
                    "env": env,
                    "per_run_gib": per_run / 2**30,
                    "fixed_gib": (b0 - per_run * r0) / 2**30,
                    "runs_that_fit": fit,
                    "device_gib": limit / 2**30,
                }
            )
            print(
                f"{env}: {per_run / 2**20:.0f} MiB per run; about {fit} runs fit in 90 % of the "
                f"device's {limit / 2**30:.1f} GiB (e.g. {fit // 20} configurations x 20 seeds)",
                flush=True,
            )
    if args.out:
        args.out.write_text(
            json.dumps(
                {
                    "device": jax.devices()[0].device_kind,
                    "jax": jax.__version__,
                    "command": "python experiments/group_memory.py --envs "
                    + args.envs
                    + " --sizes "
                    + args.sizes,
                    "rows": rows,
                },
                indent=1,
            )
            + "\n"
        )


if __name__ == "__main__":
    main()
