"""Seconds spent tracing (Python, before XLA compiles) the programs of one cell: training's init
and chunk, and evaluation. No cache can save this time, so it bounds a warm start.

    python experiments/trace_time.py [--envs pendulum,ant] [--physics auto|jax|warp]

It lowers the programs without compiling them, so it runs on a CPU as on a GPU.
"""

from __future__ import annotations

import argparse
import time
from functools import partial

import jax
import numpy as np

from hintsjax import envs
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.settings.layers import run_config
from hintsjax.algorithms.registry import make_trainer
from hintsjax.evaluation.evaluator import eval_keys, make_task_evaluator


def trace_seconds(env: str, physics: str = envs.AUTO) -> tuple[float, float]:
    """(training's init and chunk, evaluation) tracing seconds of env's default hints/fc cell."""
    cfg = run_config(
        {"env": env, "agent": "hints", "hint": ENV_DEFAULTS[env]["hint"], "physics": physics}
    )
    t = time.perf_counter()
    trainer = make_trainer(cfg)
    init = jax.jit(jax.vmap(trainer.init)).lower(cfg.seed_keys())
    jax.jit(jax.vmap(partial(trainer.run_chunk, length=10), in_axes=(0, None))).lower(
        init.out_info, np.int32(10)
    )
    t1 = time.perf_counter()
    evaluate = jax.jit(
        jax.vmap(make_task_evaluator(cfg, cfg.eval_episodes), in_axes=(0, 0, None, None))
    )
    evaluate.lower(init.out_info.params, eval_keys(cfg), envs.make_params(env, None), False)
    return t1 - t, time.perf_counter() - t1


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default="pendulum,ant")
    parser.add_argument(
        "--physics", default=envs.AUTO, help="auto, jax or warp: what steps the MJX envs"
    )
    args = parser.parse_args()
    for env in args.envs.split(","):
        train, evaluate = trace_seconds(env, args.physics)
        print(
            f"{env}: training programs traced in {train:.2f} s, evaluation in {evaluate:.2f} s "
            f"(physics={envs.resolve_physics(env, args.physics)}; "
            f"{jax.default_backend()}, jax {jax.__version__})",
            flush=True,
        )


if __name__ == "__main__":
    main()
