"""What every training algorithm builds: a `Trainer` of pure functions over one run's state.

`init(key)` builds the state, `update(state)` advances it by one update and returns that
update's metrics; `run(state, n)` is `n` updates in one `lax.scan` and `train(key)` the whole run;
`run_chunk(state, n, length)` is one compiled program for every chunk of a chunked run (the first
`n` of `length` updates happen, `n` a traced number), so a shorter last chunk does not compile
again. All are pure, so `jax.jit(jax.vmap(trainer.train))(keys)` trains many seeds at once, and
chunking `run` between checkpoints gives the same result as one call. The state is any pytree with a
`params` field (the policy's ActorCritic parameters, which evaluation uses) and an `update`
counter; its metrics include `episode_return` and `env_steps`, which the run log plots.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp

from hintsjax.envs import WARP
from hintsjax.settings.config import RunConfig
from hintsjax.settings.hint_sources import PROGRAMMATIC


@dataclass(frozen=True)
class Trainer:
    """The pure functions of one configuration's training run."""

    cfg: RunConfig
    env: Any  # AutoReset(Env)
    network: Any  # the policy's ActorCritic
    init: Callable[[jax.Array], Any]
    update: Callable[[Any], tuple[Any, dict[str, jax.Array]]]
    # What the programs depend on besides code and their arguments' shapes (`program_identity`),
    # the key of the traced-program cache (hintsjax/system/program_cache.py); None: never cached
    identity: str | None = None

    def run(self, state: Any, num_updates: int) -> tuple[Any, dict[str, jax.Array]]:
        """Advance `num_updates` updates; metrics are [num_updates]-stacked."""
        return jax.lax.scan(lambda s, _: self.update(s), state, None, length=num_updates)

    def run_chunk(
        self, state: Any, count: jax.Array, length: int
    ) -> tuple[Any, dict[str, jax.Array]]:
        """The first `count` of `length` updates (`count` may be traced); metrics are
        [length]-stacked, those after `count` filled with NaN (0 for integer metrics) and the state
        left as it was."""
        # traced once: its shapes below and the branch reuse the trace
        update = jax.jit(self.update)
        shapes = jax.eval_shape(lambda s: update(s)[1], state)
        blank = jax.tree.map(
            lambda x: jnp.full(
                x.shape, jnp.nan if jnp.issubdtype(x.dtype, jnp.floating) else 0, x.dtype
            ),
            shapes,
        )

        def body(s, i):
            # Under vmap over seeds `count` and `i` stay unbatched, so this is a real branch: a
            # skipped update costs nothing.
            return jax.lax.cond(i < count, update, lambda s: (s, blank), s)

        return jax.lax.scan(body, state, jnp.arange(length))

    def train(self, key: jax.Array) -> tuple[Any, dict[str, jax.Array]]:
        """The whole run from a seed key: the function that is vmapped over seeds."""
        return self.run(self.init(key), self.cfg.ppo.num_updates)

    def abstract_state(self) -> Any:
        """The shapes and types of the run's seed-batched state ([S, ...] for cfg's seeds), computed
        without any arrays: what a checkpoint of the run restores into
        (hintsjax.system.checkpoint)."""
        return jax.eval_shape(
            jax.vmap(self.init), jax.random.split(jax.random.key(0), self.cfg.seeds)
        )


def program_identity(cfg: RunConfig, *more: Any) -> str | None:
    """The description of a run's programs that the traced-program cache keys them by: its
    configuration (and `more`, e.g. a group's members), or None where the programs close over
    files that no configuration value digests (an imitation agent's expert, a learned hint
    generator), which are then traced every time; and None for MJX-Warp physics, whose programs
    call Warp's kernels through handlers that the tracing process registers."""
    if cfg.agent_spec.imitates or {cfg.hint_source_for(False), cfg.hint_source_for(True)} != {
        PROGRAMMATIC
    }:
        return None
    if cfg.physics == WARP:
        return None
    return repr((cfg, *more))


def episode_metrics(done: jax.Array, episode_return: jax.Array) -> dict[str, jax.Array]:
    """Mean return of the episodes that ended in a rollout (NaN if none) and how many ended.

    done, episode_return: [T, N]; episode_return is valid where done (AutoReset's info).
    """
    episodes = done.sum()
    mean = (episode_return * done).sum() / jnp.maximum(episodes, 1)
    return {"episode_return": jnp.where(episodes > 0, mean, jnp.nan), "episodes": episodes}
