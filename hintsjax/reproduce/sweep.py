"""The machinery that the reproduction sweeps share (classic_control.py, locomotion.py,
car_racing.py, playground.py).

A run is named `env/label`, where the label is `RunConfig.label` (agent[-scheme][-hint], e.g.
hints-fc-composite or asym_ac-state); its folder runs/<sweep>/env/label holds config.yaml,
metrics.csv, checkpoints and, once finished, eval.json. `sweep` groups the unfinished runs of a list
that share a network's shapes (hintsjax.algorithms.group: e.g. HINTS-FC with every hint, or PPO-x
with PPO-x+N(0,1)) and trains each group, all its runs and seeds in one compiled program,
`workers` processes at a time, each a call of this module with `--one` and the group's runs:

    python -m hintsjax.reproduce.sweep --runs runs/classic --seeds 20 --one idp/ppo_rgb [--smoke]
    python -m hintsjax.reproduce.sweep --runs runs/classic --seeds 20 --one pendulum/ppo_state,pendulum/ppo_noisy_state

More of what it owns and why: docs/design.md, "Module notes", hintsjax/reproduce/sweep.py.
"""  # noqa: E501

from __future__ import annotations

import argparse
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from hintsjax.models.agents import EXPERT_AGENT
from hintsjax.reproduce.report import load
from hintsjax.reproduce.sweep_settings import add_settings, worker_settings

# A sweep's runs save at most once a minute: fast runs finish 50 updates in seconds, and a big
# run's checkpoint (every env's MJX state) can reach a GB; an interruption loses at most a minute.
CHECKPOINT_SECONDS = 60
# the workers' environment: a sweep's parent process keeps off the GPU
CHILD_ENVIRON = dict(os.environ)
EXPERT_RUN = EXPERT_AGENT  # the run whose best seed becomes its env's expert for dagger and gail
GROUPS = "_groups"  # under runs/<sweep>/<env>: the groups' checkpoints and logs
WORKER = "hintsjax.reproduce.sweep"  # the module a worker process runs (`main`)


def hints_run(scheme: str, hint: str) -> str:
    return f"hints-{scheme}-{hint}"


# --smoke: a tiny budget to check the sweep's plumbing on a CPU (the numbers mean nothing).
SMOKE = {
    "eval_episodes": 2,
    "ppo": {
        "total_env_steps": 1024,
        "num_envs": 8,
        "batch_size": 512,
        "minibatch_size": 256,
        "epochs": 1,
    },
}


def run_values(
    env: str,
    label: str,
    seeds: int,
    smoke: bool = False,
    experts: Path | None = None,
    settings: dict | None = None,
) -> dict:
    """Config values of a run label (the inverse of RunConfig.label); `settings` (top-level keys
    given with --set, e.g. physics or the first seed) apply to every run of the sweep."""
    from hintsjax.models.agents import AGENTS

    values = {
        "env": env,
        "seeds": seeds,
        "checkpoint_every": 50,
        "checkpoint_seconds": CHECKPOINT_SECONDS,
        **(SMOKE if smoke else {}),
        **(settings or {}),
    }
    if label in AGENTS and AGENTS[label].imitates:
        return {**values, "agent": label, "expert": None if experts is None else str(experts / env)}
    agent, _, rest = label.partition("-")  # agent[-scheme][-hint]: agents' names have no '-'
    if AGENTS[agent].conditioned:
        scheme, _, rest = rest.partition("-")
        values["scheme"] = scheme
    return {**values, "agent": agent, **({"hint": rest} if rest else {})}


def saved_physics(run: Path, default: str | None) -> str | None:
    """The physics a run folder's config.yaml was trained with (layers.load_run_config: jax for one
    saved before the setting existed), or `default` where it has none."""
    from hintsjax.settings.layers import CONFIG_YAML, load_run_config

    return load_run_config(run).physics if (run / CONFIG_YAML).exists() else default


def job_folder(runs: Path, run_ids: list[str]) -> Path:
    """Where a job keeps its checkpoints and train.log: a single run's own folder, or its
    group's."""
    return runs / run_ids[0] if len(run_ids) == 1 else group_folder(runs, run_ids)


def group_folder(runs: Path, run_ids: list[str]) -> Path:
    """Where a group of runs keeps its checkpoints and log: named by its runs, so that another
    set of runs never resumes from it."""
    env = run_ids[0].split("/")[0]
    digest = hashlib.sha1(",".join(run_ids).encode()).hexdigest()[:10]
    return runs / env / GROUPS / digest


def train_one(
    runs: Path,
    run_ids: list[str],
    seeds: int,
    smoke: bool,
    experts: Path | None,
    settings: dict | None = None,
) -> None:
    """Train and evaluate runs `env/label` (one, or a group that shares a program) into
    runs/env/label; export an expert's. A group that does not fit in memory is split in halves."""
    from hintsjax.system import folder_lock

    folder = job_folder(runs, run_ids)
    # one writer a folder: another sweep's worker on these runs is refused (folder_lock.py)
    with folder_lock.holding([folder, *(runs / r for r in run_ids)]):
        halves = _train_held(runs, run_ids, seeds, smoke, experts, settings, folder)
    for part in halves:  # a group too big for memory, in halves (their own locks)
        train_one(runs, part, seeds, smoke, experts, settings)


def _train_held(
    runs: Path,
    run_ids: list[str],
    seeds: int,
    smoke: bool,
    experts: Path | None,
    settings: dict | None,
    folder: Path,
) -> list[list[str]]:
    """`train_one` with its folders' locks held; the halves to train instead where the group does
    not fit ([] once trained)."""
    import jax

    from hintsjax.system import checkpoint, paths
    from hintsjax.settings.layers import run_config, save_run_config
    from hintsjax.algorithms import experts as expert_export
    from hintsjax.training import compilation, loop, pipeline

    # An interrupted run (killed by a time limit) goes on from its newest checkpoint; its
    # wall-clock counts the kept work of earlier calls, not what was lost after their last
    # checkpoint.
    resume = checkpoint.latest_update(folder) is not None
    cfgs = []
    for run_id in run_ids:
        env, label = run_id.split("/")
        values = run_values(env, label, seeds, smoke, experts, settings)
        if resume:  # it goes on with the physics it began with, whatever auto resolves to today
            values["physics"] = saved_physics(runs / run_id, values.get("physics"))
        cfg = run_config(values)
        assert cfg.label == label, (cfg.label, label)
        cfgs.append(cfg)
        (runs / run_id).mkdir(parents=True, exist_ok=True)
        save_run_config(runs / run_id, cfg)
    before, t = loop.seconds_trained(folder) if resume else 0.0, time.time()
    if resume:
        print(
            f"resuming {', '.join(run_ids)} from update {checkpoint.latest_update(folder)}",
            flush=True,
        )
    if len(run_ids) == 1:
        results = [pipeline.train(cfgs[0], folder, resume=resume, progress=False)]
    else:
        paths.write_text_whole(folder / "group.json", json.dumps({"runs": run_ids, "seeds": seeds}))
        try:
            results = pipeline.train_group(
                cfgs, folder, [runs / r for r in run_ids], resume=resume, progress=False
            )
        except compilation.GroupTooBig as e:
            half = len(run_ids) // 2
            print(
                f"{e}: splitting the group into {half} and {len(run_ids) - half} runs", flush=True
            )
            return [run_ids[:half], run_ids[half:]]
    extra = {"wall_seconds": before + time.time() - t, "device": jax.devices()[0].device_kind}
    for run_id, result in zip(run_ids, results):
        written = json.dumps({**result, **extra}, indent=1)
        paths.write_text_whole(runs / run_id / "eval.json", written)
    for run_id in run_ids:
        if run_id.split("/")[1] == EXPERT_RUN:
            exported = expert_export.export(
                runs / run_id,
                None if experts is None else experts / run_id.split("/")[0],
                force=True,
            )
            print(f"exported the expert to {exported}", flush=True)
    return []


def plan_jobs(
    run_ids: list[str], seeds: int, smoke: bool, group_size: int = 0, settings: dict | None = None
) -> list[list[str]]:
    """The runs partitioned into groups that train together, each cut into parts of at most
    `group_size` runs (0: no limit; 1: every run its own job). Smaller groups suit calls with a
    time limit: each part is a job that finishes on its own."""
    from hintsjax.settings.layers import run_config
    from hintsjax.algorithms.group import plan

    cfgs = [run_config(run_values(*r.split("/"), seeds, smoke, settings=settings)) for r in run_ids]
    size = group_size or len(run_ids)
    return [
        [run_ids[i] for i in members[k : k + size]]
        for members in plan(cfgs)
        for k in range(0, len(members), size)
    ]


def begun_groups(runs: Path, run_ids: list[str], seeds: int) -> list[list[str]]:
    """Groups an earlier sweep began (a checkpoint in their folder) that still hold unfinished runs
    of `run_ids`, e.g. one cut while it wrote its members' results. Each is resumed whole, so its
    training is kept: planned afresh, its unfinished runs would form a new group (another digest,
    no checkpoint) and train from the start. Its other members must be in `run_ids` or finished
    (they are evaluated and written again, with the same numbers)."""
    from hintsjax.system import checkpoint

    finished = lambda r: (runs / r / "eval.json").exists()  # noqa: E731
    jobs: list[list[str]] = []
    for path in sorted(runs.glob(f"*/{GROUPS}/*/group.json")):
        record = json.loads(path.read_text())
        members = record["runs"]
        if (
            record.get("seeds") != seeds
            or all(r not in run_ids or finished(r) for r in members)
            or any(r not in run_ids and not finished(r) for r in members)
            or any(r in job for job in jobs for r in members)
            or checkpoint.latest_update(path.parent) is None
        ):
            continue
        jobs.append(members)
    return jobs


def todo_jobs(
    runs: Path,
    run_ids: list[str],
    seeds: int,
    smoke: bool,
    group_size: int = 0,
    settings: dict | None = None,
) -> list[list[str]]:
    """The jobs that train the unfinished runs of `run_ids`: the groups begun earlier
    (`begun_groups`), resumed as they were, then the other unfinished runs grouped by
    `plan_jobs`."""
    begun = begun_groups(runs, run_ids, seeds)
    taken = {r for job in begun for r in job}
    rest = [r for r in run_ids if r not in taken and not (runs / r / "eval.json").exists()]
    return begun + plan_jobs(rest, seeds, smoke, group_size, settings)


def prerequisite(run_id: str) -> str | None:
    """The run that must finish before this one starts: an env's expert, for its dagger and gail."""
    from hintsjax.models.agents import AGENTS

    env, label = run_id.split("/")
    return f"{env}/{EXPERT_RUN}" if label in AGENTS and AGENTS[label].imitates else None


def budget(run_id: str) -> float:
    """Rough relative cost of a run, to start the longest first."""
    from hintsjax.settings.layers import run_config

    env, label = run_id.split("/")
    cfg = run_config(run_values(env, label, 1))
    return cfg.ppo.total_env_steps * (1.0 if cfg.agent_spec.pixels else 0.3)


def stopped(*_: Any) -> None:
    """SIGTERM: end the sweep (its `finally` records it). Later SIGTERMs are ignored: `timeout`
    signals the sweep and then its whole process group, and a second exit raised inside the
    `finally` would lose the record."""
    signal.signal(signal.SIGTERM, signal.SIG_IGN)
    sys.exit(143)


def sweep(
    runs: Path,
    run_ids: list[str],
    workers: int,
    seeds: int,
    table: int | str,
    smoke: bool,
    launch_until: float = float("inf"),
    experts: Path | None = None,
    gpus: tuple[str, ...] = (),
    group_size: int = 0,
    settings: dict | None = None,
) -> None:
    """Train every unfinished run, grouped (`todo_jobs`: a group begun earlier resumes whole),
    `workers` groups at a time, starting none after `launch_until` seconds (so that a
    time-limited call ends with finished runs, not killed ones); append the sweep's wall-clock to
    runs/sweeps.jsonl. With `gpus` (CUDA device ids), each worker gets the least busy of them to
    itself (CUDA_VISIBLE_DEVICES); without, all workers share the visible devices. `group_size` caps
    the runs of a group (`plan_jobs`); `settings` (--set) go to every run."""
    unfinished = [r for r in run_ids if not (runs / r / "eval.json").exists()]
    todo = sorted(
        todo_jobs(runs, run_ids, seeds, smoke, group_size, settings),
        key=lambda job: sum(map(budget, job)),
        reverse=True,
    )
    print(
        f"table {table}: {len(run_ids) - len(unfinished)} of {len(run_ids)} runs done already; "
        f"training {len(unfinished)} in {len(todo)} group(s), {workers} at a time, {seeds} seeds "
        "each",
        flush=True,
    )
    launched = 0
    per_gpu = -(-workers // max(len(gpus), 1))  # workers sharing one device
    env = {**CHILD_ENVIRON, "XLA_PYTHON_CLIENT_MEM_FRACTION": f"{0.9 / per_gpu:.3f}"}
    start = time.time()
    active: list[tuple[list[str], subprocess.Popen]] = []  # each worker writes its own train.log
    gpu_of: dict[str, str] = {}
    failed: list[str] = []
    signal.signal(signal.SIGTERM, stopped)  # `timeout` stops the sweep: record it below
    log_of = lambda job: job_folder(runs, job) / "train.log"  # noqa: E731
    try:
        while todo or active:
            if todo and time.time() - start > launch_until:
                print(
                    f"[{time.time() - start:6.0f} s] --launch-until reached: {sum(map(len, todo))} "
                    "runs left for the next sweep",
                    flush=True,
                )
                todo = []
            waiting = {r for job in todo for r in job} | {r for job, _ in active for r in job}
            todo = [job for job in todo if prerequisite(job[0]) not in failed]
            ready = [job for job in todo if prerequisite(job[0]) not in waiting]
            while ready and len(active) < workers:
                job = ready.pop(0)
                todo.remove(job)
                name = ",".join(job)
                log_of(job).parent.mkdir(parents=True, exist_ok=True)
                cmd = [
                    sys.executable,
                    "-m",
                    WORKER,
                    "--runs",
                    str(runs),
                    "--seeds",
                    str(seeds),
                    "--one",
                    name,
                    *(["--smoke"] if smoke else []),
                    *(["--experts", str(experts)] if experts else []),
                    *(f"--set={k}={v}" for k, v in (settings or {}).items()),
                ]
                if gpus:
                    busy = [gpu_of[",".join(j)] for j, _ in active]
                    gpu_of[name] = min(gpus, key=busy.count)
                child_env = {**env, "CUDA_VISIBLE_DEVICES": gpu_of[name]} if gpus else env
                with open(log_of(job), "w") as log:  # the child keeps its own copy
                    active.append(
                        (
                            job,
                            subprocess.Popen(
                                cmd, stdout=log, stderr=subprocess.STDOUT, env=child_env
                            ),
                        )
                    )
                launched += len(job)
            time.sleep(2)
            for job, proc in list(active):
                if proc.poll() is None:
                    continue
                active.remove((job, proc))
                if proc.returncode:
                    failed += job
                print(
                    f"[{time.time() - start:6.0f} s] {', '.join(job)}: "
                    f"{'FAILED (see ' + str(log_of(job)) + ')' if proc.returncode else 'done'}",
                    flush=True,
                )
    finally:
        interrupted = [r for job, _ in active for r in job]
        for _, proc in active:  # interrupted: these runs are retrained by the next sweep
            proc.terminate()
        seconds = time.time() - start
        record = {
            "table": table,
            "runs": len(run_ids),
            "trained": launched - len(failed) - len(interrupted),
            "failed": failed,
            "interrupted": interrupted,
            "workers": workers,
            "seconds": seconds,
            "seeds": seeds,
            "grouped": group_size != 1,
            "finished": time.strftime("%Y-%m-%d %H:%M:%S"),
            "gpus": list(gpus),
            **({"settings": settings} if settings else {}),
        }
        devices = {(load(runs, *r.split("/")) or {}).get("device", "").lower() for r in run_ids} - {
            ""
        }
        # the workers' device (the parent keeps off it): CPU sweeps leave the GPU totals
        if devices == {"cpu"}:
            record["device"] = "cpu"
        with open(runs / "sweeps.jsonl", "a") as f:
            f.write(json.dumps(record) + "\n")
        print(
            f"table {table}: {seconds:.0f} s wall-clock"
            + (f", {len(interrupted)} runs interrupted" if active else ""),
            flush=True,
        )
    if failed:
        sys.exit(1)


def main() -> None:
    """A worker: train and evaluate one run, or one group, of a sweep (`WORKER`, launched by
    `sweep`)."""
    parser = argparse.ArgumentParser(
        description="train and evaluate one run of a sweep (a worker process)"
    )
    parser.add_argument("--runs", type=Path, required=True)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument(
        "--one", required=True, help="env/label, or comma-separated env/labels of one group"
    )
    parser.add_argument("--smoke", action="store_true")
    parser.add_argument("--experts", type=Path, default=None)
    add_settings(parser)
    args = parser.parse_args()
    settings = worker_settings(parser, args)
    from hintsjax.system.errors import UsageError, report_usage

    try:
        train_one(args.runs, args.one.split(","), args.seeds, args.smoke, args.experts, settings)
    except UsageError as e:  # another sweep's worker holds a folder: one line in train.log
        sys.exit(report_usage(e))


if __name__ == "__main__":
    main()
