"""A hint file as a user writes one (tests/envs/test_adapter.py, tests/data/bad_inputs.yaml):
`hints_from=tests/data/hints/cartpole_hints.py hint=cart_position`."""

import jax.numpy as jnp

from hintsjax.envs import register_hint

ENV = "playground:CartpoleSwingup"


@register_hint(ENV, "cart_position", dim=1, unit="m")
def cart_position(state, params):
    """The cart's position along its rail."""
    return state.data.qpos[0]


@register_hint(ENV, "tip_height", dim=1, unit="m")
def tip_height(state, params):
    """The pole's cosine: 1 upright, -1 hanging."""
    return jnp.cos(state.data.qpos[1])


@register_hint(ENV, "two_for_one", dim=1, unit="m")
def two_for_one(state, params):
    """Registered with dim 1, returns 2 numbers: a wrong shape."""
    return state.data.qpos[:2]
