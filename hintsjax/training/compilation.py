"""A run's training programs compiled ahead of time for its seed-batched state, and whether they
fit.

`seed_layout` places a run's seeds over the devices; `compile_training` lowers a trainer's `init`
and its chunk of updates for that layout (each device runs its share of the seeds), through the
traced-program cache (hintsjax/system/program_cache.py), then compiles both; `check_fits` refuses
a group's program that needs more memory than the device has (GroupTooBig, which the sweeps answer
by splitting a group), `check_run_fits` a run's (one line naming the settings to lower), both by
XLA's memory analysis.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable

import jax
import numpy as np

from hintsjax.envs import physics
from hintsjax.system import memory, program_cache
from hintsjax.system.errors import UsageError
from hintsjax.system.devices import SeedLayout
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms.trainer import Trainer


def check_warp_run() -> None:
    """UsageError where a physics=warp run cannot go: over several processes (`seed_layout`)."""
    if jax.process_count() > 1:
        raise UsageError(
            "physics=warp runs in one process (on one GPU); drop JAX_NUM_PROCESSES or use "
            "physics=jax"
        )


def seed_layout(cfg: RunConfig) -> SeedLayout:
    """cfg's seeds over every device (of every process) JAX sees; a run with physics=warp on this
    process's first device only (jit's partitioner cannot split MJX-Warp's custom call: every
    device would step every world)."""
    if cfg.physics != physics.WARP:
        return SeedLayout.of(cfg.seeds)
    check_warp_run()
    return SeedLayout.of(cfg.seeds, jax.local_devices()[:1])


@dataclass(frozen=True)
class Compiled:
    """A run's training programs, compiled ahead of time for its seed-batched state."""

    init: Callable[[jax.Array], Any]  # [padded seeds] keys -> state
    # (state, n) -> (state n updates on, metrics [S, chunk]): the first n <= chunk updates of one
    # program, so every chunk, the shorter last one too, runs the same compiled code
    run_chunk: Callable[[Any, np.int32], tuple[Any, dict[str, jax.Array]]]
    chunk: int
    seconds: float  # spent tracing and compiling both
    # of which tracing and lowering to XLA (Python), or loading both as traced before
    trace_seconds: float
    loaded: bool  # both programs were read from the traced-program cache, not traced
    # the seeds over the devices (their count padded to a multiple of the devices)
    layout: SeedLayout


def compile_training(
    trainer: Trainer, keys: jax.Array, chunk: int, layout: SeedLayout | None = None
) -> Compiled:
    """Compile `trainer`'s init and its chunk of `chunk` updates for the seed keys' batch; with a
    `layout` of several devices (keys from its `pad`), each device runs its share of the seeds."""
    t = time.perf_counter()
    layout = layout or SeedLayout.of(keys.shape[0], sorted(keys.devices(), key=lambda d: d.id))
    init_fn = layout.spread(jax.vmap(trainer.init), batched=1)
    chunk_fn = layout.spread(
        jax.vmap(partial(trainer.run_chunk, length=chunk), in_axes=(0, None)), batched=1, shared=1
    )
    # traced, or loaded as traced by an earlier process (hintsjax/system/program_cache.py: one
    # device's programs only)
    identity = trainer.identity if layout.count == 1 else None
    init = program_cache.lower(init_fn, keys, name="init", context=identity)
    run_chunk = program_cache.lower(
        chunk_fn,
        init.out_info,
        np.int32(chunk),
        name=f"chunk{chunk}",
        # the state's shapes as init's lowering found them
        context=identity,
    )
    traced = time.perf_counter() - t
    loaded = all(getattr(program, "loaded", False) for program in (init, run_chunk))
    init, run_chunk = init.compile(), run_chunk.compile()
    return Compiled(init, run_chunk, chunk, time.perf_counter() - t, traced, loaded, layout)


class GroupTooBig(RuntimeError):
    """A group's compiled training program needs more memory than the device has."""


# of a device's memory, the most a compiled program may need: the rest is the runtime's, other
# buffers'
FITS = 0.9


def needs(compiled: Any) -> tuple[int, int] | None:
    """(bytes `compiled` (an XLA executable) needs by XLA's memory analysis: its arguments, outputs
    and temporaries, less what outputs share with arguments; the bytes a device has: a GPU's
    allocator limit, else the host's memory), or None where XLA gives no analysis."""
    analysis = compiled.memory_analysis()
    if analysis is None:
        return None
    need = (
        analysis.temp_size_in_bytes
        + analysis.argument_size_in_bytes
        + analysis.output_size_in_bytes
        - analysis.alias_size_in_bytes
    )
    return need, memory.device_bytes()


def check_fits(compiled: Any, what: str) -> None:
    """GroupTooBig if `compiled` needs more than FITS of the device's memory (`needs`)."""
    found = needs(compiled)
    if found is not None and found[0] > FITS * found[1]:
        raise GroupTooBig(
            f"{what} needs {found[0] / 2**30:.1f} GiB of the device's {found[1] / 2**30:.1f} GiB"
        )


# The settings that size a run's training programs: what a run that cannot fit is told to lower
# (here, and where an allocation fails anyway: hintsjax.training.pipeline).
TRAINING_SIZES = "ppo.batch_size (with ppo.num_envs and ppo.minibatch_size), seeds or image_size"


def check_run_fits(compiled: Any, cfg: Any) -> None:
    """UsageError naming the settings to lower if a run's compiled training program needs more than
    FITS of the device's memory: found from the compiled program before the first update, not as
    an out-of-memory error once it runs (the lower bounds of hintsjax.system.memory count less)."""
    found = needs(compiled)
    if found is not None and found[0] > FITS * found[1]:
        raise UsageError(
            f"seeds={cfg.seeds} x ppo.batch_size={cfg.ppo.batch_size} cannot fit: training's "
            f"compiled program needs {memory.sized(found[0])} (XLA's memory analysis), a device "
            f"has {memory.sized(found[1])}; lower {TRAINING_SIZES}"
        )
