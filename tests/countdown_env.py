"""A test-only task with episodes of known, unequal lengths: for checking where episodes end.

At reset a length L is drawn uniformly from 1..15; every step pays reward 1 whatever the action,
and the episode terminates on step L. The time limit is 10 steps, so episodes with L > 10 are
truncated there. An episode's return is therefore min(L, 10), and so is its length; an evaluator
that kept counting after an episode's end would report more. Its metric `steps_left` = L - t is
max(L - 10, 0) in the state an episode ends in, and keeps falling on steps past the end.

Importing this module registers the env (`envs.REGISTRY["countdown"]`) and its defaults.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax import envs
from hintsjax.envs.core import Env, Step

NAME = "countdown"
MAX_LENGTH = 15


@struct.dataclass
class CountdownState:
    length: jax.Array  # int32, the step on which the episode terminates
    t: jax.Array


class CountdownEnv(Env):
    name = NAME
    max_steps = 10
    action_size = 1
    image_size = 36

    def default_params(self) -> tuple:
        return ()

    def initial_state(self, key: jax.Array, params) -> CountdownState:
        length = jax.random.randint(key, (), 1, MAX_LENGTH + 1)
        return CountdownState(length=length, t=jnp.zeros((), jnp.int32))

    def transition(self, key, state: CountdownState, action, params) -> Step:
        return Step(state, jnp.ones(()), state.t + 1 >= state.length)

    def render(self, state: CountdownState, params) -> jax.Array:
        return jnp.zeros((self.image_size, self.image_size, 3), jnp.uint8)

    def state_obs(self, state: CountdownState, params) -> jax.Array:
        return state.t[None].astype(jnp.float32)

    def metrics(self, state: CountdownState, params) -> dict[str, jax.Array]:
        return {"steps_left": (state.length - state.t).astype(jnp.float32)}


envs.REGISTRY[NAME] = envs.EnvEntry(CountdownEnv, {"default": ()}, training=dict(hint="none"))
