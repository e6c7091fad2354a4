"""What every training algorithm builds: a `Trainer` of pure functions over one run's state.

`init(key)` builds the state, `update(state)` advances it by one update and returns that
update's metrics; `run(state, n)` is `n` updates in one `lax.scan` and `train(key)` the whole run.
All are pure, so `jax.jit(jax.vmap(trainer.train))(keys)` trains many seeds at once, and chunking
`run` between checkpoints gives the same result as one call. The state is any pytree with a
`params` field (the policy's ActorCritic parameters, which evaluation uses) and an `update`
counter; its metrics include `episode_return` and `env_steps`, which the run log plots.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp

from hintsjax.config import RunConfig


@dataclass(frozen=True)
class Trainer:
    """The pure functions of one configuration's training run."""

    cfg: RunConfig
    env: Any  # AutoReset(Env)
    network: Any  # the policy's ActorCritic
    init: Callable[[jax.Array], Any]
    update: Callable[[Any], tuple[Any, dict[str, jax.Array]]]

    def run(self, state: Any, num_updates: int) -> tuple[Any, dict[str, jax.Array]]:
        """Advance `num_updates` updates; metrics are [num_updates]-stacked."""
        return jax.lax.scan(lambda s, _: self.update(s), state, None, length=num_updates)

    def train(self, key: jax.Array) -> tuple[Any, dict[str, jax.Array]]:
        """The whole run from a seed key: the function that is vmapped over seeds."""
        return self.run(self.init(key), self.cfg.ppo.num_updates)


def episode_metrics(done: jax.Array, episode_return: jax.Array) -> dict[str, jax.Array]:
    """Mean return of the episodes that ended in a rollout (NaN if none) and how many ended.

    done, episode_return: [T, N]; episode_return is valid where done (AutoReset's info).
    """
    episodes = done.sum()
    mean = (episode_return * done).sum() / jnp.maximum(episodes, 1)
    return {"episode_return": jnp.where(episodes > 0, mean, jnp.nan), "episodes": episodes}
