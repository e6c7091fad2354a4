"""Where a run's seeds live: its seed axis split over every device it can use, whatever its seed
count.

A run of S seeds on D devices holds ceil(S / D) x D of them: the seed axis is padded to a
multiple of D with copies of its first seeds, and each device runs the per-seed program
vmapped over its own share (`SeedLayout.spread`). The copies are dropped from every
result (`crop`): metrics, checkpoints (always S seeds, so a run resumes on any device count)
and evaluations. With several processes (`jax.distributed`), the devices are the global ones
and `fetch` gathers an array to every process's host.

What a layout changes (docs/design.md, "Several devices and processes"): a seed's keys, and so
its draws, are the same on any layout, and the same command on the same kind and number of
devices gives the same numbers bit for bit. Another device count compiles another program
(another share per device, or one device's program against an SPMD one), whose floating-point
sums may round differently: a seed's numbers then agree statistically, not bit for bit.
"""

from __future__ import annotations

import functools
import os
from dataclasses import dataclass
from typing import Any, Callable

import jax
import numpy as np
from jax.experimental import multihost_utils
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "seeds"


def join_processes() -> int:
    """Join the run's other processes, if it has any, before JAX touches a device; the process
    count. hintsjax/__init__.py calls it on import, so every command joins before its modules load.

    With JAX_NUM_PROCESSES > 1 (and JAX_COORDINATOR_ADDRESS, JAX_PROCESS_ID), or inside a SLURM
    job step of several tasks (`srun`), every process calls jax.distributed.initialize; the
    devices of all of them then form one mesh (`jax.devices()`), and CPU processes talk through
    gloo. Elsewhere nothing happens."""
    count = int(os.environ.get("JAX_NUM_PROCESSES", "1") or 1)
    slurm = int(os.environ.get("SLURM_STEP_NUM_TASKS", "1") or 1)
    if (count > 1 or slurm > 1) and not jax.distributed.is_initialized():
        jax.config.update("jax_cpu_collectives_implementation", "gloo")
        if count > 1:
            jax.distributed.initialize(
                os.environ.get("JAX_COORDINATOR_ADDRESS"),
                count,
                int(os.environ.get("JAX_PROCESS_ID", "0")),
            )
        else:
            jax.distributed.initialize()  # JAX's own detection of SLURM's variables
    return jax.process_count()


def is_main() -> bool:
    """Whether this process writes the run folder (process 0; every process when there is one)."""
    return jax.process_index() == 0


def agree(text: str) -> str:
    """Process 0's `text`, on every process (e.g. the run folder it chose)."""
    if jax.process_count() == 1:
        return text
    data = np.zeros(4096, np.uint8)
    raw = text.encode()[:4096]
    data[: len(raw)] = np.frombuffer(raw, np.uint8)
    return bytes(np.asarray(multihost_utils.broadcast_one_to_all(data))).rstrip(b"\0").decode()


def agree_that(flag: bool) -> bool:
    """Process 0's `flag`, on every process (a choice that all of them must make alike, such as
    writing a checkpoint now: each process writes its share)."""
    if jax.process_count() == 1:
        return flag
    return bool(multihost_utils.broadcast_one_to_all(np.asarray(flag)))


def every_process(flag: bool) -> bool:
    """Whether `flag` holds on every process, each giving its own (a collective all of them join):
    a choice whose cause may show on one process only, as a failed write."""
    if jax.process_count() == 1:
        return flag
    return bool(np.all(multihost_utils.process_allgather(np.asarray(flag))))


@functools.lru_cache(maxsize=None)
def _first_seeds(seeds: int, everywhere: NamedSharding) -> Callable[[Any], Any]:
    """A compiled program: a tree's first `seeds` of each leaf, a whole copy on every device."""
    return jax.jit(lambda tree: jax.tree.map(lambda x: x[:seeds], tree), out_shardings=everywhere)


def _place(x: Any, sharding: NamedSharding) -> jax.Array:
    """`x` (the same value on every process) as a global array split by `sharding`."""
    if jax.process_count() == 1:
        return jax.device_put(x, sharding)
    if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
        return jax.random.wrap_key_data(
            _place(jax.random.key_data(x), sharding), impl=jax.random.key_impl(x)
        )
    host = np.asarray(x)
    return jax.make_array_from_callback(host.shape, sharding, lambda index: host[index])


@dataclass(frozen=True)
class SeedLayout:
    """S seeds over devices: padded to a multiple of the device count, split along the seed axis."""

    seeds: int
    devices: tuple[Any, ...]

    @classmethod
    def of(cls, seeds: int, devices: Any = None) -> "SeedLayout":
        """`seeds` over `devices` (default: every device of the default backend, all processes')."""
        return cls(seeds, tuple(jax.devices() if devices is None else devices))

    @property
    def count(self) -> int:
        return len(self.devices)

    @property
    def padded(self) -> int:
        """Seeds held: the smallest multiple of the device count that holds them all."""
        return -(-self.seeds // self.count) * self.count

    @property
    def per_device(self) -> int:
        return self.padded // self.count

    @property
    def mesh(self) -> Mesh:
        return Mesh(np.array(self.devices), (AXIS,))

    @property
    def everywhere(self) -> NamedSharding:
        """A whole copy on every device (what `spread`'s shared arguments and `crop`'s result
        are)."""
        return NamedSharding(self.mesh, PartitionSpec())

    @property
    def sharding(self) -> NamedSharding | None:
        """The seed axis split over the devices (None on one device: arrays stay where they are)."""
        return None if self.count == 1 else NamedSharding(self.mesh, PartitionSpec(AXIS))

    def pad(self, tree: Any) -> Any:
        """[S, ...] leaves -> [padded, ...], the extra seeds copies of the first ones, placed split
        over the devices."""
        if self.padded != self.seeds:
            take = np.arange(self.padded) % self.seeds
            tree = jax.tree.map(lambda x: x[take], tree)
        return (
            tree
            if self.sharding is None
            else jax.tree.map(lambda x: _place(x, self.sharding), tree)
        )

    def crop(self, tree: Any) -> Any:
        """[padded, ...] leaves -> their first S seeds (the run's own), on every device.

        One compiled program for the whole tree, not an eager slice a leaf: over several
        processes each eager op is a program that every process must run in step, and a
        checkpoint's hundreds of them hung two processes on 2 cores in CI."""
        if self.padded == self.seeds:
            return tree
        if self.sharding is None:
            return jax.tree.map(lambda x: x[: self.seeds], tree)
        return _first_seeds(self.seeds, self.everywhere)(tree)

    def spread(self, fn: Callable[..., Any], batched: int, shared: int = 0) -> Callable[..., Any]:
        """`fn(*batched_args, *shared_args)`, a function of seed-batched arrays (and of `shared`
        arguments the same for every seed), compiled for the seed axis split over the devices:
        XLA's SPMD partitioner gives each device its share (the seeds never meet, so no device
        talks to another). A shard_map of the same function crashed on several GPUs (a segfault in
        the first chunk; docs/gpu.md), so the partitioner does it."""
        if self.count == 1:
            return fn
        seeds = self.sharding
        return jax.jit(
            fn, in_shardings=(seeds,) * batched + (self.everywhere,) * shared, out_shardings=seeds
        )

    def fetch(self, tree: Any) -> Any:
        """Leaves as numpy arrays on this host, the run's S seeds of each (gathered from every
        process's devices when they are not all this process's)."""

        def host(x: Any) -> np.ndarray:
            # replicated by `crop`: any copy
            if isinstance(x, jax.Array) and not x.is_fully_addressable:
                x = x.addressable_data(0)
            return np.asarray(x)[: self.seeds]

        if jax.process_count() > 1:  # one program gathers the whole tree (see `crop`)
            tree = _first_seeds(self.seeds, self.everywhere)(tree)
        return jax.tree.map(host, tree)
