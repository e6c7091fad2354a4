"""Where the compile of one cell's training programs goes, cold and warm, under XLA flag variants.

    python experiments/compile_time.py [--env ant] [--variants base,threads16] [--warm] [--out FILE]

Each variant runs in its own process (XLA_FLAGS are read at start-up) with its own empty
compilation cache; with `--warm` a second process then compiles again from the cache the first
filled, as a second run of `python -m hintsjax.run` would. A process compiles the cell's init and
chunk programs through `compilation.compile_training` (what the command runs, the traced-program
cache included), splits the seconds by JAX's monitoring events (tracing, lowering to MLIR, XLA's
backend compile, reading the persistent cache), then runs one chunk of `--updates` updates and
digests the params: equal digests mean a flag left the program's numbers alone.
"""

from __future__ import annotations

import argparse
import json
import os
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from hintsjax.reproduce import flag_variants

# name -> XLA flags appended to the defaults (deterministic ops stay on in every variant)
VARIANTS = {
    "base": "",
    # XLA compiles the program's parts on 16 threads (jax 0.11.2's XLA no longer knows
    # --xla_gpu_enable_llvm_module_compilation_parallelism: a process given it stops at start-up)
    "threads16": "--xla_gpu_force_compilation_parallelism=16",
    "autotune0": "--xla_gpu_autotune_level=0",
}


def one(args: argparse.Namespace) -> dict:
    import jax
    import numpy as np

    from hintsjax.system import compilation_cache
    from hintsjax.settings.env_defaults import ENV_DEFAULTS
    from hintsjax.settings.layers import run_config
    from hintsjax.algorithms.registry import make_trainer
    from hintsjax.training import compilation

    seconds: dict[str, float] = defaultdict(float)
    jax.monitoring.register_event_duration_secs_listener(
        lambda event, s, **_: seconds.__setitem__(event, seconds[event] + s)
    )
    compilation_cache.enable(args.cache)
    cfg = run_config(
        {
            "env": args.env,
            "agent": "hints",
            "scheme": "fc",
            "hint": ENV_DEFAULTS[args.env]["hint"],
            "checkpoint_every": args.updates,
        }
    )
    keys = cfg.seed_keys()
    t = time.perf_counter()
    compiled = compilation.compile_training(make_trainer(cfg), keys, args.updates)
    total = time.perf_counter() - t
    state = compiled.init(keys)
    state, _ = jax.block_until_ready(compiled.run_chunk(state, np.int32(args.updates)))
    digest = flag_variants.params_digest(state.params)
    short = {k.rsplit("/", 1)[-1]: round(v, 2) for k, v in seconds.items()}
    return {
        "variant": args.variant,
        "warm": args.warm,
        "xla_flags": os.environ.get("XLA_FLAGS", ""),
        "device": jax.devices()[0].device_kind,
        "jax": jax.__version__,
        "compile_s": round(total, 2),
        "trace_s": round(compiled.trace_seconds, 2),
        "loaded_traced": compiled.loaded,
        "events_s": short,
        "digest": digest,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="ant")
    parser.add_argument("--updates", type=int, default=2)
    parser.add_argument("--variants", default="base,threads16")
    parser.add_argument(
        "--warm", action="store_true", help="compile each variant a second time from its cache"
    )
    # set in the child process
    parser.add_argument("--variant", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--cache", default=None, help=argparse.SUPPRESS)
    parser.add_argument("--out", default=None, help="write the rows as JSON here")
    args = parser.parse_args()
    if args.variant is not None:
        flag_variants.report(one(args))
        return
    rows = []
    for name in flag_variants.chosen(parser, args.variants, VARIANTS):
        with tempfile.TemporaryDirectory() as cache:
            for warm in [False, True] if args.warm else [False]:
                row = flag_variants.run(
                    __file__,
                    VARIANTS[name],
                    [
                        "--variant",
                        name,
                        "--env",
                        args.env,
                        "--updates",
                        str(args.updates),
                        "--cache",
                        cache,
                    ]
                    + (["--warm"] if warm else []),
                )
                if row is None:
                    break
                rows.append(row)
                print(json.dumps(row), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
