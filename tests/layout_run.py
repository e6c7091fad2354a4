"""A tiny run and a tiny group trained on this process's devices, for tests/test_devices.py.

    XLA_FLAGS=--xla_force_host_platform_device_count=4 python tests/layout_run.py <folder>

Trains the linear env's ppo_state at 3 seeds (on 4 devices: 1 seed a device, 1 of them
padding) with a checkpoint after every chunk of 2 updates, and the group of ppo_state and
ppo_noisy_state at 3 seeds; prints one JSON line: the device count and each one's evaluation.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import jax

import linear_env  # noqa: F401  (registers the test env "linear")
from hintsjax.settings.layers import run_config, save_run_config
from hintsjax.training import pipeline

TINY_PPO = {
    "total_env_steps": 320,
    "num_envs": 4,
    "batch_size": 64,
    "minibatch_size": 32,
    "epochs": 1,
}


def values(agent: str) -> dict:
    return {
        "env": "linear",
        "agent": agent,
        "seeds": 3,
        "ppo": TINY_PPO,
        "eval_episodes": 2,
        "checkpoint_every": 2,
        "checkpoint_seconds": 0,
    }


def main() -> None:
    out = Path(sys.argv[1])
    cfg = run_config(values("ppo_state"))
    (out / "alone").mkdir(parents=True)
    save_run_config(out / "alone", cfg)
    alone = pipeline.train(cfg, out / "alone", progress=False)
    cfgs = [run_config(values(agent)) for agent in ("ppo_state", "ppo_noisy_state")]
    dirs = [out / "group" / c.label for c in cfgs]
    for d, c in zip(dirs, cfgs):
        d.mkdir(parents=True)
        save_run_config(d, c)
    group = pipeline.train_group(cfgs, out / "group" / "_group", dirs, progress=False)
    print(
        json.dumps(
            {
                "devices": len(jax.devices()),
                "alone": alone["evaluations"][0]["seed_means"],
                "group": [r["evaluations"][0]["seed_means"] for r in group],
            }
        )
    )


if __name__ == "__main__":
    main()
