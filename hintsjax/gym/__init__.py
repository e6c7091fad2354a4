"""hintsjax.gym: hintsjax's envs as Gymnasium 1.x envs, for learners outside hintsjax (docs/gym.md).

    import gymnasium, hintsjax.gym
    envs = gymnasium.make_vec(
        "hintsjax/pendulum-v0", num_envs=64, hint="composite", variant="swingup"
    )
    env = gymnasium.make("hintsjax/pendulum-v0")        # one env, for gymnasium.utils.env_checker

Importing it registers `hintsjax/<env>-v0` for every env of the suite and every Brax env
(`hintsjax/brax.hopper-v0`); Playground's tasks, whose import takes seconds, are registered by
`import hintsjax.gym.playground` (or its Gymnasium prefix: `gymnasium.make_vec(
"hintsjax.gym.playground:hintsjax/playground.CartpoleSwingup-v0", ...)`), and an env of your own
by `register("mine")`. `hintsjax.gym.sb3` makes a vector env a Stable-Baselines3 VecEnv.

Owns: the Gymnasium envs (core.py), their ids; imports hintsjax.envs and Gymnasium (`gym` extra).
"""

from __future__ import annotations

import gymnasium

from hintsjax import envs
from hintsjax.envs import brax_env
from hintsjax.gym.core import SingleEnv, VectorEnv, default_hint, seed_key

NAMESPACE = "hintsjax"


def env_id(name: str) -> str:
    """The Gymnasium id of hintsjax env `name`: `hintsjax/<name>-v0`, a source's colon a dot
    (`brax:hopper` -> `hintsjax/brax.hopper-v0`), since Gymnasium reads a colon as a module
    prefix."""
    return f"{NAMESPACE}/{name.replace(':', '.')}-v0"


def register(name: str) -> str:
    """Register hintsjax env `name` (a suite env, `<source>:<task>` or one added to
    hintsjax.envs.REGISTRY) with Gymnasium: its single env for `gymnasium.make`, its vector env
    for `gymnasium.make_vec`. Its id. The env itself is made (and checked) at `make`."""
    gid = env_id(name)
    gymnasium.register(
        gid,
        entry_point=SingleEnv,
        vector_entry_point=VectorEnv,
        kwargs={"env": name},
        disable_env_checker=False,
    )
    return gid


def register_all(names: list[str]) -> list[str]:
    """`register` each of `names`; their ids."""
    return [register(name) for name in names]


SUITE_IDS = register_all(envs.env_names())
BRAX_IDS = register_all([f"{brax_env.SOURCE}:{name}" for name in brax_env.names()])

__all__ = [
    "BRAX_IDS",
    "NAMESPACE",
    "SUITE_IDS",
    "SingleEnv",
    "VectorEnv",
    "default_hint",
    "env_id",
    "register",
    "register_all",
    "seed_key",
]
