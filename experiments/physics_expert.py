"""Do MJX-Warp and MJX-JAX give a fixed policy the same task? The packaged experts in closed loop.

    python experiments/physics_expert.py [--envs ant halfcheetah humanoid] [--episodes 32]
                                         [--out experiments/results/physics_expert.json]

Learning on Warp scored below learning on JAX on the ant (experiments/results/physics_learning.md).
A learning curve mixes the physics with everything else; a fixed policy does not. Each env's
packaged expert (hintsjax/experts, a state-based policy, acting with its mean) runs `--episodes`
full episodes from the same starts (the same reset keys) under each physics, and the script
reports per physics the mean return with its 95 % bootstrap CI, the episodes that ended in a
fall (termination), and the difference warp - jax with its 95 % bootstrap CI (the episodes
resampled independently: past a hundred steps the same start no longer pairs them), beside the
same difference for jax against itself from starts 1e-6 apart.

It also measures how far the two physics drift apart along the expert's own trajectory, against
the chaos of the task itself: the largest |qpos| gap between warp and jax from the same start at
steps 1, 10 and 100, beside the gap between jax and jax from starts 1e-6 apart (qvel nudged).
A physics whose gap is of the chaos' size is as good as a perturbation of the start.

Runs on any platform with warp-lang installed (Warp's CPU path is slow: minutes per env).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np

from hintsjax import envs
from hintsjax.algorithms.experts import load
from hintsjax.reproduce import stats

HERE = Path(__file__).resolve().parent
OUT = HERE / "results" / "physics_expert.json"
GAP_STEPS = (1, 10, 100)
ABOUT = (
    "Each env's packaged expert (mean actions) for `episodes` full episodes from the same starts "
    "under physics=jax and physics=warp: mean return [95 % bootstrap CI], falls, warp - jax "
    "[95 % CI, episodes resampled independently]; jax_nudged_1e-6: the jax run again from starts "
    "with qvel + 1e-6 (the task's own chaos); qpos_gap_median: median over episodes of max "
    "|qpos| gap at steps 1, 10, 100."
)


def rollout(env, expert):
    """A jitted function of (keys, nudge): episodes from the starts drawn with `keys` (qvel +
    `nudge`), expert mean actions, to the time limit: returns, lengths, whether each fell, and
    qpos at GAP_STEPS."""
    params = env.default_params()

    def episode(key, nudge):
        first = env.reset(key, params)
        state = first.state.replace(qvel=first.state.qvel + nudge)
        first = first.replace(state=state, obs=env.observation(state, params))

        def step(carry, _):
            ts, total, length, fell, alive = carry
            nxt = env.step(key, ts.state, expert.mean(ts.obs["state"]), params)
            total = total + jnp.where(alive, nxt.reward, 0.0)
            length = length + alive
            fell = fell | (alive & nxt.terminated)
            return (
                nxt,
                total,
                length,
                fell,
                alive & ~nxt.terminated & ~nxt.truncated,
            ), nxt.state.qpos

        zero = jnp.zeros((), jnp.float32)
        carry = (first, zero, jnp.zeros((), jnp.int32), jnp.zeros((), bool), jnp.ones((), bool))
        (_, total, length, fell, _), qpos = jax.lax.scan(step, carry, None, env.max_steps)
        return total, length, fell, qpos[jnp.array(GAP_STEPS) - 1]

    return jax.jit(jax.vmap(episode, in_axes=(0, None)))


def compare(name: str, episodes: int) -> dict:
    expert = load(name)
    keys = jax.random.split(jax.random.key(2026), episodes)
    out, runs = {}, {}
    for physics in ("jax", "warp"):
        runs[physics] = rollout(envs.make(name, "none", ("state",), physics=physics), expert)
        start = time.perf_counter()
        total, length, fell, qpos = jax.block_until_ready(runs[physics](keys, 0.0))
        out[physics] = dict(
            returns=np.asarray(total),
            lengths=np.asarray(length),
            fell=np.asarray(fell),
            qpos=np.asarray(qpos),
            seconds=time.perf_counter() - start,
        )
    nudged_returns, _, nudged_fell, nudged = map(np.asarray, runs["jax"](keys, 1e-6))
    jx, wp = out["jax"], out["warp"]
    diff = stats.difference_ci(wp["returns"], jx["returns"])
    gap = lambda a, b: np.max(np.abs(a - b), axis=-1)  # noqa: E731  [episodes, steps]
    row = {"env": name, "episodes": episodes, "max_steps": int(envs.make(name).max_steps)}
    for physics, r in out.items():
        ci = stats.bootstrap_ci(r["returns"], np.mean)
        row[physics] = {
            "mean_return": float(ci.point),
            "ci": [float(ci.low), float(ci.high)],
            "std": float(r["returns"].std()),
            "falls": int(r["fell"].sum()),
            "mean_length": float(r["lengths"].mean()),
            "seconds": round(r["seconds"], 1),
        }
    row["warp_minus_jax"] = {
        "mean": float(diff.point),
        "ci": [float(diff.low), float(diff.high)],
        "decided": bool(stats.difference_decided(diff)),
    }
    # the same physics, starts 1e-6 apart
    chaos = stats.difference_ci(nudged_returns, jx["returns"])
    row["jax_nudged_1e-6"] = {
        "mean_return": float(nudged_returns.mean()),
        "falls": int(nudged_fell.sum()),
        "minus_jax": {"mean": float(chaos.point), "ci": [float(chaos.low), float(chaos.high)]},
    }
    row["qpos_gap_median"] = {
        f"step_{s}": {
            "warp_vs_jax": float(np.median(gap(wp["qpos"], jx["qpos"])[:, i])),
            "jax_nudged_1e-6": float(np.median(gap(nudged, jx["qpos"])[:, i])),
        }
        for i, s in enumerate(GAP_STEPS)
    }
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", nargs="+", default=["ant", "halfcheetah", "humanoid"])
    parser.add_argument("--episodes", type=int, default=32)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args()
    # rows by env: a rerun replaces its envs' rows and keeps the others; written after each env
    rows = (
        {r["env"]: r for r in json.loads(args.out.read_text())["rows"]} if args.out.exists() else {}
    )
    for name in args.envs:
        row = compare(name, args.episodes)
        row.update(
            device=jax.devices()[0].device_kind,
            jax_version=jax.__version__,
            command=f"python experiments/physics_expert.py --envs {name} "
            f"--episodes {args.episodes}",
        )
        rows[name] = row
        print(json.dumps(row), flush=True)
        args.out.write_text(
            json.dumps({"about": ABOUT, "rows": list(rows.values())}, indent=1) + "\n"
        )


if __name__ == "__main__":
    main()
