"""Can physics=warp train with deterministic GPU ops off? The user's command, minus its refusal.

    python experiments/warp_det_off.py [--env ant] [--updates 100] [--eval-compile beside|first]
                                       [--out F]

Run under `XLA_FLAGS=--xla_gpu_deterministic_ops=false` (hintsjax then adds its persisted
autotune folder beside $HINTSJAX_COMPILATION_CACHE: give each trial an empty one). It trains the
env's HINTS-FC cell (its default hint) with physics=warp for `--updates` updates through
`run.main_from_values`, the command's own path, with `compilation.check_warp_run`'s refusal of this
flag set lifted, and the evaluation program compiled beside training (as before this script) or
first (`pipeline.evaluation_compiles_first`, what the command does now: done before training,
since issue 82 beside the training program's compile, without autotuning). It prints one JSON
row: the exit status, the training rate and compile seconds from eval.json, and the tail of what
went wrong.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import tempfile
from pathlib import Path


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--env", default="ant")
    parser.add_argument("--updates", type=int, default=100)
    parser.add_argument("--eval-compile", choices=("beside", "first"), default="first")
    parser.add_argument(
        "--out", type=Path, default=None, help="append the row to this JSON-lines file"
    )
    args = parser.parse_args()

    import jax

    import hintsjax
    from hintsjax.settings.layers import run_config
    from hintsjax.training import compilation, pipeline
    from hintsjax import run

    compilation.check_warp_run = lambda: None  # the refusal under test
    pipeline.evaluation_compiles_first = lambda cfg: args.eval_compile == "first"
    steps = args.updates * run_config({"env": args.env, "physics": "warp"}).ppo.batch_size
    with tempfile.TemporaryDirectory() as out:
        values = {
            "env": args.env,
            "agent": "hints",
            "scheme": "fc",
            "physics": "warp",
            "checkpoint_every": 50,
            "ppo": {"total_env_steps": steps},
            "out_dir": out,
            "name": "trial",
        }
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            try:
                status = run.main_from_values(values)
            except Exception as e:  # noqa: BLE001  what failed is the result
                status, _ = -1, print(f"{type(e).__name__}: {e}", file=err)
        result = Path(out, "trial", "eval.json")
        row = {
            "env": args.env,
            "updates": args.updates,
            "eval_compile": args.eval_compile,
            "status": status,
            "deterministic_ops": hintsjax.deterministic_gpu_ops(),
            "device": jax.devices()[0].device_kind,
        }
        if result.exists():
            found = json.loads(result.read_text())
            row.update(
                env_steps_per_s=round(found["train_env_steps_per_s"]),
                train_s=round(found["train_seconds"], 1),
                compile_s={k: round(v, 1) for k, v in found["compile_seconds"].items()},
                return_mean=round(found["evaluations"][0]["mean"], 1),
            )
        row["error_tail"] = err.getvalue()[-600:] if status else ""
    print(json.dumps(row), flush=True)
    if args.out:
        with args.out.open("a") as f:
            f.write(json.dumps(row) + "\n")


if __name__ == "__main__":
    main()
