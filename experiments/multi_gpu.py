"""One run's speed on 1, 2 and 4 GPUs: the command a user types, timed at several seed counts.

    python experiments/multi_gpu.py --gpus 0 0,1 0,1,2,3 --seeds 5,20 [--steps 262144]
                                    [--xla-flags ...]

For each set of GPUs (CUDA_VISIBLE_DEVICES) and seed count it runs
`python -m hintsjax.run env=pendulum agent=hints hint=composite scheme=fc seeds=S
ppo.total_env_steps=STEPS` in a fresh runs folder and reads eval.json: training seconds
(compiles apart), env steps/s, compile seconds, the device count the run used and its
evaluation. Rows go to experiments/results/multi_gpu.json with the command and the hardware;
`speedup` is against the row of the same seeds on the first GPU set. `--xla-flags` adds
XLA_FLAGS to every run (e.g. command buffers for while loops) and is recorded in the rows.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "multi_gpu.json"
CELL = ["env=pendulum", "agent=hints", "hint=composite", "scheme=fc"]


def gpu_name() -> str:
    out = subprocess.run(
        ["nvidia-smi", "--query-gpu=name", "--format=csv,noheader"], capture_output=True, text=True
    )
    return (
        out.stdout.strip().splitlines()[0]
        if out.returncode == 0 and out.stdout.strip()
        else "unknown"
    )


def one(gpus: str, seeds: int, steps: int, xla_flags: str, runs: Path, extra: list[str]) -> dict:
    name = f"g{gpus.replace(',', '')}-s{seeds}"
    shown = [*CELL, f"seeds={seeds}", f"ppo.total_env_steps={steps}", *extra]
    args = [*shown, f"out_dir={runs}", f"name={name}"]
    env = {**os.environ, "CUDA_VISIBLE_DEVICES": gpus}
    if xla_flags:
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {xla_flags}".strip()
    t = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-m", "hintsjax.run", *args], env=env, capture_output=True, text=True
    )
    wall = time.perf_counter() - t
    if proc.returncode:
        print(proc.stdout[-2000:], proc.stderr[-4000:], file=sys.stderr)
        return {"gpus": gpus, "seeds": seeds, "failed": proc.returncode}
    result = json.loads((runs / name / "eval.json").read_text())
    ev = result["evaluations"][0]
    return {
        "gpus": gpus,
        "devices": result["devices"],
        "seeds": seeds,
        "env_steps": steps,
        "train_s": round(result["train_seconds"], 1),
        "env_steps_per_s": round(result["train_env_steps_per_s"]),
        "compile_s": {k: round(v, 1) for k, v in result["compile_seconds"].items()},
        "wall_s": round(wall, 1),
        "return": round(ev["mean"], 2),
        "return_seed_std": round(ev["seed_std"], 2),
        "xla_flags": xla_flags or None,
        "command": f"CUDA_VISIBLE_DEVICES={gpus} python -m hintsjax.run {' '.join(shown)}",
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--gpus",
        nargs="+",
        default=["0", "0,1", "0,1,2,3"],
        help="GPU sets, each comma-separated ids",
    )
    parser.add_argument("--seeds", default="5,20", help="comma-separated seed counts")
    parser.add_argument(
        "--steps", type=int, default=262144, help="ppo.total_env_steps per seed (a quarter budget)"
    )
    parser.add_argument("--xla-flags", default="", help="XLA_FLAGS added to every run")
    parser.add_argument(
        "--tag", default="", help="a name for this set of rows (kept in the results file)"
    )
    parser.add_argument(
        "--results",
        type=Path,
        default=RESULTS,
        help=f"the results file (default {RESULTS.relative_to(HERE.parent)})",
    )
    parser.add_argument("extra", nargs="*", help="more key=value settings for every run")
    args = parser.parse_args()
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seeds in [int(s) for s in args.seeds.split(",")]:
            for gpus in args.gpus:
                row = one(gpus, seeds, args.steps, args.xla_flags, Path(tmp), args.extra)
                base = next((r for r in rows if r["seeds"] == seeds and "failed" not in r), None)
                if base is not None and "failed" not in row:
                    row["speedup"] = round(base["train_s"] / row["train_s"], 2)
                print(json.dumps(row), flush=True)
                rows.append(row)
    record = {
        "tag": args.tag,
        "device": gpu_name(),
        "finished": time.strftime("%Y-%m-%d %H:%M"),
        "rows": rows,
    }
    kept = json.loads(args.results.read_text()) if args.results.exists() else []
    args.results.write_text(json.dumps(kept + [record], indent=1) + "\n")


if __name__ == "__main__":
    main()
