"""Data rollouts for the tools that learn from an env's pictures and hints (hintsjax.generator,
hintsjax.rank): N(0, 1) actions, the start of an untrained policy, with an optional expert (an
object with `mean(state)` and `log_std`, such as hintsjax.expert's) driving some of the envs."""

from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp

from hintsjax import envs


def observed(expert: Any) -> tuple[str, ...]:
    """The observation keys a rollout needs: pictures and hints, and the state an expert acts on."""
    return ("pixels", "hint", "state") if expert is not None else ("pixels", "hint")


def rollout(
    env: Any,
    params: Any,
    key: jax.Array,
    num_envs: int,
    steps: int,
    record: Callable[..., Any],
    expert: Any = None,
    driven: int = 0,
) -> Any:
    """`steps` steps of `num_envs` fresh episodes of an AutoReset env observing `observed(expert)`;
    the expert's sampled actions in the first `driven` envs, N(0, 1) in the others. Returns
    `record(state, obs, action, ts)` of every step (the state and observation the action was taken
    in, the Timestep it led to), stacked [steps, ...]."""
    k_reset, k_run = jax.random.split(key)
    ts = envs.fresh_episodes(k_reset, env, params, num_envs)
    by_expert = jnp.arange(num_envs) < driven

    def step(carry, key):
        state, obs = carry
        k_act, k_env = jax.random.split(key)
        action = jax.random.normal(k_act, (num_envs, env.action_size))
        if expert is not None:
            expert_action = jax.vmap(expert.mean)(obs["state"]) + jnp.exp(expert.log_std) * action
            action = jnp.where(by_expert[:, None], expert_action, action)
        ts = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
            jax.random.split(k_env, num_envs), state, action, params
        )
        return (ts.state, ts.obs), record(state, obs, action, ts)

    return jax.lax.scan(step, (ts.state, ts.obs), jax.random.split(k_run, steps))[1]
