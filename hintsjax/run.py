"""Train from the command line (Hydra), evaluate, and write one run folder.

    python -m hintsjax.run env=pendulum agent=hints hint=composite scheme=fc seeds=5
    python -m hintsjax.run -m scheme=lc,ac,fc,mc          # a sweep, one folder per run
    python -m hintsjax.run resume=runs/<folder>           # go on (ppo.total_env_steps=N: train longer)

A run folder holds config.yaml (resolved), metrics.csv, TensorBoard events (tb/), orbax
checkpoints of the full train state (checkpoints/), eval.json and learning_curve.png.
Bad input is reported in one line with the valid choices, exit status 2, nothing written.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from functools import partial
from pathlib import Path
from typing import Any, Callable

import hydra
import jax
import jax.numpy as jnp
import numpy as np
from omegaconf import DictConfig, OmegaConf
from tqdm import tqdm

from hintsjax.system import checkpoint, compilation_cache, devices, memory, paths, program_cache, xla_flags
from hintsjax.cli import choices, overrides
from hintsjax.algorithms import experts
from hintsjax.settings.config import RunConfig, load_run_config, run_config, save_run_config, to_dict
from hintsjax.system.devices import SeedLayout
from hintsjax.evaluation.evaluator import compile_evaluator, evaluate_group, evaluate_variants, metrics_text
from hintsjax.algorithms.registry import make_trainer
from hintsjax.envs import physics
from hintsjax.system.errors import INTERRUPTED, UsageError, command, fail, report_bug
from hintsjax.algorithms.group import cell_state, make_group, make_group_trainer
from hintsjax.training.runlog import CURVE_PNG, METRICS_CSV, RunLog, fresh_folder, plot_curves, read_curves
from hintsjax.algorithms.trainer import Trainer

EVAL_JSON = "eval.json"


def new_run_dir(out_dir: str, name: str | None, cfg: RunConfig) -> Path:
    """A fresh folder; never an existing one."""
    return fresh_folder(Path(out_dir) / (name or f"{cfg.env}-{cfg.label}-{time.strftime('%Y%m%d-%H%M%S')}"))


# Training seconds (compiles excluded) up to the newest checkpoint, summed over resumed calls; and
# this call's compile seconds, of which tracing (Python).
SECONDS_JSON = "seconds.json"


def seconds_trained(run_dir: Path) -> float:
    """Training seconds that the newest checkpoint of `run_dir` holds (0 for a fresh folder)."""
    path = Path(run_dir) / SECONDS_JSON
    return json.loads(path.read_text())["seconds"] if path.exists() else 0.0


@dataclass(frozen=True)
class Compiled:
    """A run's training programs, compiled ahead of time for its seed-batched state."""

    init: Callable[[jax.Array], Any]  # [padded seeds] keys -> state
    # (state, n) -> (state n updates on, metrics [S, chunk]): the first n <= chunk updates of one
    # program, so every chunk, the shorter last one too, runs the same compiled code
    run_chunk: Callable[[Any, np.int32], tuple[Any, dict[str, jax.Array]]]
    chunk: int
    seconds: float  # spent tracing and compiling both
    trace_seconds: float  # of which tracing and lowering to XLA (Python), or loading both as traced before
    loaded: bool  # both programs were read from the traced-program cache, not traced
    layout: SeedLayout  # the seeds over the devices (their count padded to a multiple of the devices)


def compile_training(trainer: Trainer, keys: jax.Array, chunk: int, layout: SeedLayout | None = None) -> Compiled:
    """Compile `trainer`'s init and its chunk of `chunk` updates for the seed keys' batch; with a
    `layout` of several devices (keys from its `pad`), each device runs its share of the seeds."""
    t = time.perf_counter()
    layout = layout or SeedLayout.of(keys.shape[0], sorted(keys.devices(), key=lambda d: d.id))
    init_fn = layout.spread(jax.vmap(trainer.init), batched=1)
    chunk_fn = layout.spread(jax.vmap(partial(trainer.run_chunk, length=chunk), in_axes=(0, None)), batched=1, shared=1)
    # traced, or loaded as traced by an earlier process (hintsjax/system/program_cache.py: one device's programs only)
    identity = trainer.identity if layout.count == 1 else None
    init = program_cache.lower(init_fn, keys, name="init", context=identity)
    run_chunk = program_cache.lower(chunk_fn, init.out_info, np.int32(chunk), name=f"chunk{chunk}",
                                    context=identity)  # the state's shapes as init's lowering found them
    traced = time.perf_counter() - t
    loaded = all(getattr(program, "loaded", False) for program in (init, run_chunk))
    init, run_chunk = init.compile(), run_chunk.compile()
    return Compiled(init, run_chunk, chunk, time.perf_counter() - t, traced, loaded, layout)


class GroupTooBig(RuntimeError):
    """A group's compiled training program needs more memory than the device has."""


def check_fits(compiled: Any, what: str) -> None:
    """GroupTooBig if `compiled` (an XLA executable) needs more than 90 % of the device's memory
    (only where the device reports both: GPUs do, the CPU does not)."""
    stats = jax.devices()[0].memory_stats() or {}
    analysis = compiled.memory_analysis()
    if "bytes_limit" not in stats or analysis is None:
        return
    need = analysis.temp_size_in_bytes + analysis.argument_size_in_bytes + analysis.output_size_in_bytes
    if need > 0.9 * stats["bytes_limit"]:
        raise GroupTooBig(f"{what} needs {need / 2**30:.1f} GiB of the device's {stats['bytes_limit'] / 2**30:.1f} GiB")


class NonFiniteError(RuntimeError):
    """Training went NaN or infinite: the run stopped without saving that state, so its newest
    checkpoint is the last good one (NONFINITE_JSON in the run folder says where and what)."""

    def __init__(self, message: str, found: dict[str, Any]):
        super().__init__(message)
        self.found = found  # what NONFINITE_JSON holds


# Losses that every sound update keeps finite (episode_return is NaN where no episode ended). A
# non-finite parameter makes the next update's losses non-finite, so checking them on the host
# finds it one update later at most, without adding anything to the compiled training program;
# a checkpoint is written only of params that are all finite (`finite_seeds`).
FINITE_METRICS = ("policy_loss", "value_loss", "entropy")
NONFINITE_JSON = "nonfinite.json"


@jax.jit
def finite_seeds(params: Any) -> jax.Array:
    """[S] bool: whether every parameter of each seed (of every member, for a group) is finite."""
    return jnp.stack([jnp.isfinite(x).reshape(x.shape[0], -1).all(axis=1) for x in jax.tree.leaves(params)]).all(axis=0)


def first_nonfinite(metrics: dict[str, np.ndarray], after: int) -> dict[str, Any] | None:
    """The first update of a chunk's metrics ([S, n] or a group's [S, n, K], `after` updates
    before it) with a loss that is not finite: its update, the loss, the seeds (and members)."""
    for u in range(next(iter(metrics.values())).shape[1]):
        for name in FINITE_METRICS:
            if name in metrics:
                bad = ~np.isfinite(metrics[name][:, u])
                if bad.any():
                    found = {"update": after + u + 1, "quantity": name,
                             "seeds": np.flatnonzero(bad.reshape(len(bad), -1).any(axis=1)).tolist()}
                    return found if bad.ndim == 1 else {**found, "members": np.flatnonzero(bad.any(axis=0)).tolist()}
    return None


def stop_nonfinite(run_dir: Path, label: str, found: dict[str, Any]) -> None:
    """Record `found` in the run folder and raise NonFiniteError."""
    if devices.is_main():
        (run_dir / NONFINITE_JSON).write_text(json.dumps(found) + "\n")
    where = f"seed(s) {found['seeds']}" + (f", member(s) {found['members']}" if "members" in found else "")
    raise NonFiniteError(f"{label}: {found['quantity']} is not finite after update {found['update']} ({where}); "
                         f"training stopped without saving it", found)


def check_physics(cfg: RunConfig, label: str) -> None:
    """UsageError naming `warp_capacity` if MJX-Warp ran out of a buffer in this process (its
    worlds that did were made NaN, so nothing was trained on dropped contacts)."""
    lost = physics.overflow_seen()
    if lost is not None:
        raise UsageError(f"{cfg.env} {label}: MJX-Warp ran out of {lost} at warp_capacity={cfg.warp_capacity}; "
                         f"train again with a larger warp_capacity (or physics=jax)")


@dataclass
class Training:
    """A training run's progress: its compiled programs, state and timing (what `start` and `advance` share)."""

    compiled: Compiled
    state: Any
    done: int  # updates in `state`
    first: int  # updates this call started from (a resumed run's checkpoint)
    before: float  # training seconds of earlier calls (resumed)
    seconds: float = 0.0  # training seconds of this call
    # (seconds since training began, updates done) each time a chunk's metrics reached the host
    arrivals: tuple[tuple[float, int], ...] = ()


def chunks_rate(training: Training, env_steps_per_update: int) -> float | None:
    """Env steps per second from training's start to the last chunk's metrics on the host: the span
    the bench's back-to-back chunks are timed over, so the two compare; the last checkpoint's
    write, after it, is left out. None when no chunk ran. (A rate between chunk ends would read
    high whenever the host fetched the first chunk late, once later chunks had run.)"""
    if not training.arrivals:
        return None
    seconds, updates = training.arrivals[-1]
    return (updates - training.first) * env_steps_per_update / max(seconds, 1e-9)


def check_warp_run() -> None:
    """UsageError where a physics=warp run cannot go: over several processes (`seed_layout`)."""
    if jax.process_count() > 1:
        raise UsageError("physics=warp runs in one process (on one GPU); drop JAX_NUM_PROCESSES or use physics=jax")


def evaluation_compiles_first(cfg: RunConfig) -> bool:
    """Whether the evaluation program compiles before training rather than beside it: under
    physics=warp. MuJoCo Warp captures CUDA graphs and launches its kernels from a Python
    callback, so a compile in another thread slows every physics call (the ant's first 100
    updates: 40.4 K env steps/s beside, 56.4 K first) and, with deterministic ops off (XLA's
    autotuner then runs kernels on the GPU while it compiles), broke the capture: a segfault, and
    earlier "Warp CUDA error 904", in 3 of 4 runs beside, none of 3 first
    (experiments/results/warp_det_off_h100.json)."""
    return cfg.physics == physics.WARP


def seed_layout(cfg: RunConfig) -> SeedLayout:
    """cfg's seeds over every device (of every process) JAX sees; a run with physics=warp on this
    process's first device only (jit's partitioner cannot split MJX-Warp's custom call: every
    device would step every world)."""
    if cfg.physics != physics.WARP:
        return SeedLayout.of(cfg.seeds)
    check_warp_run()
    return SeedLayout.of(cfg.seeds, jax.local_devices()[:1])


def start(trainer: Trainer, cfg: RunConfig, run_dir: Path, resume: bool, label: str, check_memory: bool = False) -> Training:
    """Compile `trainer`'s programs for cfg's seeds, then a fresh state or the newest checkpoint of run_dir."""
    layout = seed_layout(cfg)
    keys = layout.pad(cfg.seed_keys())
    physics.clear_overflow()
    total = cfg.ppo.num_updates
    compiled = compile_training(trainer, keys, min(cfg.checkpoint_every, total), layout)
    if check_memory:
        check_fits(compiled.run_chunk, label)
    if resume:  # a checkpoint holds the run's own seeds, restored onto one device: padded and placed as at the start
        state, done = checkpoint.restore_latest(run_dir, trainer.abstract_state())
        state = layout.pad(state)
    else:
        state, done = compiled.init(keys), 0
    spread = f" ({layout.per_device} a device{f', {layout.padded - cfg.seeds} of them padding' if layout.padded > cfg.seeds else ''})"
    print(f"{cfg.env} {label}: {cfg.seeds} seeds x {total} updates of {cfg.ppo.batch_size} env steps "
          f"on {layout.count} {jax.default_backend()} device(s){spread if layout.count > 1 else ''}, "
          f"compiled in {compiled.seconds:.1f} s -> {run_dir}", flush=True)
    return Training(compiled, state, done, done, seconds_trained(run_dir) if resume else 0.0)


def advance(training: Training, cfg: RunConfig, run_dir: Path, write: Callable[[dict[str, np.ndarray], int], None],
            progress: bool, label: str) -> Training:
    """Train to cfg's last update in chunks, checkpointing into run_dir; `write(metrics, after)`
    gets each chunk's metrics ([S, n, ...] for n updates after `after`).

    The device never waits on the host: each chunk is dispatched before the previous one's
    metrics are written and its state checkpointed (in the background), so logging and saving
    overlap with training. A save that comes due while the previous one is still being written
    is skipped (the newest complete checkpoint is then at most one write old); the last update
    is always saved. Compile seconds are reported apart from training seconds.
    """
    compiled, state, done, total = training.compiled, training.state, training.done, cfg.ppo.num_updates
    layout = compiled.layout
    bar = tqdm(total=total, initial=done, unit="upd", disable=not (progress and devices.is_main()), desc=f"{cfg.env} {label}")
    t0 = saved = time.perf_counter()
    last_saved = written = done  # the newest update saved (or being saved), and logged

    def save(state: Any, update: int, finite: jax.Array) -> None:
        """Checkpoint `state` unless `finite` (its finite_seeds) says some seed's params are not."""
        nonlocal saved, last_saved
        finite = layout.fetch(finite)
        if not finite.all():
            stop_nonfinite(run_dir, label, {"update": update, "quantity": "params",
                                            "seeds": np.flatnonzero(~finite).tolist()})
        last_saved = update  # before the write starts: an interrupt never asks for it twice
        checkpoint.save(run_dir, layout.crop(state), update)  # the run's own seeds: it resumes on any device count
        saved = time.perf_counter()
        if devices.is_main():
            (run_dir / SECONDS_JSON).write_text(json.dumps({"update": update, "seconds": training.before + saved - t0,
                                                             "compile_seconds": compiled.seconds,
                                                             "trace_seconds": compiled.trace_seconds}))

    arrivals = []

    def report(metrics: dict[str, jax.Array], after: int, n: int) -> None:
        nonlocal written
        metrics = {k: v[:, :n] for k, v in layout.fetch(metrics).items()}  # waits for that chunk only
        arrivals.append((time.perf_counter() - t0, after + n))
        write(metrics, after)
        written = after + n
        check_physics(cfg, label)  # before the NaN guard: a world that overflowed is NaN
        found = first_nonfinite(metrics, after)
        if found is not None:
            stop_nonfinite(run_dir, label, found)
        returns = metrics["episode_return"]  # the chunk's updates (NaN where no episode ended in one)
        bar.set_postfix(steps=int(np.max(metrics["env_steps"][:, -1])),
                        ret=f"{np.nanmean(returns):.1f}" if not np.all(np.isnan(returns)) else "-")
        bar.update(n)

    pending = None  # (metrics, updates before, length) of the chunk dispatched last
    finite = None  # finite_seeds of `state` once a chunk has made it (the state a call starts from is never saved)
    try:
        with checkpoint.writing(run_dir):  # leaving it, even by Ctrl-C, waits for the writes under way
            try:
                while done < total:
                    n = min(compiled.chunk, total - done)
                    following, metrics = compiled.run_chunk(state, np.int32(n))  # returns at once; the device works on
                    # queued behind the chunk, so reading it once the chunk has run never stalls the device
                    following_finite = finite_seeds(following.params)
                    if pending is not None:
                        report(*pending)
                    if devices.agree_that(done > training.first and time.perf_counter() - saved >= cfg.checkpoint_seconds
                                          and not checkpoint.saving(run_dir)):  # process 0 decides for all
                        save(state, done, finite)  # the state this chunk started from: computed, copied off as the chunk runs
                    state, finite, pending, done = following, following_finite, (metrics, done, n), done + n
                if pending is not None:  # something was trained (a run resumed at its end only evaluates)
                    report(*pending)
                    save(state, total, finite)
            except KeyboardInterrupt:
                # Ctrl-C: `state` (at `done`, its metrics logged) is saved when a checkpoint is due
                # (one process only: several would have to agree); then the interrupt goes on up
                if (jax.process_count() == 1 and finite is not None and written == done > last_saved
                        and time.perf_counter() - saved >= cfg.checkpoint_seconds and not checkpoint.saving(run_dir)):
                    save(state, done, finite)
                raise
    finally:
        bar.close()
    return dataclasses.replace(training, state=state, done=done, seconds=time.perf_counter() - t0,
                               arrivals=tuple(arrivals))


def finish(cfg: RunConfig, run_dir: Path, training: Training, evaluations: list[dict], eval_compile: float,
           extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """Write a run's eval.json (its evaluations and timings) and learning curve; print the results."""
    compiled = training.compiled
    results = {"label": cfg.label, "env": cfg.env, "train_seconds_this_call": training.seconds,
               "train_seconds": training.before + training.seconds,
               "compile_seconds": {"train": compiled.seconds, "eval": eval_compile},
               "trace_seconds": {"train": compiled.trace_seconds}, "traced_programs_loaded": compiled.loaded,
               "train_env_steps_per_s": (training.done - training.first) * cfg.ppo.batch_size * cfg.seeds
               / max(training.seconds, 1e-9),
               "chunks_env_steps_per_s": chunks_rate(training, cfg.ppo.batch_size * cfg.seeds),
               "env_steps": cfg.ppo.num_updates * cfg.ppo.batch_size, "physics": cfg.physics,
               "devices": compiled.layout.count, "device": jax.devices()[0].device_kind,
               "deterministic": jax.default_backend() == "cpu" or xla_flags.deterministic_gpu_ops(), **(extra or {}),
               "evaluations": evaluations}
    if not devices.is_main():  # process 0 writes the run folder
        return results
    (run_dir / EVAL_JSON).write_text(json.dumps(results, indent=1))
    if (run_dir / METRICS_CSV).exists():
        plot_curves({cfg.label: read_curves(run_dir / METRICS_CSV)}, run_dir / CURVE_PNG, f"{cfg.env}: {cfg.label}")
    for ev in results["evaluations"]:
        print(f"{cfg.env}/{ev['variant']} {cfg.label}: {ev['mean']:.2f} +- {ev['std']:.2f}{metrics_text(ev)} "
              f"({ev['seeds']} seeds x {ev['episodes_per_seed']} episodes)  -> {run_dir}")
    return results


class Unlogged:
    """What a process other than the main one logs: nothing (process 0 writes metrics.csv and tb/)."""

    def write(self, metrics: dict[str, np.ndarray], after: int) -> None:
        pass

    def close(self) -> None:
        pass


def run_log(run_dir: Path, resume_update: int) -> RunLog | Unlogged:
    return RunLog(run_dir, resume_update=resume_update) if devices.is_main() else Unlogged()


def train(cfg: RunConfig, run_dir: Path, resume: bool = False, progress: bool = True) -> dict[str, Any]:
    """Train all seeds (in chunks, with checkpoints: see `advance`), evaluate, plot; returns eval results."""
    training = start(make_trainer(cfg), cfg, run_dir, resume, cfg.label)
    log = run_log(run_dir, training.done)
    variants = (cfg.variant, *cfg.eval_variants)
    shapes = jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding), training.state.params)
    # The evaluation program compiles on the host while the device trains (it needs only the
    # params' shapes), so its compile adds nothing to the wall-clock of a run that trains longer;
    # under physics=warp it compiles first (`evaluation_compiles_first`).
    with ThreadPoolExecutor(max_workers=1) as pool:
        evaluator = pool.submit(compile_evaluator, cfg, shapes, variants[0], cfg.eval_episodes, cfg.stochastic_eval,
                                layout=training.compiled.layout)
        if evaluation_compiles_first(cfg):
            evaluator.result()
        try:
            training = advance(training, cfg, run_dir, log.write, progress, cfg.label)
        finally:
            log.close()
        compiled = evaluator.result()
    evaluations, eval_compile = evaluate_variants(cfg, training.state.params, variants, cfg.eval_episodes,
                                                  cfg.stochastic_eval, compiled, training.compiled.layout)
    check_physics(cfg, cfg.label)
    return finish(cfg, run_dir, training, evaluations, eval_compile)


def train_group(group_cfgs: list[RunConfig], group_dir: Path, cell_dirs: list[Path], resume: bool = False,
                progress: bool = True) -> list[dict[str, Any]]:
    """Train configurations that share a network's shapes together (hintsjax.algorithms.group), all seeds of
    all of them in one compiled program; checkpoints of the group go to group_dir. Each member
    then gets what its own run would have written in its folder (cell_dirs, each holding its
    config.yaml): metrics.csv, its final state as a checkpoint, eval.json, learning_curve.png.
    GroupTooBig if the group's program would not fit on the device (before anything is written)."""
    group = make_group(group_cfgs)
    cfg = group.cfgs[0]
    label = f"group of {len(group.cfgs)} ({', '.join(c.label for c in group.cfgs)})"
    training = start(make_group_trainer(group), cfg, group_dir, resume, label, check_memory=len(group.cfgs) > 1)
    logs = [run_log(d, training.done) for d in cell_dirs]

    def write(metrics: dict[str, np.ndarray], after: int) -> None:  # [S, n, K]: one log per member
        for k, log in enumerate(logs):
            log.write({name: v[..., k] for name, v in metrics.items()}, after)

    try:
        training = advance(training, cfg, group_dir, write, progress, label)
    finally:
        for log in logs:
            log.close()
    for k, cell_dir in enumerate(cell_dirs):
        if checkpoint.latest_update(cell_dir) != training.done:
            checkpoint.save(cell_dir, cell_state(group, training.compiled.layout.crop(training.state), k), training.done)
    evaluations, eval_compile = evaluate_group(group, training.state, training.compiled.layout)
    rate = (training.done - training.first) * cfg.ppo.batch_size * cfg.seeds * len(group.cfgs) / max(training.seconds, 1e-9)
    extra = {"group": [c.label for c in group.cfgs], "group_dir": str(group_dir), "group_env_steps_per_s": rate}
    return [finish(member, cell_dir, training, member_evaluations, eval_compile, extra)
            for member, cell_dir, member_evaluations in zip(group.cfgs, cell_dirs, evaluations)]


def places(values: dict[str, Any]) -> tuple[str | None, str, str | None]:
    """(resume, out_dir, name) popped from `values` as strings, whatever YAML made of them
    (`name=2024` is a folder name, not a number); UsageError for a name that is not one folder's
    name inside out_dir (a path separator, `..`, or nothing)."""
    resume, out_dir, name = (values.pop(k, default) for k, default in (("resume", None), ("out_dir", "runs"), ("name", None)))
    resume, out_dir, name = (None if v is None else str(v).lower() if isinstance(v, bool) else str(v)
                             for v in (resume, out_dir, name))
    if name is not None and (not name.strip() or name in (".", "..") or any(sep in name for sep in ("/", "\\"))):
        raise UsageError(f"name must be one folder's name inside out_dir (no '/', '\\' or '..'), got {name!r}")
    return resume, out_dir or "runs", name


def refuse_overrides_on_resume(values: dict[str, Any]) -> None:
    """UsageError naming the settings given beside `resume` (a resumed run continues as it was
    configured: its config.yaml decides); values equal to the command line's defaults are none."""
    defaults = overrides.defaults()
    given = []
    for key, value in values.items():
        if key == "compilation_cache":
            continue
        default = defaults.get(key)
        if isinstance(value, dict):
            given += [f"{key}.{k}={v}" for k, v in value.items() if v != (default or {}).get(k)]
        elif value != default:
            given.append(f"{key}={value}")
    if given:
        raise UsageError(f"resume continues a run as its config.yaml says; drop {' '.join(given)} (or start a new run)")


@dataclasses.dataclass(frozen=True)
class Request:
    """What a command line asks for, checked: a new run (`cfg`, to go in out_dir/name) or a
    resumed one (`run_dir`, its config read from there)."""

    cfg: RunConfig
    run_dir: Path | None
    out_dir: str
    name: str | None
    longer: bool = False  # a resumed run given a larger ppo.total_env_steps (its config.yaml is rewritten)


def request(values: dict[str, Any]) -> Request:
    """The run that plain config values (what Hydra resolved) ask for; UsageError for anything
    that cannot run, found before any folder is made or anything compiled."""
    values = dict(values)
    values.pop("compilation_cache", None)
    resume, out_dir, name = places(values)
    steps = None
    if resume is not None:
        values["ppo"] = dict(values.get("ppo") or {})
        steps = values["ppo"].pop("total_env_steps", None)  # the one setting a resumed run may change
        refuse_overrides_on_resume(values)
        run_dir = Path(resume)
        cfg = load_run_config(run_dir, complete=True)  # a missing or bad checkpoint is reported by train's restore
        if steps is not None:
            cfg = train_longer(cfg, steps)
    else:
        cfg, run_dir = run_config(values), None
        paths.check_folder(out_dir, "out_dir")
    if cfg.agent_spec.imitates:
        experts.describe(cfg.env, cfg.expert)  # a missing or foreign expert
    # seed_layout refuses a Warp run it cannot place; then sizes that cannot fit, before the seeds' keys are drawn
    memory.check_run(cfg, seed_layout(cfg).per_device)
    return Request(cfg, run_dir, out_dir, name, longer=steps is not None)


def train_longer(cfg: RunConfig, steps: Any) -> RunConfig:
    """cfg with a budget of `steps` env steps a seed, for a resumed run to train on to; UsageError
    for a budget smaller than the one it was started with. The learning rates are constant, so
    training on from the saved state is the longer run, update for update."""
    saved = to_dict(cfg)
    longer = run_config({**saved, "ppo": {**saved["ppo"], "total_env_steps": steps}}, resolved=True)
    if longer.ppo.num_updates < cfg.ppo.num_updates:
        raise UsageError(f"a resumed run can train longer, not shorter: ppo.total_env_steps must be at least "
                         f"{cfg.ppo.total_env_steps} (its budget), got {steps}")
    return longer


def main_from_values(values: dict[str, Any]) -> int:
    """Run from plain config values (what Hydra resolved); returns the exit status."""
    try:
        asked = request(values)
    except UsageError as e:
        return fail(e)
    except Exception as e:  # noqa: BLE001  the boundary: a bug, not bad input
        return report_bug(e)
    cfg, run_dir = asked.cfg, asked.run_dir
    compilation_cache.enable(compilation_cache.folder(values.get("compilation_cache")))
    if run_dir is None:
        if devices.is_main():
            run_dir = new_run_dir(asked.out_dir, asked.name, cfg)
            save_run_config(run_dir, cfg)
        run_dir = Path(devices.agree(str(run_dir)))  # the folder process 0 made, on every process
    elif asked.longer and devices.is_main():
        save_run_config(run_dir, cfg)  # the budget it now trains to
    try:
        train(cfg, run_dir, resume=asked.run_dir is not None)
    except UsageError as e:
        return fail(e)
    except checkpoint.CheckpointWriteError as e:  # the newest complete checkpoint stays; resume from it
        print(f"error: {e}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:  # Ctrl-C: advance saved a checkpoint if one was due, and its writes are done
        good = checkpoint.latest_update(run_dir)
        print(f"interrupted; {f'checkpoint at update {good}' if good else 'no checkpoint yet'}; "
              f"go on with: python -m hintsjax.run resume={run_dir}", file=sys.stderr)
        return INTERRUPTED
    except NonFiniteError as e:  # its checkpoints were all written before it went non-finite
        good = checkpoint.latest_update(run_dir)  # read once the background writes are done
        if devices.is_main():
            (run_dir / NONFINITE_JSON).write_text(json.dumps({**e.found, "last_good_checkpoint": good}) + "\n")
        print(f"error: {e}; last good checkpoint: {f'update {good}' if good else 'none'} ({run_dir})", file=sys.stderr)
        return 1
    except Exception as e:  # noqa: BLE001  the boundary: a bug, its traceback kept in the run folder
        return report_bug(e, run_dir)
    return 0


@hydra.main(version_base=None, config_path="conf", config_name="config")
def _hydra_main(cfg: DictConfig) -> None:
    status = main_from_values(OmegaConf.to_container(cfg, resolve=True))
    if status:
        sys.exit(status)  # SystemExit passes through Hydra's exception reporting


@command
def checked_main() -> int:
    """The command line checked (every job of a sweep, before the first trains), then Hydra's run.
    --help: the registries' choices, then Hydra's page of the settings."""
    if {"-h", "--help"} & set(sys.argv[1:]):
        print(f"{__doc__.strip()}\n\n{choices.text()}\n")
    overrides.check_overrides(sys.argv[1:])
    if overrides.asks_only_for_warp(sys.argv[1:]):
        xla_flags.drop_determinism()  # nothing under MuJoCo Warp repeats bit for bit; they only cost speed
    overrides.check_sweep(sys.argv[1:], request)
    _hydra_main()  # exits itself with a run's non-zero status
    return 0


def main() -> None:
    sys.exit(checked_main())


if __name__ == "__main__":
    main()
