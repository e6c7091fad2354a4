"""The policy's action heads (`ppo.action_head`): each env's action range, the tanh head's
squashing into it (envs.SquashedActions), the authors' sigmoid head, and a tanh agent learning an
action at the edge of its range. Bad heads are in tests/test_cli.py's BAD_SETTINGS."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from flax import struct

from hintsjax import envs
from hintsjax.envs.core import Env, Step
from hintsjax.models.agents import AGENTS
from hintsjax.models.networks import ActorCritic, SIGMOID_MIN_STD
from hintsjax.settings.layers import run_config
from hintsjax.algorithms.registry import make_trainer


@struct.dataclass
class EdgeState:
    t: jax.Array


class EdgeEnv(Env):
    """One-step episodes whose reward is the action received. Its range is [-1, 1], but it does not
    clip: a reward above 1 is an action the agent sent outside the range."""

    name = "edge"
    max_steps = 1
    action_size = 1
    image_size = 36

    def default_params(self):
        return ()

    def initial_state(self, key, params):
        return EdgeState(jnp.zeros((), jnp.int32))

    def action_range(self, params):
        return -jnp.ones(1), jnp.ones(1)

    def transition(self, key, state, action, params):
        return Step(state, action[0], jnp.ones((), bool))

    def render(self, state, params):
        return jnp.zeros((self.image_size, self.image_size, 3), jnp.uint8)

    def state_obs(self, state, params):
        return jnp.ones(2, jnp.float32)


envs.REGISTRY["edge"] = envs.EnvEntry(
    EdgeEnv,
    {"default": ()},
    training=dict(
        ppo=dict(hidden=(16, 16), num_envs=16, batch_size=64, minibatch_size=32, epochs=4)
    ),
)


@pytest.mark.parametrize("name", ["pendulum", "acrobot", "car_racing"])
def test_each_env_clips_its_actions_into_its_action_range(name):
    """Stepping with an action far outside the range is stepping with the range's nearest edge."""
    env, params = envs.make(name, envs.NO_HINT, ("state",)), envs.make_params(name)
    low, high = env.action_range(params)
    assert low.shape == high.shape == (env.action_size,) and bool(jnp.all(low < high))
    state, key = env.reset(jax.random.key(0), params).state, jax.random.key(1)
    step = jax.jit(lambda a: env.step(key, state, a, params).obs["state"])
    for far, edge in ((1e6, high), (-1e6, low)):
        np.testing.assert_array_equal(step(jnp.full(env.action_size, far)), step(edge))


def test_locomotion_action_range_is_the_actuators_ctrlrange():
    env = envs.make("halfcheetah", envs.NO_HINT, ("state",))
    low, high = env.action_range(envs.make_params("halfcheetah"))
    np.testing.assert_array_equal(np.stack([low, high], axis=1), env.mj_model.actuator_ctrlrange)


def test_squashed_actions_map_the_real_line_onto_the_range():
    car = envs.SquashedActions(envs.make("car_racing", envs.NO_HINT, ("state",)))
    params = envs.make_params("car_racing")
    # gas and brake half on
    np.testing.assert_allclose(car.squash(jnp.zeros(3), params), [0.0, 0.5, 0.5])
    np.testing.assert_allclose(car.squash(jnp.full(3, 30.0), params), [1.0, 1.0, 1.0])
    np.testing.assert_allclose(car.squash(jnp.full(3, -30.0), params), [-1.0, 0.0, 0.0])
    pendulum = envs.make("pendulum", envs.NO_HINT, ("state",))
    squashed, params = envs.SquashedActions(pendulum), envs.make_params("pendulum")
    state, key, u = (
        pendulum.reset(jax.random.key(0), params).state,
        jax.random.key(1),
        jnp.array([0.3]),
    )
    np.testing.assert_array_equal(
        squashed.step(key, state, u, params).obs["state"],
        pendulum.step(key, state, 2.0 * jnp.tanh(u), params).obs["state"],
    )


def test_sigmoid_head_bounds_the_mean_and_floors_the_std():
    net = ActorCritic(AGENTS["ppo_state"], "fc", 2, hidden=(8,), action_head="sigmoid")
    variables = net.init(jax.random.key(0), {"state": jnp.zeros((1, 3))})
    params = variables["params"]
    params = {
        **params,
        "log_std": jnp.array([-10.0, 0.5]),
        "actor": jax.tree.map(lambda x: 1e3 * jnp.ones_like(x), params["actor"]),
    }
    mean, log_std, _ = net.apply(
        {"params": params}, {"state": jnp.array([[1.0, 1.0, 1.0], [-1.0, -1.0, -1.0]])}
    )
    assert bool(jnp.all(jnp.abs(mean) <= 1.0)) and float(jnp.max(jnp.abs(mean))) > 0.99
    np.testing.assert_allclose(log_std, [np.log(SIGMOID_MIN_STD), 0.5], rtol=1e-6)


def test_sigmoid_head_log_probability_is_the_hand_computed_one():
    """The actor's last layer outputs its bias b = (0, ln 3) (every kernel zero), so the head's mean
    is 2 sigmoid(b) - 1 = (0, 0.5); log std (ln 0.5, -10) is floored to (ln 0.5, ln 0.01). Action
    (0.5, 0.52) is then 1 and 2 stds from the mean: log p = (-1/2 + ln 2) + (-2 + ln 100) -
    ln 2 pi."""
    from hintsjax.algorithms.ppo_math import gaussian_log_prob

    net = ActorCritic(AGENTS["ppo_state"], "fc", 2, hidden=(8,), action_head="sigmoid")
    params = net.init(jax.random.key(0), {"state": jnp.zeros((1, 3))})["params"]
    actor = jax.tree.map(jnp.zeros_like, params["actor"])
    actor["Dense_1"]["bias"] = jnp.array([0.0, np.log(3.0)])
    params = {**params, "actor": actor, "log_std": jnp.array([np.log(0.5), -10.0])}
    mean, log_std, _ = net.apply({"params": params}, {"state": jnp.array([[0.3, -1.2, 2.0]])})
    got = float(gaussian_log_prob(jnp.array([[0.5, 0.52]]), mean, log_std)[0])
    want = (-0.5 + np.log(2.0)) + (-2.0 + np.log(100.0)) - np.log(2 * np.pi)
    np.testing.assert_allclose(got, want, rtol=1e-4)


def test_a_tanh_agent_learns_the_action_at_the_edge_of_its_range():
    """Reward = the action: the squashed policy's deterministic action, tanh(mean), nears the
    range's edge 1, and every action the env received lay in the range (returns <= 1; the gaussian
    head's draws, unsquashed, go beyond it)."""
    cfg = run_config(
        dict(
            env="edge",
            agent="ppo_state",
            seeds=1,
            ppo=dict(action_head="tanh", total_env_steps=64 * 40),
        )
    )
    trainer = make_trainer(cfg)
    before = trainer.init(jax.random.key(0))
    state, metrics = jax.jit(lambda s: trainer.run(s, cfg.ppo.num_updates))(before)
    mean = lambda s: trainer.network.apply(s.params, {"state": jnp.ones((1, 2))})[0][0, 0]  # noqa: E731
    assert float(jnp.tanh(mean(before))) == pytest.approx(0.0, abs=0.05)
    assert float(jnp.tanh(mean(state))) > 0.9, float(jnp.tanh(mean(state)))
    returns = np.asarray(metrics["episode_return"])
    assert np.nanmax(returns) <= 1.0 and np.nanmean(returns[-5:]) > np.nanmean(returns[:5])
