"""Where one training chunk of a cell spends its GPU time: a kernel table from JAX's profiler.

    python experiments/profile_update.py [--env pendulum] [--seeds 5] [--updates 10] [--top 25]
                                         [--variants base,nodet,...] [--physics auto|jax|warp]
                                         [--out DIR]
                                         [--part update|learn] [--ppo num_envs=1024,...]

For each variant (a fresh process, since XLA_FLAGS are read at start-up) it compiles the cell's
chunk program (`compilation.compile_training`, what `python -m hintsjax.run` runs), times
`--updates` updates back to back (best of 3), then records one chunk under `jax.profiler.trace` and
sums the GPU kernels' time by name: the device's busy fraction (the union of kernel intervals over
the chunk's wall time) says whether the chunk is bound by the GPU's work or by launching it.

`--part learn` profiles the learner alone: one seed-vmapped `learn` (GAE and the epochs of
minibatch steps) on one rollout's transitions, `--updates` times, with the kernels of one call
sorted into kinds (the encoder's patch copies, matrix products, the optimiser's and the loss's
elementwise fusions) by their names.
"""

from __future__ import annotations

import argparse
import gzip
import json
import os
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from hintsjax.reproduce import flag_variants

# name -> (extra XLA flags, {scan length: unroll}); a variant runs in its own process with its
# flags appended, and its scans of those lengths unrolled (the pendulum's rollout and GAE scan 64
# steps, an epoch 4 minibatches, an update 8 epochs)
VARIANTS = {
    "base": ("", {}),
    "nodet": ("--xla_gpu_deterministic_ops=false", {}),
    "cmdbuf": (
        "--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL",
        {},
    ),
    "nocmdbuf": ("--xla_gpu_enable_command_buffer=", {}),
    # deterministic without --xla_gpu_deterministic_ops: no non-deterministic ops (scatter's
    # atomics), kernels chosen without autotuning (the same in every process) or with it
    "excl_at0": (
        "--xla_gpu_deterministic_ops=false --xla_gpu_exclude_nondeterministic_ops=true "
        "--xla_gpu_autotune_level=0",
        {},
    ),
    "excl": ("--xla_gpu_deterministic_ops=false --xla_gpu_exclude_nondeterministic_ops=true", {}),
    "at0": ("--xla_gpu_deterministic_ops=false --xla_gpu_autotune_level=0", {}),
    "excl_at0_unroll_learn": (
        "--xla_gpu_deterministic_ops=false --xla_gpu_exclude_nondeterministic_ops=true "
        "--xla_gpu_autotune_level=0",
        {4: 4},
    ),
    # XLA's sort-and-prefix-scan rewrite of scatters that deterministic ops would otherwise turn
    # into while loops of one update per iteration (MJX's scatter-adds)
    "scatter_det": ("--xla_gpu_enable_scatter_determinism_expander=true", {}),
    # deterministic ops off, autotuning persisted (XLA's docs/determinism.md: compilation is
    # deterministic once autotuning is read from a cache): the first process tunes and writes the
    # folder, later ones read it; `tuned_b` starts another folder
    "tuned": (
        "--xla_gpu_deterministic_ops=false "
        "--xla_gpu_per_fusion_autotune_cache_dir=/tmp/hintsjax_autotune_a",
        {},
    ),
    "tuned_b": (
        "--xla_gpu_deterministic_ops=false "
        "--xla_gpu_per_fusion_autotune_cache_dir=/tmp/hintsjax_autotune_b",
        {},
    ),
    "tuned_scatter": (
        "--xla_gpu_deterministic_ops=false --xla_gpu_enable_scatter_determinism_expander=true "
        "--xla_gpu_per_fusion_autotune_cache_dir=/tmp/hintsjax_autotune_a",
        {},
    ),
    # physics=warp runs with deterministic ops off (MuJoCo Warp's atomics are not reproducible
    # anyway): its baseline is `nodet`; this adds CUDA graphs over the update's while loops and
    # conditionals
    "nodet_cmdbuf": (
        "--xla_gpu_deterministic_ops=false "
        "--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL",
        {},
    ),
    "nodet_unroll_learn": ("--xla_gpu_deterministic_ops=false", {4: 4}),
    "unroll_rollout": ("", {64: 8}),
    "unroll_learn": ("", {4: 4}),
    "unroll_both": ("", {64: 8, 4: 4}),
}


def unroll_scans(unroll: dict[int, int]) -> None:
    """Make every later `jax.lax.scan` of a length in `unroll` unroll that many steps."""
    import jax

    scan = jax.lax.scan

    def patched(f, init, xs=None, length=None, **kw):
        n = length if length is not None else jax.tree.leaves(xs)[0].shape[0]
        return scan(f, init, xs, length, **{**kw, "unroll": unroll.get(n, kw.get("unroll", 1))})

    jax.lax.scan = patched


def kernel_table(trace_dir: Path, top: int) -> dict:
    """Sum the GPU events of the newest perfetto trace under trace_dir by name."""
    path = max(trace_dir.rglob("*.trace.json.gz"), key=os.path.getmtime)
    events = json.loads(gzip.open(path).read())["traceEvents"]
    gpu_pids = {
        e["pid"]
        for e in events
        if e.get("ph") == "M"
        and e.get("name") == "process_name"
        and "/device:GPU" in str(e.get("args", {}).get("name", ""))
    }
    kernels = [e for e in events if e.get("ph") == "X" and e.get("pid") in gpu_pids and "dur" in e]
    if not kernels:
        return {"note": "no GPU events in the trace"}
    by_name: dict[str, list[float]] = defaultdict(lambda: [0.0, 0])
    for e in kernels:
        by_name[e["name"]][0] += e["dur"]
        by_name[e["name"]][1] += 1
    intervals = sorted((e["ts"], e["ts"] + e["dur"]) for e in kernels)
    busy, end = 0.0, intervals[0][0]
    for a, b in intervals:
        if b > end:
            busy += b - max(a, end)
            end = b
    span = intervals[-1][1] - intervals[0][0]
    rows = [
        {"name": n[:120], "ms": t / 1e3, "count": c}
        for n, (t, c) in sorted(by_name.items(), key=lambda kv: -kv[1][0])
    ]
    return {
        "span_ms": span / 1e3,
        "busy_ms": busy / 1e3,
        "busy_fraction": busy / span,
        "events": len(kernels),
        "top": rows[:top],
        "kinds": kinds(rows),
    }


def kinds(rows: list[dict]) -> dict:
    """The kernel table's rows' time summed by kind of kernel (a guess from XLA's and Warp's
    names)."""
    out: dict[str, list[float]] = defaultdict(lambda: [0.0, 0])
    for row in rows:
        name = row["name"]
        kind = (
            "physics (Warp)"
            if "cuda_kernel_forward" in name
            else "patch copies (concatenate)"
            if "concatenate" in name
            else "matrix products"
            if any(
                k in name for k in ("gemm", "cutlass", "cublas", "dot", "sm90", "xmma", "ampere")
            )
            else "reductions"
            if "reduce" in name
            else "copies and transposes"
            if any(k in name for k in ("transpose", "copy", "memcpy", "memset"))
            else "other fusions"
        )
        out[kind][0] += row["ms"]
        out[kind][1] += row["count"]
    return {
        k: {"ms": v[0], "count": v[1]} for k, v in sorted(out.items(), key=lambda kv: -kv[1][0])
    }


def ppo_overrides(text: str) -> dict:
    """'num_envs=1024,encoder=brax_vision' -> {'num_envs': 1024, 'encoder': 'brax_vision'}, each
    value typed as the run command types it (Hydra's grammar)."""
    from hintsjax.cli.overrides import parse

    return {o.key_or_group: o.value() for o in parse(list(filter(None, text.split(","))))}


def one_learn(args: argparse.Namespace, cfg) -> dict:
    """The learner alone: `learn` on one rollout's transitions, vmapped over seeds."""
    import jax

    from hintsjax.algorithms.ppo import make_ppo

    parts = make_ppo(cfg)
    keys = cfg.seed_keys()
    state = jax.jit(jax.vmap(parts.init))(keys)
    state, traj, last = jax.jit(jax.vmap(parts.rollout))(state, keys)
    learn = jax.jit(jax.vmap(parts.learn))
    t = time.perf_counter()
    compiled = learn.lower(state, traj, last, traj.reward, keys).compile()
    compile_s = time.perf_counter() - t
    after, _ = jax.block_until_ready(compiled(state, traj, last, traj.reward, keys))
    digest = flag_variants.params_digest(after.params)
    times = []
    for _ in range(args.updates):
        t = time.perf_counter()
        jax.block_until_ready(compiled(state, traj, last, traj.reward, keys))
        times.append(time.perf_counter() - t)
    with tempfile.TemporaryDirectory() as folder:
        with jax.profiler.trace(folder, create_perfetto_trace=True):
            jax.block_until_ready(compiled(state, traj, last, traj.reward, keys))
        table = kernel_table(Path(folder), args.top)
    ppo = cfg.ppo
    steps = ppo.epochs * ppo.num_minibatches
    return {
        "variant": args.variant,
        "part": "learn",
        "env": cfg.env,
        "seeds": cfg.seeds,
        "ppo": {
            k: getattr(ppo, k)
            for k in ("num_envs", "rollout_length", "batch_size", "epochs", "minibatch_size")
        },
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "device": jax.devices()[0].device_kind,
        "compile_s": compile_s,
        "digest": digest,
        "learn_ms": 1e3 * min(times),
        "gradient_steps": steps,
        "ms_per_gradient_step": 1e3 * min(times) / steps,
        "samples_per_s": cfg.seeds * ppo.batch_size * ppo.epochs / min(times),
        "kernels": table,
    }


def one(args: argparse.Namespace) -> dict:
    import jax
    import numpy as np

    from hintsjax.settings.layers import run_config
    from hintsjax.algorithms.registry import make_trainer
    from hintsjax.training import compilation

    unroll_scans(VARIANTS[args.variant][1])
    for flag in os.environ.get("XLA_FLAGS", "").split():  # XLA wants the autotune folder made
        if flag.startswith("--xla_gpu_per_fusion_autotune_cache_dir="):
            Path(flag.split("=", 1)[1]).mkdir(parents=True, exist_ok=True)
    cfg = run_config(
        {
            "env": args.env,
            "agent": "hints",
            "scheme": "fc",
            "seeds": args.seeds,
            "checkpoint_every": args.updates,
            "physics": args.physics,
            "ppo": ppo_overrides(args.ppo),
        }
    )
    if args.part == "learn":
        return one_learn(args, cfg)
    keys = cfg.seed_keys()
    compiled = compilation.compile_training(make_trainer(cfg), keys, args.updates)
    state = compiled.init(keys)
    n = np.int32(args.updates)
    state, _ = jax.block_until_ready(compiled.run_chunk(state, n))
    # the params after one chunk from the seeds' start: equal digests from two processes mean
    # the variant's compiled program is reproducible
    digest = flag_variants.params_digest(state.params)
    times = []
    for _ in range(3):
        t = time.perf_counter()
        state, _ = jax.block_until_ready(compiled.run_chunk(state, n))
        times.append(time.perf_counter() - t)
    with tempfile.TemporaryDirectory() as folder:
        with jax.profiler.trace(folder, create_perfetto_trace=True):
            state, _ = jax.block_until_ready(compiled.run_chunk(state, n))
        table = kernel_table(Path(folder), args.top)
    per_update = min(times) / args.updates
    return {
        "variant": args.variant,
        "physics": cfg.physics,
        "unroll": VARIANTS[args.variant][1],
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "device": jax.devices()[0].device_kind,
        "compile_s": compiled.seconds,
        "digest": digest,
        "update_ms": 1e3 * per_update,
        "env_steps_per_s": cfg.seeds * cfg.ppo.batch_size / per_update,
        "kernels": table,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="pendulum")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--updates", type=int, default=10)
    parser.add_argument("--top", type=int, default=25)
    parser.add_argument(
        "--physics",
        default="auto",
        choices=("auto", "jax", "warp"),
        help="MJCF envs' physics (default: auto)",
    )
    parser.add_argument(
        "--variants",
        default="base,nodet",
        help=f"comma-separated of {', '.join(VARIANTS)} (one twice: is it reproducible?)",
    )
    # set in the child process
    parser.add_argument("--variant", default=None, help=argparse.SUPPRESS)
    parser.add_argument(
        "--out", default=None, help="write every variant's result as JSON into this folder"
    )
    parser.add_argument(
        "--part",
        default="update",
        choices=("update", "learn"),
        help="profile a whole chunk of updates, or the learner alone (default: update)",
    )
    parser.add_argument(
        "--ppo", default="", help="PPO settings over the env's, e.g. num_envs=1024,epochs=4"
    )
    args = parser.parse_args()
    if args.variant is not None:
        flag_variants.report(one(args))
        return
    results = []
    for name in flag_variants.chosen(parser, args.variants, VARIANTS):
        r = flag_variants.run(
            __file__,
            VARIANTS[name][0],
            [
                "--variant",
                name,
                "--env",
                args.env,
                "--seeds",
                str(args.seeds),
                "--updates",
                str(args.updates),
                "--top",
                str(args.top),
                "--physics",
                args.physics,
                "--part",
                args.part,
                "--ppo",
                args.ppo,
            ],
        )
        if r is None:
            continue
        results.append(r)
        k = r["kernels"]
        rate = (
            f"{r['update_ms']:.1f} ms/update = {r['env_steps_per_s']:,.0f} env steps/s"
            if args.part == "update"
            else f"learn {r['learn_ms']:.1f} ms = {r['gradient_steps']} steps of "
            f"{r['ms_per_gradient_step']:.2f} ms, {r['samples_per_s']:,.0f} samples/s"
        )
        print(
            f"\n== {name} ({r['xla_flags']}): {rate}, "
            f"compile {r['compile_s']:.1f} s, params digest {r['digest']}; "
            f"GPU busy {k.get('busy_ms', 0):.1f} of {k.get('span_ms', 0):.1f} ms "
            f"({k.get('busy_fraction', 0):.0%}), {k.get('events', 0)} kernels",
            flush=True,
        )
        for kind, v in k.get("kinds", {}).items():
            print(f"  {v['ms']:9.2f} ms {v['count']:7d}x  [{kind}]")
        for row in k.get("top", []):
            print(f"  {row['ms']:9.2f} ms {row['count']:7d}x  {row['name']}")
    if args.out:
        Path(args.out).mkdir(parents=True, exist_ok=True)
        (Path(args.out) / f"profile_{args.part}_{args.env}_{args.physics}.json").write_text(
            json.dumps(results, indent=1)
        )


if __name__ == "__main__":
    main()
