"""The machinery that the reproduction sweeps share (classic_control.py, locomotion.py, car_racing.py).

A run is named `env/label`, where the label is `RunConfig.label` (an agent's name, or
hints-<scheme>-<hint>); its folder runs/<sweep>/env/label holds config.yaml, metrics.csv,
train.log and, once finished, eval.json. `sweep` trains every unfinished run of a list,
`workers` processes at a time, each a call of this file with `--one env/label`:

    python experiments/sweep.py --runs runs/classic --seeds 5 --one idp/ppo_rgb [--smoke]

`table_main` is a table script's command line: train its runs, or `--report` (archive the
finished runs, then write the tables with report.py's readers).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

from report import archive_runs, load

# A sweep's runs save at most once a minute: fast runs finish 50 updates in seconds, and a big
# run's checkpoint (every env's MJX state) can reach a GB; an interruption loses at most a minute.
CHECKPOINT_SECONDS = 60
CHILD_ENVIRON = dict(os.environ)  # the workers' environment: a sweep's parent process keeps off the GPU
EXPERT_RUN = "expert_ppo"  # the run whose best seed becomes its env's expert for dagger and gail


def hints_run(scheme: str, hint: str) -> str:
    return f"hints-{scheme}-{hint}"


# --smoke: a tiny budget to check the sweep's plumbing on a CPU (the numbers mean nothing).
SMOKE = {"eval_episodes": 2, "ppo": {"total_env_steps": 1024, "num_envs": 8, "batch_size": 512,
                                     "minibatch_size": 256, "epochs": 1}}


def run_values(env: str, label: str, seeds: int, smoke: bool = False, experts: Path | None = None) -> dict:
    """Config values of a run label (the inverse of RunConfig.label)."""
    from hintsjax.agents import AGENTS

    values = {"env": env, "seeds": seeds, "checkpoint_every": 50, "checkpoint_seconds": CHECKPOINT_SECONDS,
              **(SMOKE if smoke else {})}
    if label in AGENTS and AGENTS[label].imitates:
        return {**values, "agent": label, "expert": None if experts is None else str(experts / env)}
    if label in AGENTS:
        return {**values, "agent": label}
    _, scheme, hint = label.split("-", 2)
    return {**values, "agent": "hints", "scheme": scheme, "hint": hint}


def train_one(runs: Path, run_id: str, seeds: int, smoke: bool, experts: Path | None) -> None:
    """Train and evaluate one configuration `env/label` into runs/env/label; export an expert's."""
    import jax

    import hintsjax
    from hintsjax import checkpoint, expert, run
    from hintsjax.config import run_config, save_run_config

    env, label = run_id.split("/")
    cfg = run_config(run_values(env, label, seeds, smoke, experts))
    assert cfg.label == label, (cfg.label, label)
    folder = runs / env / label
    folder.mkdir(parents=True, exist_ok=True)
    save_run_config(folder, cfg)
    # An interrupted run (killed by a time limit) goes on from its newest checkpoint; its
    # wall-clock counts the kept work of earlier calls, not what was lost after their last checkpoint.
    resume = checkpoint.latest_update(folder) is not None
    before, t = run.seconds_trained(folder) if resume else 0.0, time.time()
    if resume:
        print(f"resuming {run_id} from update {checkpoint.latest_update(folder)}", flush=True)
    results = run.train(cfg, folder, resume=resume, progress=False)
    results["wall_seconds"] = before + time.time() - t
    results["device"] = jax.devices()[0].device_kind
    results["deterministic"] = jax.default_backend() == "cpu" or hintsjax.deterministic_gpu_ops()
    (folder / "eval.json").write_text(json.dumps(results, indent=1))
    if label == EXPERT_RUN:
        print(f"exported the expert to {expert.export(folder, None if experts is None else experts / env)}", flush=True)


def prerequisite(run_id: str) -> str | None:
    """The run that must finish before this one starts: an env's expert, for its dagger and gail."""
    from hintsjax.agents import AGENTS

    env, label = run_id.split("/")
    return f"{env}/{EXPERT_RUN}" if label in AGENTS and AGENTS[label].imitates else None


def budget(run_id: str) -> float:
    """Rough relative cost of a run, to start the longest first."""
    from hintsjax.config import run_config

    env, label = run_id.split("/")
    cfg = run_config(run_values(env, label, 1))
    return cfg.ppo.total_env_steps * (1.0 if cfg.agent_spec.pixels else 0.3)


def sweep(runs: Path, run_ids: list[str], workers: int, seeds: int, table: int | str, smoke: bool,
          launch_until: float = float("inf"), experts: Path | None = None, gpus: tuple[str, ...] = ()) -> None:
    """Train every unfinished run, `workers` processes at a time, starting none after
    `launch_until` seconds (so that a time-limited call ends with finished runs, not killed
    ones); append the sweep's wall-clock to runs/sweeps.jsonl. With `gpus` (CUDA device ids),
    each worker gets the least busy of them to itself (CUDA_VISIBLE_DEVICES); without, all
    workers share the visible devices."""
    todo = sorted((r for r in run_ids if not (runs / r / "eval.json").exists()), key=budget, reverse=True)
    print(f"table {table}: {len(run_ids) - len(todo)} of {len(run_ids)} runs done already; "
          f"training {len(todo)} with {workers} worker(s)", flush=True)
    launched = 0
    per_gpu = -(-workers // max(len(gpus), 1))  # workers sharing one device
    env = {**CHILD_ENVIRON, "XLA_PYTHON_CLIENT_MEM_FRACTION": f"{0.9 / per_gpu:.3f}"}
    start = time.time()
    active: list[tuple[str, subprocess.Popen]] = []  # each worker writes its own train.log
    gpu_of: dict[str, str] = {}
    failed: list[str] = []
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # `timeout` stops the sweep: record it below
    try:
        while todo or active:
            if todo and time.time() - start > launch_until:
                print(f"[{time.time() - start:6.0f} s] --launch-until reached: {len(todo)} runs left for the next sweep",
                      flush=True)
                todo = []
            waiting = {r for r in todo} | {r for r, _ in active}
            todo = [r for r in todo if prerequisite(r) not in failed]
            ready = [r for r in todo if prerequisite(r) not in waiting]
            while ready and len(active) < workers:
                run_id = ready.pop(0)
                todo.remove(run_id)
                (runs / run_id).mkdir(parents=True, exist_ok=True)
                cmd = [sys.executable, str(Path(__file__).resolve()), "--runs", str(runs), "--seeds", str(seeds), "--one", run_id,
                       *(["--smoke"] if smoke else []), *(["--experts", str(experts)] if experts else [])]
                if gpus:
                    busy = [gpu_of[r] for r, _ in active]
                    gpu_of[run_id] = min(gpus, key=busy.count)
                child_env = {**env, "CUDA_VISIBLE_DEVICES": gpu_of[run_id]} if gpus else env
                with open(runs / run_id / "train.log", "w") as log:  # the child keeps its own copy
                    active.append((run_id, subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT, env=child_env)))
                launched += 1
            time.sleep(2)
            for run_id, proc in list(active):
                if proc.poll() is None:
                    continue
                active.remove((run_id, proc))
                if proc.returncode:
                    failed.append(run_id)
                print(f"[{time.time() - start:6.0f} s] {run_id}: "
                      f"{'FAILED (see ' + str(runs / run_id / 'train.log') + ')' if proc.returncode else 'done'}", flush=True)
    finally:
        for _, proc in active:  # interrupted: these runs are retrained by the next sweep
            proc.terminate()
        seconds = time.time() - start
        record = {"table": table, "runs": len(run_ids), "trained": launched - len(failed) - len(active),
                  "failed": failed, "interrupted": [r for r, _ in active], "workers": workers, "seconds": seconds,
                  "finished": time.strftime("%Y-%m-%d %H:%M:%S"), "gpus": list(gpus)}
        devices = {(load(runs, *r.split("/")) or {}).get("device", "").lower() for r in run_ids} - {""}
        if devices == {"cpu"}:  # the workers' device (the parent keeps off it): CPU sweeps leave the GPU totals
            record["device"] = "cpu"
        with open(runs / "sweeps.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")
        print(f"table {table}: {seconds:.0f} s wall-clock" + (f", {len(active)} runs interrupted" if active else ""), flush=True)
    if failed:
        sys.exit(1)


def add_arguments(parser: argparse.ArgumentParser, runs: str, envs: tuple[str, ...]) -> None:
    """The options every sweep script takes (`runs`: the default runs folder)."""
    parser.add_argument("--report", action="store_true", help="only write the result tables and curves")
    parser.add_argument("--force", action="store_true",
                        help="with --report: rewrite a table even where it would blank cells the committed one fills")
    parser.add_argument("--envs", default=",".join(envs), help=f"comma-separated subset of {', '.join(envs)}")
    parser.add_argument("--runs", type=Path, default=Path(runs))
    parser.add_argument("--workers", type=int, default=1, help="configurations trained at once")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--smoke", action="store_true", help="tiny budgets: check the plumbing on a CPU")
    parser.add_argument("--gpus", type=lambda s: tuple(g for g in s.split(",") if g), default=(), metavar="IDS",
                        help="comma-separated CUDA device ids; each worker gets the least busy one to itself")
    parser.add_argument("--launch-until", type=float, default=float("inf"), metavar="SECONDS",
                        help="start no run after this many seconds; running ones finish (for time-limited machines)")
    parser.add_argument("--only", type=lambda s: tuple(x for x in s.split(",") if x), default=(), metavar="LABELS",
                        help="comma-separated run labels (e.g. ppo_rgb,hints-fc-speed): train only these of the table's runs")
    parser.add_argument("--experts", type=lambda s: Path(s).absolute(), default=None,
                        help="where expert_ppo runs export their expert and dagger/gail read it "
                             "(default: the package's hintsjax/experts/<env>)")


def chosen_envs(parser: argparse.ArgumentParser, args: argparse.Namespace, envs: tuple[str, ...]) -> list[str]:
    """The envs of --envs; exit 2 naming the valid ones on an unknown env or --workers < 1."""
    names = [n.strip() for n in args.envs.split(",") if n.strip()]
    unknown = [n for n in names if n not in envs]
    if unknown or args.workers < 1:
        parser.exit(2, f"error: unknown env {unknown}; valid choices: {', '.join(envs)}\n" if unknown
                    else "error: --workers must be at least 1\n")
    return names


def chosen_runs(parser: argparse.ArgumentParser, args: argparse.Namespace, run_ids: list[str]) -> list[str]:
    """The runs of --only (all when not given); exit 2 naming the valid labels on an unknown one."""
    if not args.only:
        return run_ids
    labels = list(dict.fromkeys(r.split("/")[1] for r in run_ids))
    unknown = [label for label in args.only if label not in labels]
    if unknown:
        parser.exit(2, f"error: unknown run label {unknown}; valid choices: {', '.join(labels)}\n")
    return [r for r in run_ids if r.split("/")[1] in args.only]


def table_main(description: str, default_runs: str, envs: tuple[str, ...], table: str,
               run_ids: Callable[[list[str]], list[str]], report: Callable[[Path, bool], None]) -> None:
    """The command line of a table's sweep script: train its runs for --envs, or --report."""
    parser = argparse.ArgumentParser(description=description)
    add_arguments(parser, default_runs, envs)
    args = parser.parse_args()
    os.environ["JAX_PLATFORMS"] = "cpu"  # the parent only reads configs; workers get the devices
    if args.report:
        archive_runs(args.runs, run_ids(list(envs)))
        report(args.runs, args.force)
        return
    names = chosen_envs(parser, args, envs)
    ids = chosen_runs(parser, args, run_ids(names))
    sweep(args.runs, ids, args.workers, args.seeds, table, args.smoke, args.launch_until, args.experts, args.gpus)


def main() -> None:
    parser = argparse.ArgumentParser(description="train and evaluate one run of a sweep (a worker process)")
    parser.add_argument("--runs", type=Path, required=True)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--one", required=True, help="env/label")
    parser.add_argument("--smoke", action="store_true")
    parser.add_argument("--experts", type=Path, default=None)
    args = parser.parse_args()
    train_one(args.runs, args.one, args.seeds, args.smoke, args.experts)


if __name__ == "__main__":
    main()
