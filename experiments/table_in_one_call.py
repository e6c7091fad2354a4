"""What a whole table costs: the pendulum's Table 2 trained by the command a user types.

    python experiments/table_in_one_call.py --seeds 5,20 [--env pendulum] [--alone]
                                            [--keep runs/classic20]
    python experiments/table_in_one_call.py --cpu-updates 3  # the training rate on this CPU

For each seed count it runs `experiments/classic_control.py --table 2 --envs <env> --seeds S`
on the table's learner rows (PPO-RGB, PPO-x, PPO-x+N(0,1) and HINTS-FC with every hint; the
references expert_ppo, dagger and gail are left out: dagger and gail need the expert's run
first) into a fresh runs folder, and times the whole command, compiles and evaluation included.
The rows go to experiments/results/table_in_one_call.json with the fields
`env, rows, seeds, wall_s, env_steps_per_s, ceiling_fraction, device, devices, deterministic`
and more (devices: the GPUs visible, all of which every worker's run spreads its seeds over):
env_steps_per_s is every row's training env steps over the command's wall-clock;
ceiling_fraction is that rate x PPO's epochs (gradient samples/s) over the network's own update
ceiling, measured in this process (experiments/bench.py's `ceiling`). `--alone` trains each row
in its own program (as before groups) for comparison; `--keep` keeps the runs folder.

`--cpu-updates N` instead times N updates of the table's biggest group (HINTS-FC with every hint,
5 seeds) through pipeline.train_group on the CPU, compiles apart, and reports its env steps/s beside
the authors' PyTorch implementation's 45 env steps/s (SPEC.md: 2 CPU cores, its own settings).
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

import jax

HERE = Path(__file__).resolve().parent
RESULTS = HERE / "results" / "table_in_one_call.json"
AUTHORS_CPU_ENV_STEPS_PER_S = 45.0  # SPEC.md: the authors' PyTorch implementation, 2 CPU cores


def learner_rows(env: str) -> list[str]:
    from classic_control import REFERENCES, table_runs

    return [label for label in table_runs(2, env) if label not in REFERENCES]


def record(row: dict) -> None:
    """Add `row` to the results file, replacing an earlier row of the same kind."""
    rows = json.loads(RESULTS.read_text()) if RESULTS.exists() else []
    same = ("env", "seeds", "device", "devices", "grouped", "platform", "sweep_args")
    rows = [r for r in rows if any(r.get(k) != row.get(k) for k in same)] + [row]
    RESULTS.write_text(json.dumps(rows, indent=1) + "\n")


def table(
    env: str, seeds: int, alone: bool, workers: int, runs: Path, sweep_args: list[str] = ()
) -> dict:
    import hintsjax

    labels = learner_rows(env)
    cmd = [
        sys.executable,
        str(HERE / "classic_control.py"),
        "--table",
        "2",
        "--envs",
        env,
        "--seeds",
        str(seeds),
        "--runs",
        str(runs),
        "--only",
        ",".join(labels),
        "--workers",
        str(workers),
        *(["--alone"] if alone else []),
        *sweep_args,
    ]
    print(" ".join(cmd), flush=True)
    t = time.perf_counter()
    subprocess.run(cmd, check=True)
    wall = time.perf_counter() - t
    results = [json.loads((runs / env / label / "eval.json").read_text()) for label in labels]
    env_steps = sum(r["env_steps"] * seeds for r in results)
    from hintsjax.settings.layers import run_config

    epochs = run_config({"env": env, "agent": "hints"}).ppo.epochs
    groups = {tuple(r.get("group", [r["label"]])) for r in results}
    return {
        "env": env,
        "rows": labels,
        "seeds": seeds,
        "wall_s": round(wall, 1),
        "env_steps_per_s": round(env_steps / wall),
        "epochs": epochs,
        "device": jax.devices()[0].device_kind,
        "devices": len(jax.devices()),
        "deterministic": hintsjax.deterministic_gpu_ops(),
        "platform": jax.default_backend(),
        "jax": jax.__version__,
        "grouped": not alone,
        "workers": workers,
        "groups": [list(g) for g in sorted(groups, key=len, reverse=True)],
        "sweep_args": list(sweep_args),
        "env_steps": env_steps,
        "train_seconds": {r["label"]: round(r["train_seconds"], 1) for r in results},
        "compile_seconds": {r["label"]: r["compile_seconds"] for r in results},
        "command": " ".join(["python", "experiments/classic_control.py", *cmd[2:]]).replace(
            str(runs), "<runs>"
        ),
    }


def cpu_rate(env: str, seeds: int, updates: int) -> dict:
    """Env steps/s of `updates` updates of the table's HINTS-FC group on this machine's CPU."""
    from hintsjax.settings.layers import run_config, save_run_config
    from hintsjax.training import pipeline
    from hintsjax.reproduce.sweep import run_values

    labels = [label for label in learner_rows(env) if label.startswith("hints-")]
    cfgs = [run_config(run_values(env, label, seeds)) for label in labels]
    steps = updates * cfgs[0].ppo.batch_size
    cfgs = [
        run_config(
            {
                **run_values(env, label, seeds),
                "checkpoint_every": updates,
                "eval_episodes": 1,
                "ppo": {"total_env_steps": steps},
            }
        )
        for label in labels
    ]
    with tempfile.TemporaryDirectory() as folder:
        dirs = [Path(folder) / c.label for c in cfgs]
        for d, c in zip(dirs, cfgs):
            d.mkdir()
            save_run_config(d, c)
        results = pipeline.train_group(cfgs, Path(folder) / "group", dirs, progress=False)
    rate = results[0]["train_env_steps_per_s"] * len(cfgs)  # per member x members
    return {
        "env": env,
        "rows": labels,
        "seeds": seeds,
        "updates": updates,
        "platform": "cpu",
        "device": f"{os.cpu_count()} CPU cores",
        "env_steps_per_s": round(rate, 1),
        "authors_env_steps_per_s": AUTHORS_CPU_ENV_STEPS_PER_S,
        "ratio": round(rate / AUTHORS_CPU_ENV_STEPS_PER_S, 1),
        "compile_seconds": results[0]["compile_seconds"],
        "grouped": True,
        "note": f"training only (compiles apart), {updates} updates of the {len(cfgs)}-row "
        "HINTS-FC group extrapolated to the table; the other rows (PPO-RGB, PPO-x) train at a "
        "similar or higher rate",
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="pendulum")
    parser.add_argument("--seeds", default="5,20", help="comma-separated seed counts")
    parser.add_argument(
        "--alone", action="store_true", help="every row in its own program (as before groups)"
    )
    parser.add_argument(
        "--workers", type=int, default=3, help="groups trained at once (classic_control --workers)"
    )
    parser.add_argument(
        "--keep", type=Path, default=None, help="train into this runs folder and keep it"
    )
    parser.add_argument(
        "--cpu-updates", type=int, default=0, help="time this many updates on the CPU instead"
    )
    parser.add_argument(
        "--gpus",
        default="",
        help="classic_control --gpus: one GPU per worker (default: every "
        "worker spreads its seeds over all visible GPUs)",
    )
    parser.add_argument(
        "--group-size", type=int, default=0, help="classic_control --group-size (0: no limit)"
    )
    args = parser.parse_args()
    if args.cpu_updates:
        os.environ["JAX_PLATFORMS"] = "cpu"
        row = cpu_rate(args.env, 5, args.cpu_updates)
        print(json.dumps(row), flush=True)
        record(row)
        return
    # This process measures the ceiling after the tables; until then it must not hold the
    # device's memory (JAX preallocates 75 % of it on first use), which the workers need.
    os.environ["XLA_PYTHON_CLIENT_PREALLOCATE"] = "false"
    from bench import bench_ceiling

    rows = []
    for seeds in [int(s) for s in args.seeds.split(",")]:
        with tempfile.TemporaryDirectory() as tmp:
            runs = args.keep / f"seeds{seeds}" if args.keep else Path(tmp)
            sweep_args = [
                *(["--gpus", args.gpus] if args.gpus else []),
                *(["--group-size", str(args.group_size)] if args.group_size else []),
            ]
            rows.append(table(args.env, seeds, args.alone, args.workers, runs, sweep_args))
    ceiling = bench_ceiling(8192)["update_samples_per_s"]
    print(f"ceiling: {ceiling:,.0f} samples/s", flush=True)
    for row in rows:
        row.update(
            ceiling_fraction=round(row["env_steps_per_s"] * row.pop("epochs") / ceiling, 3),
            ceiling_samples_per_s=round(ceiling),
        )
        print(
            json.dumps(
                {
                    k: row[k]
                    for k in ("env", "seeds", "wall_s", "env_steps_per_s", "ceiling_fraction")
                }
            ),
            flush=True,
        )
        record(row)


if __name__ == "__main__":
    main()
