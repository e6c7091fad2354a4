"""What the command a user types delivers: `python -m hintsjax.run` timed end to end, beside the bench.

    python experiments/run_path.py [--cells pendulum,ant,ant_fast,humanoid] [--updates 200]
                                   [--physics jax,warp] [--no-bench]
                                   [--out experiments/results/run_path.json]

For each cell (pendulum: hints/fc/composite; ant: hints/fc/speed; humanoid: hints/fc/velocity;
the env defaults otherwise), the command runs twice in a fresh process, first with an empty compilation cache (cold), then
with the cache the first run filled (warm). Each row: `cell_wall_s` (the whole command, start-up,
compiles, training, evaluation and plotting), `compile_s` (training and evaluation programs),
`train_env_steps_per_s` (the command's training rate, compile excluded), and
`bench_env_steps_per_s` (the same compiled chunks called back to back with nothing else on the
host: experiments/bench.py's `scan_env_steps_per_s`), and the milliseconds of one update's
parts, measured in this process on the same device. A cell whose full budget
does not fit a device lease (the ant's 5 M steps) is trained for `--updates` updates and its
full wall is extrapolated at the measured rate: such rows say so (`updates`, `full_cell_wall_s`).
With `--physics jax,warp` each cell runs once per physics (`physics=...` on the command line),
cold and warm, with its own empty caches: XLA's and MuJoCo Warp's kernel cache ($WARP_CACHE_PATH),
so a cold warp row compiles Warp's CUDA kernels too.
"""  # noqa: E501

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

CELLS = {
    "pendulum": ["env=pendulum", "agent=hints", "hint=composite", "scheme=fc"],
    "ant": ["env=ant", "agent=hints", "hint=speed", "scheme=fc"],
    # a different, cheaper task on the ant's body (Euler, 2 Newton iterations, 9 contacts:
    # docs/environments.md)
    "ant_fast": ["env=ant_fast", "agent=hints", "hint=speed", "scheme=fc"],
    "humanoid": ["env=humanoid", "agent=hints", "hint=velocity", "scheme=fc"],
}
# cells trained for --updates updates, their full wall extrapolated
PARTIAL = ("ant", "ant_fast", "humanoid")


def timed_command(args: list[str], cache: Path, out_dir: Path) -> tuple[float, dict]:
    """Run the command once (MuJoCo Warp's kernels cached beside XLA's); (wall seconds, its
    eval.json)."""
    name = f"r{time.time_ns()}"
    t = time.perf_counter()
    subprocess.run(
        [
            sys.executable,
            "-m",
            "hintsjax.run",
            *args,
            f"out_dir={out_dir}",
            f"name={name}",
            f"compilation_cache={cache}",
        ],
        check=True,
        env={**os.environ, "WARP_CACHE_PATH": str(cache / "warp")},
    )
    wall = time.perf_counter() - t
    return wall, json.loads((out_dir / name / "eval.json").read_text())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--cells", default="pendulum,ant", help=f"comma-separated subset of {', '.join(CELLS)}"
    )
    parser.add_argument(
        "--updates",
        "--ant-updates",
        type=int,
        default=200,
        help=f"updates of the locomotion cells ({', '.join(PARTIAL)}: "
        "the ant's full budget is 4882)",
    )
    parser.add_argument(
        "--physics", default="jax", help="comma-separated: auto, jax, warp (one row pair each)"
    )
    parser.add_argument(
        "--no-bench", action="store_true", help="the command's rows only (no bench row)"
    )
    parser.add_argument("--out", type=Path, default=None)
    args = parser.parse_args()
    cells = [c for c in args.cells.split(",") if c]
    unknown = [c for c in cells if c not in CELLS]
    if unknown:
        parser.exit(2, f"error: unknown cell {unknown}; valid choices: {', '.join(CELLS)}\n")
    if args.updates < 1:
        parser.exit(2, "error: --updates must be at least 1\n")
    import jax

    from hintsjax.system import compilation_cache
    from hintsjax.settings.layers import run_config
    from bench import bench_train

    rows = []
    for cell, physics in [(c, p) for c in cells for p in args.physics.split(",")]:
        values = dict(a.split("=") for a in CELLS[cell])
        cfg = run_config({**values, "physics": physics})
        budget = [f"physics={physics}"]
        if cell in PARTIAL:
            budget += [f"ppo.total_env_steps={args.updates * cfg.ppo.batch_size}"]
        cache = Path(tempfile.mkdtemp(prefix="xla-cache-"))
        with tempfile.TemporaryDirectory() as out:
            for warm in (False, True):
                wall, result = timed_command(CELLS[cell] + budget, cache, Path(out))
                updates = result["env_steps"] // cfg.ppo.batch_size
                compile_s = sum(result["compile_seconds"].values())
                row = {
                    "env": cell,
                    "label": result["label"],
                    "physics": result["physics"],
                    "cell_wall_s": wall,
                    "compile_s": compile_s,
                    "compile_s_parts": result["compile_seconds"],
                    "updates": updates,
                    "train_env_steps_per_s": result["train_env_steps_per_s"],
                    "chunks_env_steps_per_s": result.get("chunks_env_steps_per_s"),
                    "device": jax.devices()[0].device_kind,
                    "jax": jax.__version__,
                    # the run's own (physics=warp turns them off)
                    "deterministic": result["deterministic"],
                    "warm_cache": warm,
                }
                # extrapolated to the full budget at the measured rate
                if updates < cfg.ppo.num_updates:
                    rest = (cfg.ppo.num_updates - updates) * cfg.ppo.batch_size * cfg.seeds
                    row["full_cell_wall_s"] = wall + rest / result["train_env_steps_per_s"]
                rows.append(row)
                print(json.dumps(row), flush=True)
        if args.no_bench:
            shutil.rmtree(cache, ignore_errors=True)
            continue
        compilation_cache.enable(cache)  # the bench's programs are the command's: compiled above
        bench = bench_train(cell, cfg.seeds, 40, {}, physics=physics)
        shutil.rmtree(cache, ignore_errors=True)
        for row in rows:
            if row["env"] == cell and row["physics"] == cfg.physics:
                row["bench_env_steps_per_s"] = bench["scan_env_steps_per_s"]
                row["cli_fraction_of_bench"] = (
                    row["train_env_steps_per_s"] / bench["scan_env_steps_per_s"]
                )
                # training's start to the last chunk: the bench's span
                if row["chunks_env_steps_per_s"] is not None:
                    row["chunks_fraction_of_bench"] = (
                        row["chunks_env_steps_per_s"] / bench["scan_env_steps_per_s"]
                    )
                row["update_parts_s"] = bench["update_parts_s"]
        print(json.dumps({"bench": bench}), flush=True)
    if args.out:
        args.out.write_text(
            json.dumps(
                {
                    "command": "python experiments/run_path.py " + " ".join(sys.argv[1:]),
                    "rows": rows,
                },
                indent=1,
            )
            + "\n"
        )


if __name__ == "__main__":
    os.environ.setdefault("PYTHONUNBUFFERED", "1")
    main()
