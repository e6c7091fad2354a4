"""Is training bit-reproducible on this device? Trains the same seeds twice and compares.

    python experiments/determinism.py [--agent ppo_state] [--updates 20]

Prints the difference between two runs in one process and a checksum of the params: compare
the checksums of separate processes (a new compile may autotune differently), plain and with
XLA_FLAGS=--xla_gpu_deterministic_ops=true.
"""

from __future__ import annotations

import argparse
import os

import jax
import numpy as np

from hintsjax.settings.layers import run_config
from hintsjax.algorithms.registry import make_trainer


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--agent", default="ppo_state")
    parser.add_argument("--updates", type=int, default=20)
    args = parser.parse_args()
    cfg = run_config(
        {
            "env": "pendulum",
            "agent": args.agent,
            "seeds": 5,
            "ppo": {"total_env_steps": args.updates * 1024},
        }
    )
    trainer = make_trainer(cfg)
    keys = jax.random.split(jax.random.key(0), cfg.seeds)
    train = jax.jit(jax.vmap(trainer.train))
    runs = [jax.tree.map(np.asarray, train(keys)[0].params) for _ in range(2)]
    diff = max(
        float(np.abs(a - b).max())
        for a, b in zip(jax.tree.leaves(runs[0]), jax.tree.leaves(runs[1]))
    )
    print(
        f"{args.agent} {args.updates} updates, XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}: "
        f"max |param difference| between two runs in this process = {diff:.3g}, "
        "checksum "
        f"{sum(float(np.abs(x).astype(np.float64).sum()) for x in jax.tree.leaves(runs[0])):.10e}"
    )


if __name__ == "__main__":
    main()
