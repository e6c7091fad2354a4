"""Does a checkpoint's save wait for the chunk running on the device? One cell's chunk program,
then saves of the state a chunk started from while that chunk runs, as the run loop makes them.

    python experiments/checkpoint_stall.py [--env pendulum] [--repeats 3]

For each way of saving it prints the seconds the save call took and when the running chunk
ended, counted from its dispatch, against one chunk alone: a save that takes about a chunk's time
waited for it (the device then idles until the loop dispatches the next chunk); a chunk that ends
later than one alone was slowed by the save's work beside it. (An array's `is_ready()` is not
used: on an H200 it reported the chunk finished 0.1 s after its dispatch, while the chunk ran
0.8 s.)
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import jax
import numpy as np

from hintsjax.system import checkpoint
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.settings.layers import run_config
from hintsjax.algorithms.registry import make_trainer
from hintsjax.training import compilation


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="pendulum")
    parser.add_argument("--repeats", type=int, default=3)
    args = parser.parse_args()
    cfg = run_config(
        {"env": args.env, "agent": "hints", "scheme": "fc", "hint": ENV_DEFAULTS[args.env]["hint"]}
    )
    keys = cfg.seed_keys()
    compiled = compilation.compile_training(make_trainer(cfg), keys, cfg.checkpoint_every)
    n = np.int32(compiled.chunk)
    state, _ = jax.block_until_ready(compiled.run_chunk(compiled.init(keys), n))
    t = time.perf_counter()
    jax.block_until_ready(compiled.run_chunk(state, n))
    chunk = time.perf_counter() - t
    print(
        f"{args.env}: one chunk of {compiled.chunk} updates takes {chunk:.3f} s "
        f"({jax.devices()[0].device_kind})"
    )

    def device_get(folder: Path, state, update: int) -> None:
        jax.device_get(state)

    # name -> (save, copy the state towards the host before the next chunk is dispatched)
    ways = {
        "checkpoint.save": (checkpoint.save, False),
        "jax.device_get": (device_get, False),
        "checkpoint.save, copied before the chunk": (checkpoint.save, True),
    }
    with tempfile.TemporaryDirectory() as folder:
        folder = Path(folder)
        with checkpoint.writing(folder):
            update = 0
            for name, (save, copy_first) in ways.items():
                for _ in range(args.repeats):
                    update += 1
                    if copy_first:
                        for x in jax.tree.leaves(state):
                            if not jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key):
                                x.copy_to_host_async()
                    t0 = time.perf_counter()
                    following, _ = compiled.run_chunk(state, n)  # the device works on
                    t = time.perf_counter()
                    save(folder, state, update)
                    took = time.perf_counter() - t
                    jax.block_until_ready(following)
                    print(
                        f"  {name}: {took:.3f} s; the chunk ended {time.perf_counter() - t0:.3f} s "
                        "after its dispatch",
                        flush=True,
                    )
                    while checkpoint.saving(folder):
                        time.sleep(0.01)


if __name__ == "__main__":
    main()
