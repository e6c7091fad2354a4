"""A test-only one-step task whose right action can be read only from the hint.

At reset a cue c in {-1, +1} is drawn uniformly; the picture is a constant grey image and the
state observation is [0.0], so neither reveals c. The hint `cue` is [c]. The episode is one
step long (truncated at t = 1) with reward -(a - c)^2, a clipped to [-2, 2]. (A second hint,
`cue_pair` = [c, -c], gives tests/test_group.py hints of several widths; a third, `distractor`, is
noise: a number drawn uniformly in [-1, 1] at reset, independent of c, for tests/test_rank.py.) The
best an agent blind to the hint can do is the constant action a = 0, whose expected return is -1; an
agent that reads the hint can reach 0.

Importing this module registers the env with its defaults in one call (`envs.REGISTRY["cue"]`)
and its hint, so `run_config({"env": "cue", ...})` works.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax import envs
from hintsjax.envs.core import Env, Step
from hintsjax.envs.hints import register_hint

NAME = "cue"
GREY = 128


@struct.dataclass
class CueParams:
    action_limit: float = 2.0


@struct.dataclass
class CueState:
    cue: jax.Array  # float32, -1 or +1
    t: jax.Array
    distractor: jax.Array  # float32 in [-1, 1], independent of the cue


class CueEnv(Env):
    name = NAME
    max_steps = 1
    action_size = 1
    image_size = 36  # the smallest the encoder's 8/4, 4/2, 3/1 VALID convolutions accept

    def default_params(self) -> CueParams:
        return CueParams()

    def initial_state(self, key: jax.Array, params: CueParams) -> CueState:
        cue = jnp.where(jax.random.bernoulli(key), 1.0, -1.0).astype(jnp.float32)
        # the cue's draw unchanged
        distractor = jax.random.uniform(jax.random.fold_in(key, 1), (), jnp.float32, -1.0, 1.0)
        return CueState(cue=cue, t=jnp.zeros((), jnp.int32), distractor=distractor)

    def transition(self, key, state: CueState, action, params: CueParams) -> Step:
        a = jnp.clip(jnp.reshape(action, ()), -params.action_limit, params.action_limit)
        return Step(state, -((a - state.cue) ** 2), jnp.zeros((), bool))

    def render(self, state: CueState, params: CueParams) -> jax.Array:
        return jnp.full((self.image_size, self.image_size, 3), GREY, jnp.uint8)

    def state_obs(self, state: CueState, params: CueParams) -> jax.Array:
        return jnp.zeros((1,), jnp.float32)


@register_hint(NAME, "cue", dim=1, unit="1")
def cue(state: CueState, params: CueParams) -> jax.Array:
    """The episode's cue c in {-1, +1}: the right action."""
    return state.cue[None]


@register_hint(NAME, "cue_pair", dim=2, unit="1")
def cue_pair(state: CueState, params: CueParams) -> jax.Array:
    """[c, -c]: the cue twice (a second hint of another width, for the group tests)."""
    return jnp.stack([state.cue, -state.cue])


@register_hint(NAME, "distractor", dim=1, unit="1")
def distractor(state: CueState, params: CueParams) -> jax.Array:
    """Noise: a number drawn at reset, independent of the cue."""
    return state.distractor[None]


envs.REGISTRY[NAME] = envs.EnvEntry(
    CueEnv, {"default": CueParams()}, training=dict(hint="cue", ppo=dict(actor_lr=1e-3))
)
