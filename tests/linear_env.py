"""A test-only linear system with a known linear expert, for the imitation agents.

The state s in R^2 starts uniform in [-1, 1]^2 and moves as s' = clip(0.9 s + 0.1 [a, -a], -2, 2)
for an action a in R (unclipped); the reward is -|s'|^2 and episodes are truncated after
`max_steps` = 16 steps (or terminated, for `LinearParams(terminate_at > 0)`, once |s'| < that).
`EXPERT` is the linear policy a = K s with known gains K = (-1, 0.5); it is what the imitation
agents are given instead of a trained expert, so their students should reproduce a = K s.

Importing this module registers the env (`envs.REGISTRY["linear"]`) and its defaults.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax import envs
from hintsjax.envs.core import Env, Step

NAME = "linear"
GAINS = (-1.0, 0.5)


@struct.dataclass
class LinearParams:
    terminate_at: float = 0.0  # radius under which an episode ends (0: never)


@struct.dataclass
class LinearState:
    s: jax.Array  # [2]
    t: jax.Array


class LinearEnv(Env):
    name = NAME
    max_steps = 16
    action_size = 1
    image_size = 36

    def default_params(self) -> LinearParams:
        return LinearParams()

    def initial_state(self, key: jax.Array, params: LinearParams) -> LinearState:
        return LinearState(
            jax.random.uniform(key, (2,), minval=-1.0, maxval=1.0), jnp.zeros((), jnp.int32)
        )

    def transition(self, key, state: LinearState, action, params: LinearParams) -> Step:
        a = jnp.reshape(action, ())
        s = jnp.clip(0.9 * state.s + 0.1 * jnp.stack([a, -a]), -2.0, 2.0)
        radius = jnp.sqrt(jnp.sum(s**2))
        return Step(state.replace(s=s), -jnp.sum(s**2), radius < params.terminate_at)

    def render(self, state: LinearState, params: LinearParams) -> jax.Array:
        return jnp.zeros((self.image_size, self.image_size, 3), jnp.uint8)

    def state_obs(self, state: LinearState, params: LinearParams) -> jax.Array:
        return state.s.astype(jnp.float32)


@struct.dataclass
class LinearExpert:
    """a = K s, with a Gaussian of std exp(log_std) around it for `sample`."""

    gains: jax.Array  # [2]
    log_std: jax.Array  # [1]

    def mean(self, state: jax.Array) -> jax.Array:
        return (state @ self.gains)[..., None]

    def sample(self, key: jax.Array, state: jax.Array) -> jax.Array:
        mean = self.mean(state)
        return mean + jnp.exp(self.log_std) * jax.random.normal(key, mean.shape)


EXPERT = LinearExpert(jnp.asarray(GAINS, jnp.float32), jnp.asarray([-2.0], jnp.float32))

envs.REGISTRY[NAME] = envs.EnvEntry(
    LinearEnv,
    {"default": LinearParams(), "terminating": LinearParams(0.3)},
    training=dict(ppo=dict(hidden=(32, 32))),
)
