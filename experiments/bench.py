"""Throughput of each env (with its picture), of training end to end, and the ceiling.

    python experiments/bench.py [--envs pendulum,acrobot,idp] [--sizes 4096,65536] [--steps 100]
                                [--no-train] [--reset-cost] [--default-train-only] [--quick]
                                [--out results.json]
                                [--model-option integrator=EULER ...]

Measures, in one process on whatever device JAX sees:
  env      env steps/s including the env's picture (AutoReset, vmapped, in a scan), beside the
           same loop without the picture (physics, reward and hint only); --reset-cost adds the
           picture loop with next starts drawn once per rollout of 8 steps (ppo.starts_per_rollout)
           and without AutoReset (which otherwise draws a start, picture and all, every step)
  ceiling  the encoder + heads' own update rate: samples/s of one forward+backward+Adam step
           of the hints/fc network at batch 8192 (nothing else in the graph)
  train    end-to-end training (rollout, GAE, epochs of minibatch updates), seed-vmapped, timed
           through pipeline.train, the function the command line runs (compile apart), beside the
           same updates as one bare jitted scan: env steps/s, and gradient samples/s = env steps/s x
           epochs, as a fraction of the ceiling (1.0 would mean the GPU did nothing but full-batch
           updates); and the milliseconds of one update's rollout, learning and env steps alone
Each timing is the best of a few repetitions after a compile-and-warm-up call. Where every env
steps with MuJoCo Warp (`--physics warp`, or auto where it gives Warp) the process runs without
deterministic GPU ops, as the command does (hintsjax/run.py); elsewhere with them.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import optax

from hintsjax import envs
from hintsjax.system import compilation_cache, xla_flags
from hintsjax.settings.algorithm_settings import ENCODER_DTYPES
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.settings.layers import run_config
from hintsjax.algorithms.ppo import Hyper, make_network, make_optimizer, make_trainer
from hintsjax.algorithms.ppo_math import gaussian_log_prob


def best_time(fn, *args, repeats: int = 3) -> float:
    jax.block_until_ready(fn(*args))
    times = []
    for _ in range(repeats):
        t = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t)
    return min(times)


RESETS = {  # how AutoReset gets the next start: the --reset-cost rows compare them
    "step": "AutoReset",  # drawn on every step (AutoReset's default)
    # drawn once per 8 steps (ppo.starts_per_rollout)
    "rollout": "AutoReset, starts per rollout of 8",
    "none": "no AutoReset",  # episodes run on past their end
}


# mj_model.opt fields whose values are MuJoCo enums, named in --model-option by their suffix
OPTION_ENUMS = {
    "integrator": mujoco.mjtIntegrator,
    "solver": mujoco.mjtSolver,
    "cone": mujoco.mjtCone,
    "jacobian": mujoco.mjtJacobian,
}


def model_options(items: list[str]) -> dict:
    """mj_model.opt overrides from FIELD=VALUE items (an enum by its suffix: integrator=EULER);
    ValueError naming the valid fields or values."""
    fields = sorted(f for f in dir(mujoco.MjOption) if not f.startswith("_"))
    options = {}
    for item in items:
        field, _, value = item.partition("=")
        if field not in fields or not value:
            raise ValueError(
                f"--model-option {item!r}: give FIELD=VALUE with FIELD one of {', '.join(fields)}"
            )
        if field in OPTION_ENUMS:
            members = {
                name.split("_", 1)[1]: m for name, m in OPTION_ENUMS[field].__members__.items()
            }
            if value.upper() not in members:
                raise ValueError(f"--model-option {item!r}: {field} is one of {', '.join(members)}")
            options[field] = members[value.upper()]
        else:
            options[field] = float(value) if "." in value or "e" in value.lower() else int(value)
    return options


def bench_env(
    name: str,
    num_envs: int,
    steps: int,
    pixels: bool = True,
    reset: str = "step",
    rollout: int = 8,
    options: dict | None = None,
    physics: str = envs.AUTO,
) -> dict:
    observe = ("pixels", "hint") if pixels else ("hint",)
    env = envs.make(name, ENV_DEFAULTS[name].get("hint", envs.NO_HINT), observe, physics=physics)
    if options:  # the same env with other physics options (--model-option)
        env = type(env).with_options(**options)(env.hint, observe, env.physics.impl)
    env = env if reset == "none" else envs.AutoReset(env)
    params = envs.make_params(name)
    ts = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(
        jax.random.split(jax.random.key(0), num_envs), params
    )

    @jax.jit
    def roll(state, key):
        def step(state, key, starts):
            k_act, k_env = jax.random.split(key)
            action = jax.random.uniform(k_act, (num_envs, env.action_size), minval=-1, maxval=1)
            fresh = () if starts is None else (starts,)
            out = jax.vmap(env.step, in_axes=(0, 0, 0, None, *(0,) * len(fresh)))(
                jax.random.split(k_env, num_envs), state, action, params, *fresh
            )
            seen = out.obs["pixels"][:, 32, 32, 0].sum() if pixels else out.obs["hint"].sum()
            return out.state, seen + out.reward.sum()

        if reset != "rollout":
            return jax.lax.scan(lambda s, k: step(s, k, None), state, jax.random.split(key, steps))

        def chunk(state, key):
            k_starts, k_steps = jax.random.split(key)
            starts = jax.vmap(env.fresh_start, in_axes=(0, None))(
                jax.random.split(k_starts, num_envs), params
            )
            return jax.lax.scan(
                lambda s, k: step(s, k, starts), state, jax.random.split(k_steps, rollout)
            )

        return jax.lax.scan(chunk, state, jax.random.split(key, steps // rollout))

    seconds = best_time(roll, ts.state, jax.random.key(1))
    done = steps if reset != "rollout" else steps // rollout * rollout
    return {
        "env": name,
        "pixels": pixels,
        "reset": reset,
        "num_envs": num_envs,
        "steps": done,
        "physics": envs.resolve_physics(name, physics),
        "env_steps_per_s": num_envs * done / seconds,
    }


def bench_ceiling(batch: int) -> dict:
    cfg = run_config({"env": "pendulum", "agent": "hints", "scheme": "fc", "hint": "composite"})
    env = cfg.make_env()
    network = make_network(cfg, env)
    k = jax.random.key(0)
    obs = {
        "pixels": jax.random.randint(k, (batch, 64, 64, 3), 0, 255).astype(jnp.uint8),
        "hint": jax.random.normal(k, (batch, env.hint.dim)),
    }
    params = network.init(k, jax.tree.map(lambda x: x[:1], obs))
    tx = make_optimizer(Hyper.of(cfg), params, cfg.ppo)
    opt_state = tx.init(params)
    action = jax.random.normal(k, (batch, 1))

    def loss(p):
        mean, log_std, value = network.apply(p, obs)
        return -gaussian_log_prob(action, mean, log_std).mean() + (value**2).mean()

    @jax.jit
    def update(p, s):
        grads = jax.grad(loss)(p)
        updates, s = tx.update(grads, s, p)
        return optax.apply_updates(p, updates), s

    seconds = best_time(update, params, opt_state, repeats=10)
    return {"batch": batch, "update_samples_per_s": batch / seconds}


def bench_train(
    name: str,
    seeds: int,
    updates: int,
    overrides: dict,
    agent: str = "hints",
    physics: str = envs.AUTO,
) -> dict:
    """Training rate of the env's default cell (hints/fc with its default hint), two ways:
    `env_steps_per_s` through pipeline.train, the function `python -m hintsjax.run` calls (chunks,
    checkpoints, logs; compile apart), and `scan_env_steps_per_s`, the same compiled chunks called
    back to back with nothing else on the host (no logs, no checkpoints), best of two; and the
    seconds of one update's parts."""
    import tempfile

    from hintsjax.training import compilation, pipeline

    values = {
        "env": name,
        "agent": agent,
        "scheme": "fc",
        "seeds": seeds,
        "checkpoint_every": min(10, updates),
        "physics": physics,
        "ppo": overrides,
    }
    cfg = run_config(values)
    cfg = run_config(
        {**values, "ppo": {**overrides, "total_env_steps": updates * cfg.ppo.batch_size}}
    )
    with tempfile.TemporaryDirectory() as folder:
        results = pipeline.train(cfg, Path(folder), progress=False)
    compiled = compilation.compile_training(
        make_trainer(cfg), cfg.seed_keys(), cfg.checkpoint_every
    )
    state = compiled.init(cfg.seed_keys())

    def back_to_back(state):
        for _ in range(updates // compiled.chunk):
            state, metrics = compiled.run_chunk(state, np.int32(compiled.chunk))
        return metrics["env_steps"]

    seconds = best_time(back_to_back, state, repeats=2)
    updates = updates // compiled.chunk * compiled.chunk
    env_steps = seeds * updates * cfg.ppo.batch_size
    return {
        "env": name,
        "agent": agent,
        "seeds": seeds,
        "updates": updates,
        # what `physics` (auto by default) resolved to, as the run's eval.json says
        "physics": results["physics"],
        "ppo": {
            k: getattr(cfg.ppo, k) for k in ("num_envs", "batch_size", "epochs", "minibatch_size")
        },
        "env_steps_per_s": results["train_env_steps_per_s"],
        "chunks_env_steps_per_s": results["chunks_env_steps_per_s"],
        "grad_samples_per_s": results["train_env_steps_per_s"] * cfg.ppo.epochs,
        "compile_s": results["compile_seconds"],
        "scan_env_steps_per_s": env_steps / seconds,
        "update_parts_s": update_parts(cfg, state)[0],
    }


# --rollout-starts: make_ppo's `ended_starts`
ROLLOUT_STARTS = {"run": None, "every_env": False, "ended": True}


def warmed(rollout, state, rollouts: int, seeds: int) -> tuple[object, float]:
    """`state` after `rollouts` of `rollout` (its untrained policy's, jitted and seed-vmapped; no
    learning), so that its envs' episodes are under way and some end in the next rollout, as in
    a run (a fresh state ends almost none); and the envs ended a step in the last of them
    (terminated or truncated, summed over seeds; NaN for no rollouts)."""
    traj = None
    for i in range(rollouts):
        state, traj, _ = rollout(
            state, jax.random.split(jax.random.fold_in(jax.random.key(2), i), seeds)
        )
    if traj is None:
        return state, float("nan")
    done = jnp.logical_or(traj.terminated, traj.truncated)  # [seeds, T, N]
    return state, float(done.sum()) / done.shape[1]


def update_parts(
    cfg, state, ended_starts: bool | None = None, warm_rollouts: int = 0
) -> tuple[dict, float]:
    """Seconds of one seed-vmapped PPO update's parts: the rollout (env steps with pictures and
    the policy's actions), the learning (GAE and the epochs of minibatch steps), the rollout's env
    steps under random actions as `bench_env` times them (with their pictures and every env's
    fresh start drawn each step, as vmapped AutoReset draws them; without pictures; without
    pictures or starts), and the policy's network once a step on the rollout's observations.
    So: physics is the last env steps' time, the starts' share the difference of the two before
    it, the pictures' (each step's and its fresh start's) the difference of the first two; and
    where the rollout draws every env's start too (`ended_starts` False, `--rollout-starts
    every_env`), the rollout less the first is the policy's (its action and its value of the
    final observation: two passes of the network a step, one of which `policy_forwards` times).
    A rollout that draws the ended envs' starts alone (`ended_starts` True; None: as a run
    draws them, make_ppo) saves some of the starts' share. Every part steps with the run's
    physics (`cfg.physics`). All from `state` after `warm_rollouts` rollouts (`warmed`); returned
    with the envs ended a step in the last of those."""
    from hintsjax.algorithms.ppo import make_ppo

    parts = make_ppo(cfg, ended_starts=ended_starts)
    key = jax.random.split(jax.random.key(1), cfg.seeds)
    rollout = jax.jit(jax.vmap(parts.rollout))
    state, ended = warmed(rollout, state, warm_rollouts, cfg.seeds)
    _, traj, last = rollout(state, key)
    learn = jax.jit(jax.vmap(parts.learn))
    network = parts.network

    def forwards(s, obs):  # one pass of the network on each of the rollout's [T, N] observations
        def one(total, o):
            mean, _, value = network.apply(s.params, o)[:3]
            return total + mean.sum() + value.sum(), None

        return jax.lax.scan(one, jnp.zeros(()), obs)[0]

    # every seed's envs side by side
    width, steps = cfg.seeds * cfg.ppo.num_envs, cfg.ppo.rollout_length

    def env_steps(**kw) -> float:  # the seconds of the rollout's env steps, as bench_env steps them
        rate = bench_env(cfg.env, width, steps, physics=cfg.physics, **kw)["env_steps_per_s"]
        return width * steps / rate

    seconds = {
        "rollout": best_time(lambda s, k: rollout(s, k)[2], state, key),
        "learn": best_time(lambda s: learn(s, traj, last, traj.reward, key)[1]["approx_kl"], state),
        "env_steps_with_pictures": env_steps(),
        "env_steps_only": env_steps(pixels=False),
        "env_steps_no_starts": env_steps(pixels=False, reset="none"),
        "policy_forwards": best_time(jax.jit(jax.vmap(forwards)), state, traj.obs),
    }
    return seconds, ended


def parts_row(cfg, args: argparse.Namespace, parts: dict, ended: float) -> dict:
    """--parts' record of one env (--out): its settings, the envs ended a step (null where no
    rollout ran first) and each part's milliseconds."""
    return {
        "env": cfg.env,
        "seeds": cfg.seeds,
        "num_envs": cfg.ppo.num_envs,
        "rollout_length": cfg.ppo.rollout_length,
        "physics": cfg.physics,
        "encoder_dtype": cfg.ppo.encoder_dtype,
        "deterministic_ops": xla_flags.deterministic_gpu_ops(),
        "rollout_starts": args.rollout_starts,
        "warm_rollouts": args.warm_rollouts,
        "ended_a_step": None if math.isnan(ended) else ended,
        "parts_ms": {k: 1e3 * v for k, v in parts.items()},
    }


def drops_determinism(names: list[str], physics: str) -> bool:
    """Whether the bench drops deterministic GPU ops: where every env steps with MuJoCo Warp, as
    the command does then (hintsjax/run.py; they cost the learner a third, docs/throughput.md)."""
    return all(envs.likely_warp(name, physics) for name in names)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--envs", default="pendulum", help=f"comma-separated subset of {envs.env_names()}"
    )
    parser.add_argument(
        "--sizes", default="4096,65536", help="comma-separated numbers of envs for the env rows"
    )
    parser.add_argument(
        "--steps", type=int, default=100, help="env steps per timed scan in the env rows"
    )
    parser.add_argument("--no-train", action="store_true", help="env rows only (no training rows)")
    parser.add_argument(
        "--reset-cost",
        action="store_true",
        help="add rows with starts drawn once per rollout of 8 steps, and without AutoReset",
    )
    parser.add_argument(
        "--default-train-only",
        action="store_true",
        help="one training row per env: 5 seeds at the env's default settings",
    )
    parser.add_argument(
        "--parts",
        action="store_true",
        help="only the milliseconds of one update's parts (rollout, learning, env steps alone "
        "without pictures) "
        "of each env's default cell at 5 seeds",
    )
    parser.add_argument(
        "--encoder-dtype",
        choices=ENCODER_DTYPES,
        default="float32",
        help="with --parts: the pixel encoder's arithmetic (ppo.encoder_dtype)",
    )
    parser.add_argument(
        "--rollout-starts",
        choices=tuple(ROLLOUT_STARTS),
        default="run",
        help="with --parts: the rollout's fresh starts as a run draws them "
        "(hintsjax.algorithms.ppo.batch_step), every env's each step, or the ended envs' alone",
    )
    parser.add_argument(
        "--warm-rollouts",
        type=int,
        default=0,
        help="with --parts: rollouts of the untrained policy first, so that episodes are under "
        "way and some end while the parts are timed (0: from fresh starts, where almost none end)",
    )
    parser.add_argument("--quick", action="store_true", help="small sizes (a CPU smoke run)")
    parser.add_argument(
        "--model-option",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="env rows of MJX envs: override an mj_model.opt field, e.g. integrator=EULER or "
        "iterations=1 (repeatable); the registered envs keep their own",
    )
    parser.add_argument(
        "--physics", default=envs.AUTO, help="auto, jax or warp: what steps the MJX envs"
    )
    parser.add_argument("--out", default=None, help="write the results as JSON here")
    args = parser.parse_args()
    names = [n.strip() for n in args.envs.split(",") if n.strip()]
    unknown = [n for n in names if n not in envs.REGISTRY]
    if unknown:
        parser.exit(
            2, f"error: unknown env {unknown}; valid choices: {', '.join(envs.env_names())}\n"
        )
    try:
        options = model_options(args.model_option)
    except ValueError as e:
        parser.exit(2, f"error: {e}\n")
    mjx_envs = envs.mjx_env_names()
    if drops_determinism(names, args.physics):  # said before JAX's backend starts
        xla_flags.drop_determinism()
    try:
        for name in names:
            envs.resolve_physics(name, args.physics)
    except (envs.ChoiceError, envs.PhysicsUnavailable) as e:
        parser.exit(2, f"error: {e}\n")
    if options and not set(names) <= set(mjx_envs):
        parser.exit(2, f"error: --model-option applies to MJX envs only: {', '.join(mjx_envs)}\n")
    if args.warm_rollouts < 0:
        parser.exit(2, f"error: --warm-rollouts must be 0 or more, got {args.warm_rollouts}\n")
    q = args.quick
    if args.parts:
        rows = []
        for name in names:
            cfg = run_config(
                {
                    "env": name,
                    "agent": "hints",
                    "scheme": "fc",
                    "seeds": 5,
                    "physics": args.physics,
                    "ppo": {"encoder_dtype": args.encoder_dtype},
                }
            )
            state = jax.jit(jax.vmap(make_trainer(cfg).init))(cfg.seed_keys())
            starts = ROLLOUT_STARTS[args.rollout_starts]
            parts, ended = update_parts(cfg, state, starts, args.warm_rollouts)
            print(
                f"update  {name:>9} 5 seeds {cfg.ppo.num_envs} envs x "
                f"{cfg.ppo.rollout_length} steps, {cfg.physics}, {args.encoder_dtype} encoder, "
                f"deterministic ops {'on' if xla_flags.deterministic_gpu_ops() else 'off'}, "
                f"starts {args.rollout_starts}, after {args.warm_rollouts} rollouts "
                f"({ended:.1f} envs ended a step): "
                + ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in parts.items()),
                flush=True,
            )
            rows.append(parts_row(cfg, args, parts, ended))
        if args.out:
            device = str(jax.devices()[0].device_kind)
            with open(args.out, "w") as f:
                json.dump({"device": device, "jax": jax.__version__, "parts": rows}, f, indent=1)
        return
    # as the command line: a second bench compiles little
    compilation_cache.enable(compilation_cache.folder(True))
    results = {
        "device": str(jax.devices()[0].device_kind),
        "platform": jax.default_backend(),
        "jax": jax.__version__,
        "python": platform.python_version(),
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
    }
    results["ceiling"] = bench_ceiling(8192 if not q else 64)
    ceiling = results["ceiling"]["update_samples_per_s"]
    print(
        f"ceiling batch {results['ceiling']['batch']}: {ceiling:,.0f} samples/s (fwd+bwd+Adam)",
        flush=True,
    )
    results["env"], results["train"] = [], []
    for name in names:
        for n in [int(n) for n in args.sizes.split(",")] if not q else (64,):
            size = envs.make(name).image_size
            for pixels, reset in (
                (False, "step"),
                (True, "step"),
                *(((True, "rollout"), (True, "none")) if args.reset_cost else ()),
            ):
                r = bench_env(
                    name,
                    n,
                    args.steps if not q else 16,
                    pixels,
                    reset,
                    options=options,
                    physics=args.physics,
                )
                r["model_options"] = args.model_option
                results["env"].append(r)
                what = (
                    f"with {size}x{size} picture" if pixels else "physics, reward, hint"
                ) + "".join(f"; {o}" for o in args.model_option)
                print(
                    f"env     {name:>9} {n:>6} envs: {r['env_steps_per_s']:>14,.0f} env steps/s "
                    f"({what}; {RESETS[reset]}; {r['physics']})",
                    flush=True,
                )
        settings = (
            (
                (5, {}),
                (5, {"num_envs": 64}),
                (32, {}),
                (32, {"num_envs": 64, "minibatch_size": 1024}),
            )
            if not q
            else ((2, {"num_envs": 4, "batch_size": 64, "minibatch_size": 32, "epochs": 1}),)
        )
        settings = settings[:1] if args.default_train_only else settings
        for seeds, overrides in settings if not args.no_train else ():
            r = bench_train(name, seeds, 40 if not q else 2, overrides, physics=args.physics)
            r["fraction_of_ceiling"] = r["grad_samples_per_s"] / ceiling
            results["train"].append(r)
            print(
                f"train   {name:>9} {seeds:>3} seeds {r['ppo']}: "
                f"{r['env_steps_per_s']:,.0f} env steps/s "
                f"through pipeline.train (bare scan {r['scan_env_steps_per_s']:,.0f}), "
                f"{r['grad_samples_per_s']:,.0f} grad samples/s = "
                f"{r['fraction_of_ceiling']:.0%} of ceiling; "
                f"compile {r['compile_s']['train']:.1f} s; one update: "
                + ", ".join(f"{k} {1e3 * v:.1f} ms" for k, v in r["update_parts_s"].items()),
                flush=True,
            )
    if args.out:
        with open(args.out, "w") as f:
            json.dump(results, f, indent=1)


if __name__ == "__main__":
    main()
