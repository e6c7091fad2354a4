"""PPO's arithmetic, each piece checkable by hand, and the records it reads.

The diagonal Gaussian policy's log density, sample and entropy (and its squashed action's),
generalised advantage estimation and the clipped surrogate loss are free functions on arrays
(shapes in their docstrings), each tested alone against values worked out by hand
(tests/test_ppo_math.py). A rollout is stacked into a `Transition` (what GAE reads) and flattened
into `Batch`es (what the loss reads); hintsjax.algorithms.ppo joins them into PPO's update.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct


@struct.dataclass
class Transition:
    """One rollout step of every env; arrays are [T, N, ...] once stacked by the scan."""

    obs: dict[str, jax.Array]
    action: jax.Array
    log_prob: jax.Array
    value: jax.Array
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    final_value: jax.Array  # value of the pre-reset observation; used where truncated
    episode_return: jax.Array  # return of the episode that ended here (valid where done)


@struct.dataclass
class Batch:
    """Flattened training samples [M, ...] with their advantage and value target."""

    obs: dict[str, jax.Array]
    action: jax.Array
    log_prob: jax.Array
    advantage: jax.Array
    target: jax.Array


def gaussian_log_prob(action: jax.Array, mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """Log density of a diagonal Gaussian, summed over the last axis: [..., A] -> [...]."""
    z = (action - mean) * jnp.exp(-log_std)
    return jnp.sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi), axis=-1)


def gaussian_sample(key: jax.Array, mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """An action drawn from the diagonal Gaussian policy: mean + std * N(0, 1), [..., A]."""
    return mean + jnp.exp(log_std) * jax.random.normal(key, mean.shape)


def gaussian_entropy(log_std: jax.Array) -> jax.Array:
    """Entropy of a diagonal Gaussian: [A] -> []."""
    return jnp.sum(log_std + 0.5 * (1.0 + jnp.log(2 * jnp.pi)), axis=-1)


# Gauss-Hermite nodes and weights for E[f(x)], x ~ N(0, 1) (probabilists' Hermite polynomials)
_NODES, _WEIGHTS = np.polynomial.hermite_e.hermegauss(32)
_WEIGHTS = _WEIGHTS / _WEIGHTS.sum()


def squashed_entropy(mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """Entropy of tanh(u), u ~ N(mean, exp(log_std)) per dimension, summed: [..., A], [A] or
    [..., A] -> [...]. The Gaussian's entropy plus E[log(1 - tanh(u)^2)] (the squash's log
    Jacobian), the expectation by 32-node Gauss-Hermite quadrature (within 0.002 of the integral
    for stds up to e, 1 % of it beyond): deterministic, smooth in mean and log_std, and bounded
    above by A log 2 (the uniform on [-1, 1]^A), where the Gaussian's grows with the std without
    bound. Brax's tanh-squashed policies estimate the same from one draw."""
    u = mean[..., None] + jnp.exp(log_std)[..., None] * jnp.asarray(_NODES, jnp.float32)
    # log(1 - tanh(u)^2) = 2 (log 2 - u - softplus(-2u)), stable for large |u|
    log_det = 2.0 * (jnp.log(2.0) - u - jax.nn.softplus(-2.0 * u))
    expected = jnp.sum(log_det * jnp.asarray(_WEIGHTS, jnp.float32), axis=-1)
    return jnp.sum(log_std + 0.5 * (1.0 + jnp.log(2 * jnp.pi)) + expected, axis=-1)


def gae(
    reward: jax.Array,
    value: jax.Array,
    terminated: jax.Array,
    truncated: jax.Array,
    final_value: jax.Array,
    last_value: jax.Array,
    gamma: float,
    lam: float,
    segment: int = 0,
    bootstrap_truncated: bool = True,
) -> tuple[jax.Array, jax.Array]:
    """Generalised advantage estimates and value targets, both [T, N].

    reward, value, terminated, truncated, final_value: [T, N]; last_value: [N], the value of
    the observation after the last step. The step after t is the next row unless an episode
    ended at t: then the bootstrap is final_value[t] if it was truncated and 0 if terminated,
    and no advantage flows back across the boundary. With `segment` L > 0 (static, dividing T)
    the rollout is cut into runs of L steps, as Brax's unrolls: the last step of each is
    bootstrapped from the next row's value and no advantage flows back across the cut. Without
    `bootstrap_truncated` (Brax's bootstrap_on_timeout off) a truncated step's advantage is 0 and
    its target its own value: the critic learns nothing there (the actor only what the
    minibatch's normalisation makes of a 0, as in Brax).
    """
    next_value = jnp.concatenate([value[1:], last_value[None]], axis=0)
    next_value = jnp.where(truncated, final_value, next_value)
    next_value = jnp.where(terminated, 0.0, next_value)
    delta = reward + gamma * next_value - value
    if not bootstrap_truncated:
        delta = jnp.where(truncated, 0.0, delta)
    carry_on = 1.0 - (terminated | truncated).astype(jnp.float32)
    if segment:
        cut = (jnp.arange(reward.shape[0]) % segment == segment - 1)[:, None]
        carry_on = jnp.where(cut, 0.0, carry_on)

    def back(acc, x):
        d, c = x
        acc = d + gamma * lam * c * acc
        return acc, acc

    _, advantage = jax.lax.scan(back, jnp.zeros_like(last_value), (delta, carry_on), reverse=True)
    return advantage, advantage + value


def clipped_surrogate_loss(
    log_prob: jax.Array,
    old_log_prob: jax.Array,
    advantage: jax.Array,
    value: jax.Array,
    target: jax.Array,
    entropy: jax.Array,
    clip_eps: float,
    vf_coef: float,
    ent_coef: float,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """PPO's loss (paper eq. 5, with the entropy bonus subtracted so it is maximised).

    log_prob, old_log_prob, advantage, value, target: [M]; entropy: []. Advantages are used
    as given (normalise before calling). Returns the scalar loss and its parts.
    """
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    clipped = jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps)
    policy_loss = -jnp.mean(jnp.minimum(ratio * advantage, clipped * advantage))
    value_loss = jnp.mean((value - target) ** 2)
    loss = policy_loss + vf_coef * value_loss - ent_coef * entropy
    parts = {
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy": entropy,
        # not ln(ratio): inf, not NaN, on overflow
        "approx_kl": jnp.mean((ratio - 1.0) - log_ratio),
        "clip_fraction": jnp.mean((jnp.abs(ratio - 1.0) > clip_eps).astype(jnp.float32)),
    }
    return loss, parts
