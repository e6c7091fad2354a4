"""The ray caster alone: how long an env's pictures take at a batch, and where the time goes.

    python experiments/bench_render.py [--envs ant] [--sizes 1280,5120] [--physics auto]

For each env and batch: its states (reset, then a few random steps, so poses differ), then three
programs timed on them, each `jax.vmap`ped over the batch and jitted alone (envs/render3d.py):
`nearest`, the search for each pixel's nearest hit over every drawn geom (the key's min chain);
`cast`, that and the winner's normal and hit point; `render`, the env's picture as training draws
it (shading and the uint8 bytes too). Printed a row each: milliseconds a batch, pictures a second,
and ray-geom tests a second (pixels x drawn geoms over the time of `nearest`), the figure to set
against the GPU's arithmetic. Issue 82's pictures lever is measured with it.
"""

from __future__ import annotations

import argparse

import jax

from hintsjax import envs
from hintsjax.settings.env_defaults import ENV_DEFAULTS

from bench import best_time
from hintsjax.envs import render3d

WARMUP_STEPS = 8  # random steps from the resets before the pictures are drawn


def states(env, params, count: int):
    """`count` states of `env` after WARMUP_STEPS random steps from their resets."""
    keys = jax.random.split(jax.random.key(0), count)
    ts = jax.jit(jax.vmap(env.reset, in_axes=(0, None)))(keys, params)
    step = jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))
    state = ts.state
    for i in range(WARMUP_STEPS):
        k_act, k_env = jax.random.split(jax.random.fold_in(jax.random.key(1), i))
        action = jax.random.uniform(k_act, (count, env.action_size), minval=-1, maxval=1)
        state = step(jax.random.split(k_env, count), state, action, params).state
    return state


def rows(name: str, sizes: list[int], physics: str) -> None:
    env = envs.make(
        name, ENV_DEFAULTS[name].get("hint", envs.NO_HINT), ("pixels",), physics=physics
    )
    params = envs.make_params(name)
    if not hasattr(env, "render_camera"):
        raise SystemExit(f"error: {name} does not draw with render3d (its own picture code)")
    scene, size = env.scene, env.image_size

    def nearest(s):
        return render3d.depth(scene, s.geom_xpos, s.geom_xmat, env.render_camera(s), size)

    def cast(s):
        return render3d.cast(scene, s.geom_xpos, s.geom_xmat, env.render_camera(s), size).normal

    programs = {
        "nearest": nearest,
        "cast": cast,
        "render": lambda s: env.render(s, params),
    }
    for count in sizes:
        state = states(env, params, count)
        seconds = {}
        for part, fn in programs.items():
            seconds[part] = best_time(jax.jit(jax.vmap(fn)), state, repeats=10)
        tests = count * size * size * len(scene.geom) / seconds["nearest"]
        print(
            f"{name:>9} {count:6d} pictures {size}x{size}, {len(scene.geom)} geoms: "
            + ", ".join(f"{part} {1e3 * t:.2f} ms" for part, t in seconds.items())
            + f"; {count / seconds['render']:,.0f} pictures/s, "
            + f"{tests / 1e9:.1f} G ray-geom tests/s",
            flush=True,
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default="ant", help="comma-separated envs drawn by render3d")
    parser.add_argument("--sizes", default="1280,5120", help="comma-separated batch sizes")
    parser.add_argument("--physics", default=envs.AUTO)
    args = parser.parse_args()
    print(f"device: {jax.devices()[0].device_kind}", flush=True)
    for name in args.envs.split(","):
        rows(name, [int(n) for n in args.sizes.split(",")], args.physics)


if __name__ == "__main__":
    main()
