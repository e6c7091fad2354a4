"""Where `make run` ends, and how long it takes, on this machine's CPU: the quickstart at several seeds.

    python experiments/quickstart_spread.py [--seeds 0,1,2,3] [--parallel 1] [--cores 2]
                                            [--quickstart '--epochs 4'] [--out FILE]

Runs the command `make run` types (`python -m hintsjax.quickstart`, on the CPU) once per seed
(`--seed s`; `make run` itself is seed 0), `--parallel` at a time, each pinned to `--cores` cores
of its own (taskset) so that a machine of many cores measures what a 2-core laptop would. A
chaotic training run gives other digits on another CPU kind (XLA's CPU code differs between AVX2
and AVX-512), so the spread over seeds on several CPU kinds is what the README can promise.
Each row: the seed, the command's wall-clock, its compile and training seconds, the trained
agent's mean return over 20 episodes and the random policy's; with the CPU's name, jax's version
and Python's. Written to `--out`; experiments/results/quickstart_spread.md reports the committed
runs, one JSON file per CPU kind (quickstart_spread_epyc.json, quickstart_spread_xeon.json).
"""  # noqa: E501

from __future__ import annotations

import argparse
import json
import os
import platform
import queue
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from importlib.metadata import version
from pathlib import Path


def cpu_name() -> str:
    """The CPU's model name (Linux's /proc/cpuinfo), or the platform's processor string."""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown"


def isa() -> str:
    """The widest x86 vector extension the CPU reports: avx512f, avx2 or other."""
    try:
        flags = Path("/proc/cpuinfo").read_text()
    except OSError:
        return "unknown"
    return next((f for f in ("avx512f", "avx2") if f" {f}" in flags), "other")


def one(seed: int, cores: list[int] | None, out_dir: Path, extra: list[str]) -> dict:
    """Run the quickstart at `seed` (pinned to `cores`, with `extra` arguments) and read back its
    run folder's results."""
    command = [
        sys.executable,
        "-m",
        "hintsjax.quickstart",
        "--seed",
        str(seed),
        "--out-dir",
        str(out_dir),
        *extra,
    ]
    if cores and shutil.which("taskset"):
        command = ["taskset", "-c", ",".join(map(str, cores)), *command]
    # a first run: cold
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "HINTSJAX_COMPILATION_CACHE": "off"}
    t = time.perf_counter()
    done = subprocess.run(command, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t
    if done.returncode:
        return {"seed": seed, "returncode": done.returncode, "stderr": done.stderr[-2000:]}
    run = next(out_dir.glob("quickstart-*"))
    result = json.loads((run / "eval.json").read_text())
    baseline = json.loads((run / "random_policy.json").read_text())
    return {
        "seed": seed,
        "arguments": " ".join(extra),
        "wall_s": round(wall, 1),
        "compile_s": result["compile_seconds"],
        "train_s": round(result["train_seconds"], 1),
        "trained": round(result["evaluations"][0]["mean"], 1),
        "random": round(baseline["mean"], 1),
        "last_lines": done.stdout.strip().splitlines()[-6:],
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--seeds", default="0,1,2,3", help="comma-separated seeds (default: 0,1,2,3)"
    )
    parser.add_argument("--parallel", type=int, default=1, help="runs at a time (default: 1)")
    parser.add_argument(
        "--cores", type=int, default=2, help="cores pinned to each run (0: no pinning; default: 2)"
    )
    parser.add_argument(
        "--quickstart",
        default="",
        help="more arguments for the quickstart, e.g. '--epochs 4 --updates 40'",
    )
    parser.add_argument(
        "--out", type=Path, default=Path("experiments/results/quickstart_spread.json")
    )
    args = parser.parse_args()
    seeds = [int(s) for s in args.seeds.split(",")]
    available = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
    slots: queue.Queue = queue.Queue()  # each run takes a free set of cores and gives it back
    for slot in range(args.parallel):
        slots.put(available[slot * args.cores : (slot + 1) * args.cores] if args.cores else None)
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.parallel) as pool:

        def task(seed: int) -> dict:
            cores = slots.get()
            folder = Path(tmp) / f"seed{seed}"
            folder.mkdir()
            try:
                row = one(seed, cores, folder, args.quickstart.split())
            finally:
                slots.put(cores)
            print(json.dumps(row), flush=True)
            return row

        rows = list(pool.map(task, seeds))
    record = {
        "command": "python -m hintsjax.quickstart --seed S (make run is seed 0), "
        "JAX_PLATFORMS=cpu, cold caches",
        "cpu": cpu_name(),
        "isa": isa(),
        "cores_per_run": args.cores,
        "runs_at_once": args.parallel,
        "python": platform.python_version(),
        "jax": version("jax"),
        "jaxlib": version("jaxlib"),
        "date": time.strftime("%Y-%m-%d"),
        "rows": rows,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
