"""PPO's learning rates scaled by the KL of its steps (`ppo.kl_adaptive_lr`): the adaptive schedule
of rsl_rl's PPO (legged_gym, Isaac Lab), shrink-only. Before each minibatch step the update's
approx. KL from the rollout policy is read; above TOO_FAR x target_kl (the KL stop's bound) the
rates are divided by STEP, below TOO_CLOSE x target_kl they are multiplied by it, never above the
configured rates nor below MIN_SCALE of them. The scale is kept in the optimiser's state, so it
carries from one update to the next: an update's first step, which no KL stop can stop (it meets the
rollout policy itself), is taken at the rate the last update ended with
(experiments/results/locomotion_ppo_stability.md).
"""

from __future__ import annotations

from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import optax

STEP = 1.5  # rsl_rl's factor
# the KL early stop's bound, x ppo.target_kl (ppo.py: no step once a minibatch's KL is past it)
STOP = 1.5
# rsl_rl's band around the desired KL (here ppo.target_kl) is 2 and 0.5; the upper edge here is
# the stop's, so every step the stop ends also shrinks the rate
TOO_FAR, TOO_CLOSE = STOP, 0.5
# rsl_rl keeps its rate in [1e-5, 1e-2] around 1e-3; the floor here is the same ratio
MIN_SCALE = 0.01


class KLRateState(NamedTuple):
    scale: jax.Array  # float32 scalar: the factor on every learning rate


def scale_by_kl_rate() -> optax.GradientTransformation:
    """Multiplies the (Adam) updates by the state's scale, which `adapt` sets; last in the chain,
    it scales every part's learning rate alike."""

    def init(params: Any) -> KLRateState:
        del params
        return KLRateState(jnp.ones((), jnp.float32))

    def update(updates: Any, state: KLRateState, params: Any = None) -> tuple[Any, KLRateState]:
        del params
        return jax.tree.map(lambda u: u * state.scale.astype(u.dtype), updates), state

    return optax.GradientTransformation(init, update)


def adapted(scale: jax.Array, kl: jax.Array, target: jax.Array) -> jax.Array:
    """The next scale after a step whose approx. KL is `kl` (NaN or inf: too far)."""
    too_far = ~(kl <= TOO_FAR * target)
    too_close = kl < TOO_CLOSE * target
    scale = jnp.where(too_far, scale / STEP, jnp.where(too_close, scale * STEP, scale))
    return jnp.clip(scale, MIN_SCALE, 1.0)


def _is_state(x: Any) -> bool:
    return isinstance(x, KLRateState)


def adapt(opt_state: Any, kl: jax.Array, target: jax.Array) -> Any:
    """`opt_state` with its KLRateState adapted to `kl`."""
    return jax.tree.map(
        lambda s: KLRateState(adapted(s.scale, kl, target)) if _is_state(s) else s,
        opt_state,
        is_leaf=_is_state,
    )


def scale_of(opt_state: Any) -> jax.Array:
    """The scale in `opt_state` (the optimiser must hold one KLRateState)."""
    (state,) = [s for s in jax.tree.leaves(opt_state, is_leaf=_is_state) if _is_state(s)]
    return state.scale
