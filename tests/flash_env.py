"""A test-only two-step task whose right action can be read only off the previous picture.

At reset a cue c in {-1, +1} is drawn uniformly and the first picture shows it (white for +1,
black for -1); the second picture is grey whatever c is, and the state observation is [0.0]
throughout. The first action earns nothing; the second earns -(a - c)^2, a clipped to [-2, 2];
the episode is truncated after it. An agent that sees one picture at a time is blind to c when
it matters, so its best is the constant a = 0 (expected return -1); one that sees the last two
(`frames=2`, envs/frames.py) can reach 0.

Importing this module registers the env (`envs.REGISTRY["flash"]`), so `run_config({"env":
"flash", ...})` works.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from cue_env import CueParams  # the same action limit
from hintsjax import envs
from hintsjax.envs.core import Env, Step

NAME = "flash"
GREY = 128


@struct.dataclass
class FlashState:
    cue: jax.Array  # float32, -1 or +1
    t: jax.Array


class FlashEnv(Env):
    name = NAME
    max_steps = 2
    action_size = 1
    image_size = 36  # the encoder's smallest

    def default_params(self) -> CueParams:
        return CueParams()

    def initial_state(self, key: jax.Array, params: CueParams) -> FlashState:
        cue = jnp.where(jax.random.bernoulli(key), 1.0, -1.0).astype(jnp.float32)
        return FlashState(cue=cue, t=jnp.zeros((), jnp.int32))

    def transition(self, key, state: FlashState, action, params: CueParams) -> Step:
        a = jnp.clip(jnp.reshape(action, ()), -params.action_limit, params.action_limit)
        reward = jnp.where(state.t == 1, -((a - state.cue) ** 2), 0.0)
        return Step(state, reward, jnp.zeros((), bool))

    def render(self, state: FlashState, params: CueParams) -> jax.Array:
        shown = jnp.where(state.cue > 0, 255, 0).astype(jnp.uint8)
        level = jnp.where(state.t == 0, shown, jnp.uint8(GREY))
        return jnp.full((self.image_size, self.image_size, 3), level, jnp.uint8)

    def state_obs(self, state: FlashState, params: CueParams) -> jax.Array:
        return jnp.zeros((1,), jnp.float32)


envs.REGISTRY[NAME] = envs.EnvEntry(FlashEnv, {"default": CueParams()}, training=dict(hint="none"))
