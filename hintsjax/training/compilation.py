"""A run's training programs compiled ahead of time for its seed-batched state, and whether they fit.

`compile_training` lowers a trainer's `init` and its chunk of updates for the seeds' layout over
the devices (each device runs its share of the seeds), through the traced-program cache
(hintsjax/system/program_cache.py), then compiles both; `check_fits` refuses a program that needs
more memory than the device has (GroupTooBig, which the sweeps answer by splitting a group).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable

import jax
import numpy as np

from hintsjax.system import program_cache
from hintsjax.system.devices import SeedLayout
from hintsjax.algorithms.trainer import Trainer


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
