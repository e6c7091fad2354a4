"""The running state normaliser (ppo.normalize_state): its statistics, the network's use of them,
PPO's and DAgger's updates of them, and an exported expert's."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np

import linear_env  # registers the "linear" env (tests/ is on pytest's path: its rootdir conftest)
from hintsjax.models import normalization
from hintsjax.models.agents import AGENTS
from hintsjax.models.networks import ActorCritic
from hintsjax.settings import layers
from hintsjax.algorithms import dagger
from hintsjax.algorithms.ppo import make_optimizer, make_ppo

LINEAR = dict(
    env="linear",
    seeds=1,
    ppo=dict(
        num_envs=8,
        batch_size=128,
        minibatch_size=64,
        epochs=2,
        total_env_steps=2 * 128,
        normalize_state=True,
    ),
)


def stats_of(variables) -> dict:
    return jax.tree.map(np.asarray, variables[normalization.COLLECTION][normalization.NAME])


def test_merge_gives_the_statistics_of_every_row_seen():
    rows = (
        np.random.default_rng(0)
        .normal([3.0, -1.0, 0.0], [2.0, 0.5, 1e-3], size=(300, 3))
        .astype(np.float32)
    )
    identity = {"mean": jnp.zeros(3), "var": jnp.ones(3), "count": jnp.zeros(())}
    stats = normalization.merge(normalization.merge(identity, rows[:100]), rows[100:])
    np.testing.assert_allclose(stats["mean"], rows.mean(0), rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(stats["var"], rows.var(0), rtol=1e-4, atol=1e-9)
    assert float(stats["count"]) == 300


def test_the_network_reads_the_state_through_its_statistics():
    spec, state = AGENTS["ppo_state"], jnp.asarray([[10.0, -4.0], [1.0, 30.0]])
    plain, normed = ActorCritic(spec, "fc", 1), ActorCritic(spec, "fc", 1, normalize_state=True)
    variables = normed.init(jax.random.key(0), {"state": state})
    assert set(stats_of(variables)) == {"mean", "var", "count"}
    small = state / 4.0  # within +-CLIP: the statistics start as the identity
    np.testing.assert_allclose(
        normed.apply(variables, {"state": small})[2],
        plain.apply({"params": variables["params"]}, {"state": small})[2],
        rtol=1e-5,
    )
    stats = {
        "mean": jnp.asarray([2.0, 5.0]),
        "var": jnp.asarray([4.0, 0.25]),
        "count": jnp.asarray(7.0),
    }
    variables = {**variables, normalization.COLLECTION: {normalization.NAME: stats}}
    by_hand = jnp.clip(
        (state - stats["mean"]) / jnp.sqrt(stats["var"] + normalization.EPS), -10, 10
    )
    np.testing.assert_allclose(by_hand[1, 1], 10.0)  # 50 standard deviations away: clipped
    for got, want in zip(
        normed.apply(variables, {"state": state}),
        plain.apply({"params": variables["params"]}, {"state": by_hand}),
    ):
        np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)


def test_ppo_merges_each_rollout_after_learning_and_never_trains_the_statistics():
    cfg = layers.run_config({**LINEAR, "agent": "ppo_state"})
    ppo = make_ppo(cfg)
    # jitted: op by op, it took most of this test's time
    state = jax.jit(ppo.init)(jax.random.key(0))
    before = stats_of(state.params)
    rolled, traj, last_value = jax.jit(ppo.rollout)(state, jax.random.key(1))
    learnt, _ = jax.jit(ppo.learn)(rolled, traj, last_value, traj.reward, jax.random.key(2))
    want = normalization.merge(before, np.asarray(traj.obs["state"]).reshape(-1, 2))
    jax.tree.map(
        lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-6), stats_of(learnt.params), want
    )
    assert float(stats_of(learnt.params)["count"]) == cfg.ppo.batch_size
    assert not np.allclose(
        learnt.params["params"]["actor"]["Dense_0"]["kernel"],
        state.params["params"]["actor"]["Dense_0"]["kernel"],
    )
    # even a gradient on the statistics moves nothing
    optimizer = make_optimizer(state.hyper, state.params, cfg.ppo)
    ones = jax.tree.map(jnp.ones_like, state.params)
    updates, _ = jax.jit(lambda p: optimizer.update(ones, optimizer.init(p), p))(state.params)
    assert all(
        np.all(np.asarray(u) == 0) for u in jax.tree.leaves(updates[normalization.COLLECTION])
    )
    assert np.all(np.asarray(updates["params"]["log_std"]) != 0)


def test_normalize_before_learning_learns_on_the_merged_statistics():
    # Brax's order (ppo.normalize_before_learning): learning on a rollout sees the statistics that
    # already include it, so the first update learns on normalised states, not through the identity.
    # It learns exactly what the default order learns from a state whose statistics were merged
    # first.
    after = layers.run_config({**LINEAR, "agent": "ppo_state"})
    before = layers.run_config(
        {
            **LINEAR,
            "agent": "ppo_state",
            "ppo": {**LINEAR["ppo"], "normalize_before_learning": True},
        }
    )
    ppo_after, ppo_before = make_ppo(after), make_ppo(before)
    state = jax.jit(ppo_before.init)(jax.random.key(0))
    rolled, traj, last_value = jax.jit(ppo_before.rollout)(state, jax.random.key(1))
    learnt, _ = jax.jit(ppo_before.learn)(rolled, traj, last_value, traj.reward, jax.random.key(2))
    merged = rolled.replace(params=normalization.update(rolled.params, traj.obs))
    by_hand, _ = jax.jit(ppo_after.learn)(merged, traj, last_value, traj.reward, jax.random.key(2))
    jax.tree.map(
        lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6),
        learnt.params["params"],
        by_hand.params["params"],
    )
    # merged once, not again after learning
    assert float(stats_of(learnt.params)["count"]) == before.ppo.batch_size


def test_dagger_merges_the_visited_states():
    cfg = layers.run_config(
        {**LINEAR, "agent": "dagger", "dagger": dict(grad_steps=4, buffer_size=256)}
    )
    trainer = dagger.make_trainer(cfg, expert=linear_env.EXPERT)
    state = trainer.init(jax.random.key(0))
    after, _ = jax.jit(trainer.update)(state)
    data = np.asarray(after.data.state[: cfg.ppo.batch_size])  # the first round's states, in order
    jax.tree.map(
        lambda a, b: np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-6),
        stats_of(after.params),
        normalization.merge(stats_of(state.params), data),
    )
