"""A test-only task whose hint is an exact, learnable function of the picture.

A dot's position p in [-1, 1] is drawn uniformly at reset and moves by 0.25 tanh(a) a step; the
picture is black with a soft white vertical bar whose centre is at column 2 + (p + 1) / 2 * 31
(its brightness falls off linearly over 2 columns, so the picture changes smoothly with p). The
hint `position` is [p]: a generator that reads one picture can recover it exactly. Reward -p^2,
episodes of 8 steps.

Importing this module registers the env (`envs.REGISTRY["dot"]`), its hint and its defaults.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax import envs
from hintsjax.envs.core import Env, Step
from hintsjax.envs.hints import register_hint

NAME = "dot"


@struct.dataclass
class DotParams:
    speed: float = 0.25


@struct.dataclass
class DotState:
    position: jax.Array  # float32 in [-1, 1]
    t: jax.Array


class DotEnv(Env):
    name = NAME
    max_steps = 8
    action_size = 1
    image_size = 36  # the smallest the encoder's 8/4, 4/2, 3/1 VALID convolutions accept

    def default_params(self) -> DotParams:
        return DotParams()

    def initial_state(self, key: jax.Array, params: DotParams) -> DotState:
        return DotState(
            jax.random.uniform(key, (), jnp.float32, -1.0, 1.0), jnp.zeros((), jnp.int32)
        )

    def transition(self, key, state: DotState, action, params: DotParams) -> Step:
        position = jnp.clip(
            state.position + params.speed * jnp.tanh(jnp.reshape(action, ())), -1.0, 1.0
        )
        return Step(state.replace(position=position), -(position**2), jnp.zeros((), bool))

    def render(self, state: DotState, params: DotParams) -> jax.Array:
        centre = 2.0 + (state.position + 1.0) / 2.0 * 31.0
        column = jnp.clip(1.0 - jnp.abs(jnp.arange(self.image_size) - centre) / 2.0, 0.0, 1.0)
        row = jnp.round(255 * column).astype(jnp.uint8)
        return jnp.broadcast_to(row[None, :, None], (self.image_size, self.image_size, 3))

    def state_obs(self, state: DotState, params: DotParams) -> jax.Array:
        return state.position[None]


@register_hint(NAME, "position", dim=1, unit="1")
def position(state: DotState, params: DotParams) -> jax.Array:
    """The dot's position in [-1, 1]."""
    return state.position[None]


envs.REGISTRY[NAME] = envs.EnvEntry(
    DotEnv, {"default": DotParams()}, training=dict(hint="position", ppo=dict(actor_lr=1e-3))
)
