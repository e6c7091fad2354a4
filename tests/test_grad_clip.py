"""Gradient clipping (ppo.max_grad_norm, ppo.grad_clip): with one global norm a large critic loss
shrinks the actor's step; clipped per part, the actor's step is its own.

Found beside Brax's PPO on CartpoleSwingup (issue 61; experiments/results/versus_brax_knobs.md):
with Brax's reward scale (10) and discount (0.995) the critic's gradient norm reached 100 to 3000
after one update, the global clip scaled every gradient by 1e-3 to 2e-4, and the actor's
gradients (1e-7 to 1e-5 per element) fell under Adam's epsilon (1e-5): its step shrank to a few
per cent of its learning rate's.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax.algorithms.ppo import Hyper, make_optimizer
from hintsjax.settings import layers
from hintsjax.system.errors import UsageError

PARAMS = {
    "params": {"actor": {"w": jnp.zeros(4)}, "log_std": jnp.zeros(1), "critic": {"w": jnp.zeros(4)}}
}
LR = 1e-3


def actor_step(grad_clip: str, critic_gradient: float) -> np.ndarray:
    """The actor's first Adam step (its weights' change) for actor gradients of 1e-3 and critic
    gradients of `critic_gradient`, max_grad_norm 0.5."""
    cfg = layers.run_config(
        {
            "env": "pendulum",
            "agent": "ppo_state",
            "ppo": {"max_grad_norm": 0.5, "actor_lr": LR, "critic_lr": LR, "grad_clip": grad_clip},
        }
    )
    optimizer = make_optimizer(Hyper.of(cfg), PARAMS, cfg.ppo)
    grads = {
        "params": {
            "actor": {"w": jnp.full(4, 1e-3)},
            "log_std": jnp.full(1, 1e-3),
            "critic": {"w": jnp.full(4, critic_gradient)},
        }
    }
    updates, _ = optimizer.update(grads, optimizer.init(PARAMS), PARAMS)
    return np.asarray(updates["params"]["actor"]["w"])


def test_per_part_clipping_leaves_the_actor_step_to_the_actor():
    # Adam's first step is -lr * g / (|g| + eps) per element: -lr * 1e-3 / (1e-3 + 1e-5), about
    # -0.99 lr, whatever the critic's gradient (the actor's own norm, sqrt(5) 1e-3, is under the
    # clip).
    small, large = actor_step("per_part", 1.0), actor_step("per_part", 1e4)
    np.testing.assert_allclose(small, -LR * 1e-3 / (1e-3 + 1e-5), rtol=1e-5)
    np.testing.assert_array_equal(small, large)


def test_global_clipping_lets_the_critic_shrink_the_actor_step():
    # A critic gradient of 1e4 per element (norm 2e4) scales every gradient by 0.5 / 2e4: the
    # actor's become 2.5e-8, under Adam's eps, and its step -lr * 2.5e-8 / (2.5e-8 + 1e-5) is 0.25%
    # of lr.
    np.testing.assert_allclose(actor_step("global", 0.0), -LR * 1e-3 / (1e-3 + 1e-5), rtol=1e-5)
    scaled = (
        1e-3 * 0.5 / float(jnp.linalg.norm(jnp.concatenate([jnp.full(5, 1e-3), jnp.full(4, 1e4)])))
    )
    np.testing.assert_allclose(actor_step("global", 1e4), -LR * scaled / (scaled + 1e-5), rtol=1e-4)
    assert abs(actor_step("global", 1e4)[0]) < 0.01 * LR


def test_per_part_clipping_keeps_a_critic_s_own_encoder_apart_from_the_actor_s():
    """ppo.critic_encoder=own: the critic's encoder is a part of its own under per_part clipping,
    trained at the encoders' rate. A critic's gradient of 1e4 on it (and on the critic) leaves the
    actor's encoder's step what it is under a gradient of 1e-3 (in the encoders' group, the
    critic's encoder shrank that step 40x), and the critic's encoder steps at ppo.encoder_lr."""
    cfg = layers.run_config(
        {
            "agent": "ppo_rgb",
            "ppo": {"grad_clip": "per_part", "critic_encoder": "own", "max_grad_norm": 0.5},
        }
    )
    params = {
        "params": {
            name: {"w": jnp.zeros(4)} for name in ("encoder", "critic_encoder", "actor", "critic")
        }
    }
    optimizer = make_optimizer(Hyper.of(cfg), params, cfg.ppo)

    def steps(critic_gradient: float) -> dict:
        grads = jax.tree.map(lambda x: jnp.full_like(x, 1e-3), params)
        for name in ("critic_encoder", "critic"):
            grads["params"][name]["w"] = jnp.full(4, critic_gradient)
        updates, _ = optimizer.update(grads, optimizer.init(params), params)
        return {k: np.asarray(v["w"]) for k, v in updates["params"].items()}

    small, large = steps(1e-3), steps(1e4)
    rate = cfg.ppo.encoder_lr
    np.testing.assert_allclose(small["encoder"], -rate * 1e-3 / (1e-3 + 1e-5), rtol=1e-5)
    np.testing.assert_array_equal(small["encoder"], large["encoder"])
    # the critic's encoder: its own clip, then Adam's first step of about -lr per element
    np.testing.assert_allclose(large["critic_encoder"], -rate * np.ones(4), rtol=1e-4)


@pytest.mark.parametrize("grad_clip", ["global", "per_part"])
def test_a_critic_s_own_encoder_is_a_part_of_its_own_only_where_parts_are_clipped_apart(grad_clip):
    """Under global clipping the critic's own encoder steps in the encoders' group (Adam is
    element by element: the same steps), so the optimiser state keeps the shape that runs with
    ppo.critic_encoder=own saved before the group existed (101 arrays, not 102: they could not
    resume)."""
    cfg = layers.run_config(
        {"agent": "ppo_rgb", "ppo": {"critic_encoder": "own", "grad_clip": grad_clip}}
    )
    params = {
        "params": {n: {"w": jnp.zeros(2)} for n in ("encoder", "critic_encoder", "actor", "critic")}
    }
    state = make_optimizer(Hyper.of(cfg), params, cfg.ppo).init(params)
    partition = next(
        x for x in jax.tree.leaves(state, is_leaf=lambda x: hasattr(x, "inner_states"))
        if hasattr(x, "inner_states")
    )  # fmt: skip
    own = {"critic_encoder"} if grad_clip == "per_part" else set()
    assert set(partition.inner_states) == {"encoder", "actor", "critic"} | own


def test_grad_clip_and_adam_eps_are_checked():
    with pytest.raises(UsageError, match="grad_clip"):
        layers.run_config({"env": "pendulum", "ppo": {"grad_clip": "sometimes"}})
    with pytest.raises(UsageError, match="adam_eps"):
        layers.run_config({"env": "pendulum", "ppo": {"adam_eps": 0.0}})
    with pytest.raises(UsageError, match="gae_segment"):
        layers.run_config({"env": "pendulum", "ppo": {"gae_segment": 7}})


def test_per_part_clipping_trains(tmp_path):
    """A jitted PPO update runs with each new setting and moves the actor."""
    from hintsjax.algorithms.ppo import make_ppo

    cfg = layers.run_config(
        {
            "env": "pendulum",
            "agent": "ppo_state",
            "seeds": 1,
            "ppo": {
                "num_envs": 4,
                "batch_size": 64,
                "minibatch_size": 32,
                "epochs": 1,
                "total_env_steps": 64,
                "grad_clip": "per_part",
                "adam_eps": 1e-8,
                "gae_segment": 8,
            },
        }
    )
    ppo = make_ppo(cfg)
    state = jax.jit(ppo.init)(jax.random.key(0))
    rolled, traj, last_value = jax.jit(ppo.rollout)(state, jax.random.key(1))
    learnt, metrics = jax.jit(ppo.learn)(rolled, traj, last_value, traj.reward, jax.random.key(2))
    assert np.isfinite(float(metrics["policy_loss"]))
    assert not np.allclose(
        learnt.params["params"]["actor"]["Dense_0"]["kernel"],
        state.params["params"]["actor"]["Dense_0"]["kernel"],
    )
