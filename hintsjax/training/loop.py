"""The training loop: a run's programs compiled and its state started (fresh or from its newest
checkpoint), then trained in chunks to its last update: `ChunkLoop` dispatches a chunk, logs the
one before it while the device works, saves when a checkpoint is due, and stops when asked. The
non-finite guard (guards.py), the asynchronous checkpoints (hintsjax/system/checkpoint.py) and
the deferred signals (hintsjax/system/signals.py) are the parts it calls by name.
"""

from __future__ import annotations

import contextlib
import dataclasses
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import jax
import numpy as np
from tqdm import tqdm

from hintsjax import envs
from hintsjax.envs import physics
from hintsjax.system import checkpoint, devices, paths
from hintsjax.system.signals import Terminated, raise_stop_asked, stops_deferred
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms.trainer import Trainer
from hintsjax.training.compilation import (
    Compiled,
    check_fits,
    check_run_fits,
    compile_training,
    seed_layout,
)
from hintsjax.training.guards import check_physics, finite_seeds, first_nonfinite, stop_nonfinite


# Training seconds (compiles excluded) up to the newest checkpoint, summed over resumed calls; and
# this call's compile seconds, of which tracing (Python).
SECONDS_JSON = "seconds.json"

# What gets each chunk's metrics: write(metrics [S, n, ...], updates before them)
MetricsWriter = Callable[[dict[str, np.ndarray], int], None]


def seconds_trained(run_dir: Path) -> float:
    """Training seconds that the newest checkpoint of `run_dir` holds (0 for a fresh folder). One
    that cannot be read (damaged by hand, or cut by a stop before it was written whole) counts
    from 0, with one line saying so: only eval.json's timings read it."""
    path = Path(run_dir) / SECONDS_JSON
    if not path.exists():
        return 0.0
    try:
        seconds = float(json.loads(path.read_text())["seconds"])
        if not 0 <= seconds < float("inf"):
            raise ValueError(seconds)
        return seconds
    except (OSError, ValueError, KeyError, TypeError) as e:
        print(
            f"warning: {path} is unreadable ({type(e).__name__}); this run's training seconds "
            "count from this call",
            file=sys.stderr,
        )
        return 0.0


@dataclass
class Training:
    """A training run's progress: its compiled programs, state and timing (what
    `start_training` makes and `train_in_chunks` carries on)."""

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


def start_training(
    trainer: Trainer,
    cfg: RunConfig,
    run_dir: Path,
    resume: bool,
    label: str,
    check_memory: bool = False,
    before_first_state: Callable[[], None] = lambda: None,
) -> Training:
    """Compile `trainer`'s programs for cfg's seeds, then (after `before_first_state()`: MuJoCo
    Warp's kernel builds begun beside the compiles) a fresh state or the newest checkpoint of
    run_dir."""
    layout = seed_layout(cfg)
    keys = layout.pad(cfg.seed_keys())
    physics.clear_overflow()
    total = cfg.ppo.num_updates
    compiled = compile_training(trainer, keys, min(cfg.checkpoint_every, total), layout)
    if check_memory:
        check_fits(compiled.run_chunk, label)
    else:
        check_run_fits(compiled.run_chunk, cfg)
    raise_stop_asked()  # a signal while compiling (whose exception Python may have dropped)
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
    print(
        f"{cfg.env} {label}: {_started_text(cfg, layout, total, compiled)} -> {run_dir}", flush=True
    )
    return Training(compiled, state, done, done, seconds_trained(run_dir) if resume else 0.0)


def _started_text(cfg: RunConfig, layout: Any, total: int, compiled: Compiled) -> str:
    padding = layout.padded - cfg.seeds
    spread = f" ({layout.per_device} a device{f', {padding} of them padding' if padding else ''})"
    # the physics auto chose, too
    stepped_by = f", {cfg.physics} physics" if cfg.env in envs.mjx_env_names() else ""
    return (
        f"{cfg.seeds} seeds x {total} updates of {cfg.ppo.batch_size} env steps on {layout.count} "
        f"{jax.default_backend()} device(s){spread if layout.count > 1 else ''}{stepped_by}, "
        f"compiled in {compiled.seconds:.1f} s"
    )


def train_in_chunks(
    training: Training,
    cfg: RunConfig,
    run_dir: Path,
    write: MetricsWriter,
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
    return ChunkLoop(training, cfg, run_dir, write, label).run(progress)


class ChunkLoop:
    """One call's chunks of a run: the newest state dispatched, the chunk whose metrics are still
    to be logged, and what has been logged and saved."""

    def __init__(
        self, training: Training, cfg: RunConfig, run_dir: Path, write: MetricsWriter, label: str
    ):
        self.training, self.cfg, self.run_dir, self.write, self.label = (
            training,
            cfg,
            run_dir,
            write,
            label,
        )
        self.compiled, self.layout = training.compiled, training.compiled.layout
        self.total = cfg.ppo.num_updates
        self.state, self.done = (
            training.state,
            training.done,
        )  # the newest state dispatched, its updates
        # finite_seeds of `state` once a chunk has made it (the state a call starts from is never
        # saved)
        self.finite: jax.Array | None = None
        self.pending: tuple[dict[str, jax.Array], int, int] | None = (
            None  # (metrics, after, n): not yet logged
        )
        self.logged = self.saved = training.done  # the newest update logged; saved (or being saved)
        self.started = self.saved_at = 0.0  # perf_counter when `run` began (and last saved)
        self.arrivals: list[tuple[float, int]] = []
        self.bar: Any = None

    def run(self, progress: bool) -> Training:
        """Every chunk to the last update, then that update saved (see `train_in_chunks`)."""
        show = progress and devices.is_main()
        desc = f"{self.cfg.env} {self.label}"
        self.bar = tqdm(
            total=self.total, initial=self.done, unit="upd", disable=not show, desc=desc
        )
        self.started = self.saved_at = time.perf_counter()
        try:
            with checkpoint.writing(
                self.run_dir
            ):  # leaving it, even by Ctrl-C, waits for the writes under way
                try:
                    # SIGTERM (or a preemption) waits for a safe point in `step`, its state logged
                    with stops_deferred():
                        while self.done < self.total:
                            self.step()
                        if (
                            self.pending is not None
                        ):  # something was trained (a run resumed at its end only evaluates)
                            self.log(*self.pending)
                            self.save(self.total)
                    # one asked during the last chunk: the end is saved; the run stops before
                    # evaluating
                    raise_stop_asked()
                except KeyboardInterrupt as stop:
                    self.save_before_stopping(stop)
                    raise
        finally:
            self.bar.close()
        return dataclasses.replace(
            self.training,
            state=self.state,
            done=self.done,
            seconds=time.perf_counter() - self.started,
            arrivals=tuple(self.arrivals),
        )

    def step(self) -> None:
        """Dispatch the next chunk, log the one before it while the device runs this one, stop if a
        signal asked, save the state this chunk started from if a checkpoint is due."""
        n = min(self.compiled.chunk, self.total - self.done)
        following, metrics = self.compiled.run_chunk(
            self.state, np.int32(n)
        )  # returns at once; the device works on
        # queued behind the chunk, so reading it once the chunk has run never stalls the device
        following_finite = finite_seeds(following.params)
        try:
            if self.pending is not None:
                self.log(*self.pending)
            # here `state` (at `done`) has its metrics logged, and no write is half-made
            raise_stop_asked()
            if self.checkpoint_due():
                self.save(self.done)  # computed, and copied off as the chunk runs
        except BaseException:
            # the chunk still runs: the process must not exit under it (XLA's teardown crashed)
            with contextlib.suppress(Exception):  # a chunk that failed: the error raised stands
                jax.block_until_ready((following, metrics, following_finite))
            raise
        self.state, self.finite = following, following_finite
        self.pending, self.done = (metrics, self.done, n), self.done + n

    def checkpoint_due(self) -> bool:
        """Whether to save `state` now: checkpoint_seconds since the last save, none being written,
        and something trained this call (process 0 decides for all)."""
        due = time.perf_counter() - self.saved_at >= self.cfg.checkpoint_seconds
        return devices.agree_that(
            self.done > self.training.first and due and not checkpoint.saving(self.run_dir)
        )

    def log(self, metrics: dict[str, jax.Array], after: int, n: int) -> None:
        """A chunk's metrics written and shown, then the guards: MJX-Warp's buffers, non-finite
        losses."""
        metrics = {
            k: v[:, :n] for k, v in self.layout.fetch(metrics).items()
        }  # waits for that chunk only
        self.arrivals.append((time.perf_counter() - self.started, after + n))
        self.write(metrics, after)
        self.logged = after + n
        check_physics(self.cfg, self.label)  # before the NaN guard: a world that overflowed is NaN
        found = first_nonfinite(metrics, after)
        if found is not None:
            stop_nonfinite(self.run_dir, self.label, found)
        returns = metrics[
            "episode_return"
        ]  # the chunk's updates (NaN where no episode ended in one)
        self.bar.set_postfix(
            steps=int(np.max(metrics["env_steps"][:, -1])),
            ret=f"{np.nanmean(returns):.1f}" if not np.all(np.isnan(returns)) else "-",
        )
        self.bar.update(n)

    def save(self, update: int) -> None:
        """Checkpoint `state` (at `update`) unless `finite` says some seed's params are not."""
        finite = self.layout.fetch(self.finite)
        if not finite.all():
            seeds = np.flatnonzero(~finite).tolist()
            stop_nonfinite(
                self.run_dir, self.label, {"update": update, "quantity": "params", "seeds": seeds}
            )
        self.saved = update  # before the write starts: an interrupt never asks for it twice
        # the run's own seeds: it resumes on any device count
        checkpoint.save(self.run_dir, self.layout.crop(self.state), update)
        self.saved_at = time.perf_counter()
        if devices.is_main():
            seconds = {
                "update": update,
                "seconds": self.training.before + self.saved_at - self.started,
                "compile_seconds": self.compiled.seconds,
                "trace_seconds": self.compiled.trace_seconds,
            }
            paths.write_text_whole(self.run_dir / SECONDS_JSON, json.dumps(seconds))

    def save_before_stopping(self, stop: KeyboardInterrupt) -> None:
        """Ctrl-C: `state` (at `done`, its metrics logged) is saved when a checkpoint is due;
        SIGTERM (the job is going away: a time limit, preemption) saves it whenever it is newer
        than the last save, after that write (one process only: several would have to agree)."""
        due = isinstance(stop, Terminated) or (
            time.perf_counter() - self.saved_at >= self.cfg.checkpoint_seconds
            and not checkpoint.saving(self.run_dir)
        )
        if (
            jax.process_count() == 1
            and self.finite is not None
            and self.logged == self.done > self.saved
            and due
        ):
            self.save(self.done)
