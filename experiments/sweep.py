"""The machinery that the reproduction sweeps share (classic_control.py, locomotion.py, car_racing.py).

A run is named `env/label`, where the label is `RunConfig.label` (an agent's name, or
hints-<scheme>-<hint>); its folder runs/<sweep>/env/label holds config.yaml, metrics.csv,
train.log and, once finished, eval.json. `sweep` trains every unfinished run of a list,
`workers` processes at a time, each a call of this file with `--one env/label`:

    python experiments/sweep.py --runs runs/classic --seeds 5 --one idp/ppo_rgb [--smoke]

The readers below (`load`, `cell`, `metric_cell`, `kl_cell`, `wall_clock`, `sweep_seconds`) build the result tables.

runs/ is not committed (checkpoints, full logs). What the tables need of each finished run is
kept in the committed archive experiments/results/runs/<sweep>/<env>/<label>/ (`archive_runs`,
which every `--report` calls first): eval.json and config.yaml as trained, summary.json (the
training-return and KL cells, worked out from the full metrics.csv) and a metrics.csv of the
learning curve averaged into runlog.CURVE_POINTS bins, as the plots draw it; the sweeps' records
go to its sweeps.jsonl. The readers take a run from runs/ when it finished there, else from the
archive, so a report on a fresh checkout rebuilds the committed tables.
"""

from __future__ import annotations

import argparse
import csv
import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

ARCHIVE = Path(__file__).resolve().parent / "results" / "runs"
SUMMARY_JSON = "summary.json"
# A sweep's runs save at most once a minute: fast runs finish 50 updates in seconds, and a big
# run's checkpoint (every env's MJX state) can reach a GB; an interruption loses at most a minute.
CHECKPOINT_SECONDS = 60
KL_ABOVE = 0.5  # kl_cell's threshold: an update whose approx. KL exceeds it blew up
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


# -- reading finished runs ---------------------------------------------------------------------


def run_folder(runs: Path, env: str, label: str) -> Path:
    """Its archived copy when the run finished only there (runs/env/label lacks eval.json, the
    archive has it), else runs/env/label (finished, begun, or never run)."""
    folder = runs / env / label
    archived = ARCHIVE / runs.name / env / label
    if (folder / "eval.json").exists() or not (archived / "eval.json").exists():
        return folder
    return archived


def load(runs: Path, env: str, label: str) -> dict | None:
    path = run_folder(runs, env, label) / "eval.json"
    return json.loads(path.read_text()) if path.exists() else None


def cell(result: dict | None, variant: int = 0) -> str:
    """'mean ± std (seed std)' of one evaluation, or '-' when not run."""
    if result is None:
        return "-"
    e = result["evaluations"][variant]
    return f"{e['mean']:.1f} ± {e['std']:.1f} ({e['seed_std']:.1f})"


def metric_of(result: dict | None, name: str, variant: int = 0) -> tuple[float, float, float] | None:
    """(mean, std, std of the per-seed means) of an env metric (e.g. progress) of one
    evaluation; None when not run or not recorded."""
    e = None if result is None else result["evaluations"][variant]
    if e is None or f"{name}_mean" not in e:
        return None
    seed_means = e[f"{name}_seed_means"]
    centre = sum(seed_means) / len(seed_means)
    seed_std = (sum((m - centre) ** 2 for m in seed_means) / len(seed_means)) ** 0.5
    return e[f"{name}_mean"], e[f"{name}_std"], seed_std


def metric_cell(result: dict | None, name: str, variant: int = 0, percent: bool = False) -> str:
    """'mean ± std (seed std)' of an env metric of one evaluation, as `cell`; '-' when not run
    or not recorded."""
    stats = metric_of(result, name, variant)
    if stats is None:
        return "-"
    mean, std, seed_std = stats
    if percent:
        return f"{100 * mean:.0f}% ± {100 * std:.0f} ({100 * seed_std:.0f})"
    return f"{mean:.2f} ± {std:.2f} ({seed_std:.2f})"


def metrics_path(runs: Path, env: str, label: str) -> Path | None:
    """A run's metrics.csv (archived ones hold runlog.CURVE_POINTS bins of updates), or None when not run."""
    path = run_folder(runs, env, label) / "metrics.csv"
    return path if path.exists() else None


def summary(folder: Path) -> dict | None:
    """An archived run's summary.json (None for a run folder in runs/)."""
    path = folder / SUMMARY_JSON
    return json.loads(path.read_text()) if path.exists() else None


def training_seed_means(folder: Path, last: float = 0.1) -> list[float] | None:
    """Per seed, the mean return of the training episodes (sampled actions) that ended in the
    last `last` of a run's updates; None when not run or no episode ended."""
    import numpy as np

    from hintsjax.runlog import read_curves

    if (kept := summary(folder)) is not None:
        return kept["training_return_seed_means"]
    if not (folder / "metrics.csv").exists():
        return None
    _, values = read_curves(folder / "metrics.csv")
    tail = values[:, -max(1, int(last * values.shape[1])):]
    if np.isnan(tail).all():
        return None
    return [float(x) for x in np.nanmean(tail, axis=1)]


def training_cell(runs: Path, env: str, label: str) -> str:
    """Mean ± std over seeds of `training_seed_means` (the last 10% of updates): beside
    `cell`'s deterministic evaluation; '-' when not run."""
    import numpy as np

    per_seed = training_seed_means(run_folder(runs, env, label))
    if per_seed is None:
        return "-"
    return f"{np.nanmean(per_seed):.1f} ± {np.nanstd(per_seed):.1f}"


def kl_share(folder: Path, above: float = KL_ABOVE) -> float | None:
    """The share of a run's PPO updates (all seeds) whose approx. KL from the rollout policy (the
    mean over the update's minibatch steps, as logged) exceeds `above`; None when not run or
    not trained by PPO (or, for an archived run, `above` is not KL_ABOVE)."""
    import numpy as np

    if (kept := summary(folder)) is not None:
        return kept["kl_share"] if above == KL_ABOVE else None
    path = folder / "metrics.csv"
    if not path.exists():
        return None
    with path.open() as f:
        reader = csv.DictReader(f)
        if "approx_kl" not in (reader.fieldnames or ()):
            return None
        kl = np.array([float(row["approx_kl"]) for row in reader])
    return float(np.mean(kl > above))


def kl_cell(runs: Path, env: str, label: str, above: float = KL_ABOVE) -> str:
    """`kl_share` as a percentage: a PPO that drifts or blows up shows here (healthy runs stay
    near 0%; inf, an overflowed ratio, counts). '-' when not run or not trained by PPO."""
    share = kl_share(run_folder(runs, env, label), above)
    return "-" if share is None else f"{100 * share:.1f}%"


def trained_config(runs: Path, env: str, label: str):
    """The RunConfig a finished run was trained with (its config.yaml), or None when not run:
    a report states the settings its rows were trained with, not today's defaults."""
    from hintsjax.config import CONFIG_YAML, load_run_config

    folder = run_folder(runs, env, label)
    return load_run_config(folder) if (folder / "eval.json").exists() and (folder / CONFIG_YAML).exists() else None


def trained_ppo(runs: Path, env: str, label: str):
    """The PPOConfig a finished run was trained with, or None when not run."""
    cfg = trained_config(runs, env, label)
    return None if cfg is None else cfg.ppo


def references_note(runs: Path, env: str, references: tuple[str, ...]) -> str:
    """The references' budgets (as trained, else today's defaults) and the expert that dagger
    and gail learnt from (the packaged one)."""
    from hintsjax.config import run_config
    from hintsjax.expert import EXPERT_JSON, EXPERTS_DIR

    cfg = {a: trained_config(runs, env, a) or run_config({"env": env, "agent": a}) for a in references}
    expert = cfg["expert_ppo"].ppo
    meta = EXPERTS_DIR / env / EXPERT_JSON
    source = (f"its best seed (seed {m['seed_index']}, {m['seed_eval_mean']:.0f} over {m['episodes_per_seed']} episodes; "
              f"hintsjax/experts/{env})" if meta.exists() and (m := json.loads(meta.read_text())) else "its best seed")
    text = (f"References (no budget limit): expert_ppo is PPO on the state for {expert.total_env_steps / 1e6:g} M steps "
            f"({expert.num_envs} envs per seed, batches of {expert.batch_size}, {expert.epochs} epochs of minibatches of "
            f"{expert.minibatch_size}); dagger learns from {source} over {cfg['dagger'].ppo.total_env_steps / 1e3:g} K "
            f"expert-labelled steps")
    if "gail" in cfg:
        gail = cfg["gail"]
        reward = "-log(1 - D)" if gail.gail.reward == "original" else "the log odds log D - log(1 - D)"
        text += (f"; gail learns from {gail.gail.demonstrations} of that expert's episodes, by PPO for "
                 f"{gail.ppo.total_env_steps / 1e6:g} M steps on the discriminator's reward {reward}"
                 + (", the discriminator reading the state standardised by the demonstrations' statistics"
                    if gail.gail.normalize_state else ""))
    return text + "."


def mean_of(result: dict | None) -> float | None:
    return None if result is None else result["evaluations"][0]["mean"]


def wall_clock(result: dict | None) -> str:
    """A run's wall-clock in seconds, marked when it ran on a CPU rather than the GPU. A run
    trained outside a sweep (python -m hintsjax.run) recorded only its training seconds."""
    if result is None:
        return "-"
    if "wall_seconds" not in result:
        return f"{result['train_seconds']:.0f} (training only)"
    on_cpu = result.get("device", "").lower() == "cpu"
    return f"{result['wall_seconds']:.0f}" + (" (CPU)" if on_cpu else "")


def unique_lines(*paths: Path) -> list[str]:
    """The non-empty lines of the files that exist among `paths`, each once, in order."""
    return list(dict.fromkeys(line for path in paths if path.exists() for line in path.read_text().splitlines() if line.strip()))


def sweep_records(runs: Path, table: int | str) -> list[dict]:
    """The GPU sweeps of `table` recorded in runs/sweeps.jsonl and in the archive's copy (once
    each). A sweep that trained runs of both tables at once is recorded as table "2+4" and counts
    for each. Sweeps run on a CPU (recorded with "device": "cpu") are left out: their runs are
    marked (CPU)."""
    lines = unique_lines(runs / "sweeps.jsonl", ARCHIVE / runs.name / "sweeps.jsonl")
    return [r for r in map(json.loads, lines) if str(table) in str(r["table"]).split("+") and r.get("device") != "cpu"]


def sweep_seconds(runs: Path, table: int | str) -> float:
    """The GPU wall-clock of `table`'s sweeps: sweeps that ran at the same time (on one machine's
    several GPUs) count once, as the union of their [finished - seconds, finished] spans."""
    records = sweep_records(runs, table)
    total = sum(r["seconds"] for r in records if "finished" not in r)  # no timestamp: counted alone
    reach = -float("inf")  # the end of the union so far
    for start, end in sorted((end - r["seconds"], end) for r in records if "finished" in r
                             for end in [time.mktime(time.strptime(r["finished"], "%Y-%m-%d %H:%M:%S"))]):
        total += max(0.0, end - max(start, reach))
        reach = max(reach, end)
    return total


def archive_run(runs: Path, env: str, label: str) -> Path:
    """Copy what the tables need of the finished run runs/env/label into
    ARCHIVE/<runs' name>/env/label (see the module's docstring); returns that folder."""
    import numpy as np

    from hintsjax.config import CONFIG_YAML
    from hintsjax.runlog import bin_means, read_curves

    src, dest = runs / env / label, ARCHIVE / runs.name / env / label
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("eval.json", CONFIG_YAML):
        shutil.copyfile(src / name, dest / name)
    (dest / "metrics.csv").unlink(missing_ok=True)
    if not (src / "metrics.csv").exists():
        (dest / SUMMARY_JSON).write_text(json.dumps({"training_return_seed_means": None, "kl_share": None}) + "\n")
        return dest
    kept = {"training_return_seed_means": training_seed_means(src), "kl_share": kl_share(src)}
    steps, values = read_curves(src / "metrics.csv")
    # metrics.csv's updates count from 1 without gaps (a resumed run goes on from its checkpoint);
    # each archived row is a bin of them, numbered by its last update
    updates, _ = bin_means(np.arange(1, len(steps) + 1), values)
    steps, values = bin_means(steps, values)
    with (dest / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["update", "seed", "env_steps", "episode_return"])
        writer.writerows([updates[i], s, f"{steps[i]:.0f}", f"{values[s, i]:.6g}"]
                         for i in range(len(steps)) for s in range(values.shape[0]))
    (dest / SUMMARY_JSON).write_text(json.dumps(kept, indent=1) + "\n")
    return dest


def archive_runs(runs: Path, run_ids: list[str]) -> list[str]:
    """Archive every run of `run_ids` that finished in `runs` (and the sweeps' records); the
    archived ids."""
    done = [r for r in run_ids if (runs / r / "eval.json").exists()]
    for r in done:
        archive_run(runs, *r.split("/"))
    if (runs / "sweeps.jsonl").exists():
        path = ARCHIVE / runs.name / "sweeps.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(line + "\n" for line in unique_lines(path, runs / "sweeps.jsonl")))
    return done


def curve_lines(runs: Path, env: str, labels: list[str], out: Path, title: str, kept: tuple[str, ...] = ()) -> list[str]:
    """Plot the learning curves of `labels`' runs (those with a metrics.csv) into `out`; the
    report's markdown lines for it ([] when none has started). While some rows are `kept` (runs
    that predate the archive, with no curve to draw), `out` is their figure and stays; the other
    runs' curves go to a sibling figure, `out`'s name + ARCHIVED_SUFFIX."""
    from hintsjax.runlog import plot_curves, read_curves

    paths = {label: metrics_path(runs, env, label) for label in labels}
    curves = {label: read_curves(path) for label, path in paths.items() if path is not None}
    old = [f"![{env} learning curves]({out.name})", "", "(The curves of the runs kept from the previous report.)", ""]
    if not curves:  # a figure of runs that predate the archive stays, said to be theirs
        return old if out.exists() else []
    if kept and out.exists():
        out = out.with_name(out.stem + ARCHIVED_SUFFIX + out.suffix)
        plot_curves(curves, out, f"{title}: runs since the archive")
        return [*old, f"![{env} learning curves of the runs since the archive]({out.name})", ""]
    plot_curves(curves, out, title)
    return [f"![{env} learning curves]({out.name})", ""]


def footer(runs: Path, table: str, run_ids: list[str]) -> str:
    """The report's last line: the sweeps' GPU wall-clock and hardware."""
    return (f"Sweep wall-clock recorded in {runs}/sweeps.jsonl on the GPU: {sweep_seconds(runs, table):.0f} s"
            f" ({sweep_hardware(runs, table, run_ids) or 'none yet'}).")


KEPT = "†"  # marks a row kept from the committed report: its run predates the archive
ARCHIVED_SUFFIX = "_archived"  # curve_lines' figure of the runs beside kept ones


def kept_rows(path: Path) -> dict[tuple[str, str], str]:
    """The table rows of the committed report at `path`, by (section heading, agent label), each
    with its label marked KEPT. A report keeps the row of a run that is neither in runs/ nor in the
    archive (one trained before the archive existed, whose run folder was lost) instead of
    blanking it."""
    rows, section = {}, ""
    for line in path.read_text().splitlines() if path.exists() else []:
        if line.startswith("## "):
            section = line[3:].split(" (")[0]
        elif line.startswith("| ") and not line.startswith("| agent") and line.split("|")[2].strip() != "-":
            label = line.split("|")[1].strip().removesuffix(KEPT).strip()
            rows[(section, label)] = f"| {label} {KEPT} |" + line.split("|", 2)[2]
    return rows


def cell_stats(text: str) -> tuple[float, float] | None:
    """(mean, std of the per-seed means) of a 'mean ± std (seed std)' cell; None for '-'."""
    if text.strip() == "-":
        return None
    mean, rest = text.split("±")
    return float(mean), float(rest.split("(")[1].rstrip(") "))


def apart_text(a: tuple[float, float], b: tuple[float, float]) -> str:
    """Whether two agents' means differ by more than their seed stds together."""
    return "beyond" if abs(a[0] - b[0]) > a[1] + b[1] else "within"


def table_cells(text: str) -> dict[tuple[str, str, int], str]:
    """Every cell of a report's markdown tables, by (section heading, row label, column)."""
    cells, section = {}, ""
    for line in text.splitlines():
        if line.startswith("## "):
            section = line[3:].split(" (")[0]
        elif line.startswith("| ") and not line.startswith("|---"):
            label, *rest = [part.strip() for part in line.strip().strip("|").split("|")]
            cells.update({(section, label.removesuffix(KEPT).strip(), i): c for i, c in enumerate(rest, 1)})
    return cells


def lost_cells(old: str, new: str) -> list[str]:
    """'section/label' of every row with a cell that the report `old` filled and `new` leaves '-'."""
    after = table_cells(new)
    return list(dict.fromkeys(f"{section}/{label}" for (section, label, i), c in table_cells(old).items()
                              if c != "-" and after.get((section, label, i), "-") == "-"))


def refuse_lost_cells(path: Path, lines: list[str]) -> None:
    """Exit 2, naming them, if the report `lines` would blank cells that the committed report at
    `path` fills: their runs are neither in runs/ nor in the archive (e.g. a checkout whose runs
    were lost). --force skips this check."""
    if path.exists() and (lost := lost_cells(path.read_text(), "\n".join(lines))):
        sys.stderr.write(f"error: {path.name} not rewritten: it would blank {len(lost)} rows whose runs are in neither "
                         f"--runs nor {ARCHIVE} ({', '.join(lost[:5])}{', ...' if len(lost) > 5 else ''}); "
                         "--force rewrites it anyway\n")
        raise SystemExit(2)


def write_report(path: Path, lines: list[str], force: bool = False) -> None:
    """Write a report (refused as `refuse_lost_cells` says unless `force`) and print it."""
    if not force:
        refuse_lost_cells(path, lines)
    path.parent.mkdir(exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    print(path.read_text())


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


def sweep_hardware(runs: Path, table: str, run_ids: list[str]) -> str:
    """'NVIDIA H200; 6 runs at once over 2 GPUs' for the GPU sweeps of `table` (from sweeps.jsonl
    and the runs' eval.json), or '' when none ran on a GPU."""
    records = sweep_records(runs, table)
    results = [result for r in run_ids if (result := load(runs, *r.split("/")))]
    devices = sorted({result.get("device", "") for result in results} - {"", "cpu", "Cpu"})
    if not records or not devices:
        return ""
    setups = sorted({("1 run at a time" if r["workers"] == 1 else f"{r['workers']} runs at once")
                     + (f" over {len(r['gpus'])} GPUs" if len(r.get("gpus", ())) > 1 else " on one GPU") for r in records})
    # Runs recorded before this key existed ran with deterministic GPU ops (hintsjax's default).
    fast = [result for result in results if result.get("deterministic", True) is False]
    return f"{', '.join(devices)}; {'; '.join(setups)}" + (f"; deterministic GPU ops off ({len(fast)} runs)" if fast else "")


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
