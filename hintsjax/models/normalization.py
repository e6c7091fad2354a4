"""Running normalisation of the state vector (ppo.normalize_state), as Brax's and
Stable-Baselines3's observation normalisers do.

The statistics (mean, variance, count over every state seen in training) live in the network's
variables beside its parameters, in the collection "obs_stats", so checkpoints, evaluation,
videos and exported experts carry them without extra plumbing. `StateNorm` reads them in the
forward pass (no gradient flows into them); `update` merges a batch of states into them after
each update (Chan et al.'s parallel variance), so a rollout and the learning on it see the same
statistics. Before any update they are the identity (mean 0, variance 1).

Normalised states are clipped to +-CLIP; a dimension that never varies keeps 0.
"""

from __future__ import annotations

from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp

COLLECTION = "obs_stats"
NAME = "state_norm"  # the StateNorm module's name inside ActorCritic
CLIP = 10.0
EPS = 1e-6  # added to the variance


class StateNorm(nn.Module):
    """[..., n] -> (x - mean) / sqrt(var + EPS), clipped to +-CLIP, with the running statistics."""

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        n = x.shape[-1]
        mean = self.variable(COLLECTION, "mean", jnp.zeros, (n,), jnp.float32).value
        var = self.variable(COLLECTION, "var", jnp.ones, (n,), jnp.float32).value
        self.variable(COLLECTION, "count", jnp.zeros, (), jnp.float32)
        return normalize(jax.lax.stop_gradient(mean), jax.lax.stop_gradient(var), x)


def normalize(mean: jax.Array, var: jax.Array, x: jax.Array) -> jax.Array:
    return jnp.clip((x - mean) / jnp.sqrt(var + EPS), -CLIP, CLIP)


def merge(stats: dict[str, jax.Array], batch: jax.Array) -> dict[str, jax.Array]:
    """The statistics of everything in `stats` and the rows of `batch` [M, n] together."""
    m = jnp.asarray(batch.shape[0], jnp.float32)
    batch_mean, batch_var = jnp.mean(batch, axis=0), jnp.var(batch, axis=0)
    count = stats["count"] + m
    delta = batch_mean - stats["mean"]
    mean = stats["mean"] + delta * m / count
    m2 = stats["var"] * stats["count"] + batch_var * m + delta**2 * stats["count"] * m / count
    return {"mean": mean, "var": m2 / count, "count": count}


def update(variables: Any, obs: dict[str, jax.Array]) -> Any:
    """`variables` with the states in obs["state"] [..., n] merged into their StateNorm's
    statistics; unchanged when the network does not normalise."""
    if COLLECTION not in variables or "state" not in obs:
        return variables
    states = obs["state"].reshape(-1, obs["state"].shape[-1])
    stats = variables[COLLECTION][NAME]
    return {**variables, COLLECTION: {**variables[COLLECTION], NAME: merge(stats, states)}}
