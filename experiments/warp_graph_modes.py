"""MJX-Warp's CUDA graph modes and the overflow report, measured on an env's rollout.

    python experiments/warp_graph_modes.py --env ant
        --variants default:1,default:0,none:1,warp_staged:1,warp_staged_ex:1

Each variant is `graph_mode:report`: the graph mode MJX-Warp's kernels are launched with
(`default`: MJX's own choice on a GPU, Warp capturing a CUDA graph and replaying it for matching
buffers; `none`, `jax`, `warp_staged`, `warp_staged_ex`: warp.JaxCallableGraphMode) and whether
the per-call overflow report (envs/physics.py) is compiled in (1) or not (0). The row is the
env steps per second of a 16-step scan of `--envs` envs (the ant cell's 5 seeds x 256) with
AutoReset, pictures and uniform random actions, best of three after a compile. With `--train`,
the env's default training cell (5 seeds, 30 updates) runs too, through run.train and as its
compiled chunks back to back (experiments/bench.py `bench_train`), once, with MJX-Warp as
the command line builds it (the default graph mode, the overflow report on).
"""

from __future__ import annotations

import argparse
import json
import time

import jax

from hintsjax import envs
from hintsjax.envs import physics


def rollout_rate(env, n: int, steps: int = 16) -> tuple[float, float]:
    """(env steps/s, seconds of the first call: compile and run)."""
    env, params = envs.AutoReset(env), env.default_params()
    ts = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(
        jax.random.split(jax.random.key(0), n), params
    )

    @jax.jit
    def roll(state, key):
        def step(state, key):
            k_act, k_env = jax.random.split(key)
            action = jax.random.uniform(k_act, (n, env.action_size), minval=-1, maxval=1)
            out = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_env, n), state, action, params
            )
            return out.state, out.obs["pixels"][:, 32, 32, 0].sum() + out.reward.sum()

        return jax.lax.scan(step, state, jax.random.split(key, steps))

    t = time.perf_counter()
    jax.block_until_ready(roll(ts.state, jax.random.key(1)))
    first = time.perf_counter() - t
    best = float("inf")
    for i in range(3):
        t = time.perf_counter()
        jax.block_until_ready(roll(ts.state, jax.random.key(2 + i)))
        best = min(best, time.perf_counter() - t)
    return n * steps / best, first


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="ant", choices=envs.mjx_env_names())
    parser.add_argument(
        "--variants", default="default:1,default:0,none:1,warp_staged:1,warp_staged_ex:1"
    )
    parser.add_argument("--envs", type=int, default=1280)
    parser.add_argument(
        "--train", action="store_true", help="the env's training cell too, per variant"
    )
    args = parser.parse_args()
    from bench import bench_train

    hint = envs.REGISTRY[args.env].training.get("hint", envs.NO_HINT)
    for variant in args.variants.split(","):
        mode, report = variant.split(":")
        env = envs.make(args.env, hint, ("pixels", "hint"), physics="warp")
        env.physics = physics.WarpPhysics(
            env.mj_model,
            graph_mode=None if mode == "default" else mode,
            report_overflow=report == "1",
        )
        rate, first = rollout_rate(env, args.envs)
        print(
            json.dumps(
                {
                    "env": args.env,
                    "graph_mode": mode,
                    "report_overflow": report == "1",
                    "num_envs": args.envs,
                    "env_steps_per_s": rate,
                    "first_call_s": first,
                    "device": jax.devices()[0].device_kind,
                }
            ),
            flush=True,
        )
    if args.train:
        r = bench_train(args.env, 5, 30, {}, physics="warp")
        print(
            json.dumps(
                {
                    "env": args.env,
                    "train_env_steps_per_s": r["env_steps_per_s"],
                    "chunks_env_steps_per_s": r["chunks_env_steps_per_s"],
                    "scan_env_steps_per_s": r["scan_env_steps_per_s"],
                    "compile_s": r["compile_s"],
                    "update_parts_s": r["update_parts_s"],
                }
            ),
            flush=True,
        )


if __name__ == "__main__":
    main()
