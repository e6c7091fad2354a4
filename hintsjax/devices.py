"""Where a run's seeds live: its seed axis split over every device it can use, whatever its seed count.

A run of S seeds on D devices holds ceil(S / D) x D of them: the seed axis is padded to a
multiple of D with copies of its first seeds, and each device runs the per-seed program
vmapped over its own share (`SeedLayout.spread`). The copies are dropped from every
result (`crop`): metrics, checkpoints (always S seeds, so a run resumes on any device count)
and evaluations. With several processes (`jax.distributed`), the devices are the global ones
and `fetch` gathers an array to every process's host.

What a layout changes (docs/design.md, "Reproducibility"): a seed's keys, and so its draws, are
the same on any layout, and the same command on the same kind and number of devices gives the
same numbers bit for bit. Another device count compiles another program (another share per
device, or one device's program against an SPMD one), whose floating-point sums may round
differently: a seed's numbers then agree statistically, not bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

AXIS = "seeds"


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
    def sharding(self) -> NamedSharding | None:
        """The seed axis split over the devices (None on one device: arrays stay where they are)."""
        return None if self.count == 1 else NamedSharding(self.mesh, PartitionSpec(AXIS))

    def pad(self, tree: Any) -> Any:
        """[S, ...] leaves -> [padded, ...], the extra seeds copies of the first ones, placed split
        over the devices."""
        if self.padded != self.seeds:
            take = np.arange(self.padded) % self.seeds
            tree = jax.tree.map(lambda x: x[take], tree)
        return tree if self.sharding is None else jax.device_put(tree, self.sharding)

    def crop(self, tree: Any) -> Any:
        """[padded, ...] leaves -> their first S seeds (the run's own)."""
        return tree if self.padded == self.seeds else jax.tree.map(lambda x: x[: self.seeds], tree)

    def spread(self, fn: Callable[..., Any], batched: int, shared: int = 0) -> Callable[..., Any]:
        """`fn(*batched_args, *shared_args)`, a function of seed-batched arrays (and of `shared`
        arguments the same for every seed), compiled for the seed axis split over the devices:
        XLA's SPMD partitioner gives each device its share (the seeds never meet, so no device
        talks to another). A shard_map of the same function crashed on 2 and 4 H100s (jax 0.11.2,
        a segfault in the first chunk), so the partitioner does it."""
        if self.count == 1:
            return fn
        seeds, everywhere = self.sharding, NamedSharding(self.mesh, PartitionSpec())
        return jax.jit(fn, in_shardings=(seeds,) * batched + (everywhere,) * shared, out_shardings=seeds)

    def fetch(self, tree: Any) -> Any:
        """Leaves as numpy arrays on this host, the run's S seeds of each (gathered from every
        process's devices when they are not all this process's)."""
        from jax.experimental import multihost_utils

        def host(x: Any) -> np.ndarray:
            if isinstance(x, jax.Array) and not x.is_fully_addressable:
                x = multihost_utils.process_allgather(x, tiled=True)
            return np.asarray(x)[: self.seeds]

        return jax.tree.map(host, tree)
