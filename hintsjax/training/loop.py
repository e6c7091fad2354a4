"""The training loop: a run's programs compiled and its state started (fresh or from its newest
checkpoint), then advanced in chunks to its last update, with progress, checkpoints and the
guards between chunks. The device never waits on the host (see `advance`).
"""

from __future__ import annotations

import dataclasses
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import jax
import numpy as np
from tqdm import tqdm

from hintsjax import envs
from hintsjax.envs import physics
from hintsjax.system import checkpoint, devices
from hintsjax.system.devices import SeedLayout
from hintsjax.system.errors import UsageError
from hintsjax.system.signals import raise_stop_asked, stops_deferred, Terminated
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms.trainer import Trainer
from hintsjax.training.compilation import Compiled, check_fits, check_run_fits, compile_training
from hintsjax.training.guards import check_physics, finite_seeds, first_nonfinite, stop_nonfinite


# Training seconds (compiles excluded) up to the newest checkpoint, summed over resumed calls; and
# this call's compile seconds, of which tracing (Python).
SECONDS_JSON = "seconds.json"


def seconds_trained(run_dir: Path) -> float:
    """Training seconds that the newest checkpoint of `run_dir` holds (0 for a fresh folder)."""
    path = Path(run_dir) / SECONDS_JSON
    return json.loads(path.read_text())["seconds"] if path.exists() else 0.0


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
        raise UsageError(
            "physics=warp runs in one process (on one GPU); drop JAX_NUM_PROCESSES or use physics=jax"
        )


def seed_layout(cfg: RunConfig) -> SeedLayout:
    """cfg's seeds over every device (of every process) JAX sees; a run with physics=warp on this
    process's first device only (jit's partitioner cannot split MJX-Warp's custom call: every
    device would step every world)."""
    if cfg.physics != physics.WARP:
        return SeedLayout.of(cfg.seeds)
    check_warp_run()
    return SeedLayout.of(cfg.seeds, jax.local_devices()[:1])


def start(
    trainer: Trainer,
    cfg: RunConfig,
    run_dir: Path,
    resume: bool,
    label: str,
    check_memory: bool = False,
    before_first_state: Callable[[], None] = lambda: None,
) -> Training:
    """Compile `trainer`'s programs for cfg's seeds, then (after `before_first_state()`: MuJoCo
    Warp's kernel builds begun beside the compiles) a fresh state or the newest checkpoint of run_dir."""
    layout = seed_layout(cfg)
    keys = layout.pad(cfg.seed_keys())
    physics.clear_overflow()
    total = cfg.ppo.num_updates
    compiled = compile_training(trainer, keys, min(cfg.checkpoint_every, total), layout)
    if check_memory:
        check_fits(compiled.run_chunk, label)
    else:
        check_run_fits(compiled.run_chunk, cfg)
    before_first_state()
    # a checkpoint holds the run's own seeds, restored onto one device: padded and placed as at the
    # start
    if resume:
        state, done = checkpoint.restore_latest(run_dir, trainer.abstract_state(), set_aside=True)
        state = layout.pad(state)
    else:
        state, done = compiled.init(keys), 0
    # the first state's work (MuJoCo Warp's kernel builds too) counted before training
    jax.block_until_ready(state)
    spread = f" ({layout.per_device} a device{f', {layout.padded - cfg.seeds} of them padding' if layout.padded > cfg.seeds else ''})"
    # what auto chose, too
    stepped_by = f", {cfg.physics} physics" if cfg.env in envs.mjx_env_names() else ""
    print(
        f"{cfg.env} {label}: {cfg.seeds} seeds x {total} updates of {cfg.ppo.batch_size} env steps "
        f"on {layout.count} {jax.default_backend()} device(s){spread if layout.count > 1 else ''}{stepped_by}, "
        f"compiled in {compiled.seconds:.1f} s -> {run_dir}",
        flush=True,
    )
    return Training(compiled, state, done, done, seconds_trained(run_dir) if resume else 0.0)


def advance(
    training: Training,
    cfg: RunConfig,
    run_dir: Path,
    write: Callable[[dict[str, np.ndarray], int], None],
    progress: bool,
    label: str,
) -> Training:
    """Train to cfg's last update in chunks, checkpointing into run_dir; `write(metrics, after)`
    gets each chunk's metrics ([S, n, ...] for n updates after `after`).

    The device never waits on the host: each chunk is dispatched before the previous one's
    metrics are written and its state checkpointed (in the background), so logging and saving
    overlap with training. A save that comes due while the previous one is still being written
    is skipped (the newest complete checkpoint is then at most one write old); the last update
    is always saved. Compile seconds are reported apart from training seconds.
    """
    compiled, state, done, total = (
        training.compiled,
        training.state,
        training.done,
        cfg.ppo.num_updates,
    )
    layout = compiled.layout
    bar = tqdm(
        total=total,
        initial=done,
        unit="upd",
        disable=not (progress and devices.is_main()),
        desc=f"{cfg.env} {label}",
    )
    t0 = saved = time.perf_counter()
    last_saved = written = done  # the newest update saved (or being saved), and logged

    def save(state: Any, update: int, finite: jax.Array) -> None:
        """Checkpoint `state` unless `finite` (its finite_seeds) says some seed's params are not."""
        nonlocal saved, last_saved
        finite = layout.fetch(finite)
        if not finite.all():
            stop_nonfinite(
                run_dir,
                label,
                {"update": update, "quantity": "params", "seeds": np.flatnonzero(~finite).tolist()},
            )
        last_saved = update  # before the write starts: an interrupt never asks for it twice
        # the run's own seeds: it resumes on any device count
        checkpoint.save(run_dir, layout.crop(state), update)
        saved = time.perf_counter()
        if devices.is_main():
            (run_dir / SECONDS_JSON).write_text(
                json.dumps(
                    {
                        "update": update,
                        "seconds": training.before + saved - t0,
                        "compile_seconds": compiled.seconds,
                        "trace_seconds": compiled.trace_seconds,
                    }
                )
            )

    arrivals = []

    def report(metrics: dict[str, jax.Array], after: int, n: int) -> None:
        nonlocal written
        # waits for that chunk only
        metrics = {k: v[:, :n] for k, v in layout.fetch(metrics).items()}
        arrivals.append((time.perf_counter() - t0, after + n))
        write(metrics, after)
        written = after + n
        check_physics(cfg, label)  # before the NaN guard: a world that overflowed is NaN
        found = first_nonfinite(metrics, after)
        if found is not None:
            stop_nonfinite(run_dir, label, found)
        # the chunk's updates (NaN where no episode ended in one)
        returns = metrics["episode_return"]
        bar.set_postfix(
            steps=int(np.max(metrics["env_steps"][:, -1])),
            ret=f"{np.nanmean(returns):.1f}" if not np.all(np.isnan(returns)) else "-",
        )
        bar.update(n)

    pending = None  # (metrics, updates before, length) of the chunk dispatched last
    # finite_seeds of `state` once a chunk has made it (the state a call starts from is never saved)
    finite = None
    try:
        # leaving it, even by Ctrl-C, waits for the writes under way
        with checkpoint.writing(run_dir):
            try:
                # SIGTERM (or a preemption) waits for the safe point below, its state logged
                with stops_deferred():
                    while done < total:
                        n = min(compiled.chunk, total - done)
                        # returns at once; the device works on
                        following, metrics = compiled.run_chunk(state, np.int32(n))
                        # queued behind the chunk, so reading it once the chunk has run never stalls the device
                        following_finite = finite_seeds(following.params)
                        if pending is not None:
                            report(*pending)
                        # here `state` (at `done`) has its metrics logged, and no write is half-made
                        raise_stop_asked()
                        if devices.agree_that(
                            done > training.first
                            and time.perf_counter() - saved >= cfg.checkpoint_seconds
                            # process 0 decides for all
                            and not checkpoint.saving(run_dir)
                        ):
                            # the state this chunk started from: computed, copied off as the chunk
                            # runs
                            save(state, done, finite)
                        state, finite, pending, done = (
                            following,
                            following_finite,
                            (metrics, done, n),
                            done + n,
                        )
                    # something was trained (a run resumed at its end only evaluates)
                    if pending is not None:
                        report(*pending)
                        save(state, total, finite)
                # one asked during the last chunk: the end is saved; the run stops before evaluating
                raise_stop_asked()
            except KeyboardInterrupt as e:
                # Ctrl-C: `state` (at `done`, its metrics logged) is saved when a checkpoint is due;
                # SIGTERM (the job is going away: a time limit, preemption) saves it whenever it is
                # newer than the last save, after that write (one process only: several would
                # have to agree); then the interrupt goes on up
                due = isinstance(e, Terminated) or (
                    time.perf_counter() - saved >= cfg.checkpoint_seconds
                    and not checkpoint.saving(run_dir)
                )
                if (
                    jax.process_count() == 1
                    and finite is not None
                    and written == done > last_saved
                    and due
                ):
                    save(state, done, finite)
                raise
    finally:
        bar.close()
    return dataclasses.replace(
        training, state=state, done=done, seconds=time.perf_counter() - t0, arrivals=tuple(arrivals)
    )
