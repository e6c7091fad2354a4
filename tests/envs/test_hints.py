"""Pendulum hints: shapes, hand-computed values, composites, errors, the torque hint (SPEC 3)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.envs import hints as hints_module
from hintsjax.envs.pendulum import PendulumState, wrap_angle


S = PendulumState.at


SPEC_DIMS = {
    "goal_distance": 1,
    "angular_velocity": 1,
    "torque": 1,
    "composite": 2,
    "partial_state": 2,
    "state": 3,
}
HINT_NAMES = envs.hint_names("pendulum")


def hint_value(name, state, params):
    return np.asarray(envs.make_hint("pendulum", name)(state, params))


def random_states(n, seed=0):
    rng = np.random.default_rng(seed)
    return S(
        rng.uniform(-7, 7, n),
        rng.uniform(-8, 8, n),
        rng.uniform(-1.5, 1.5, n),
        rng.integers(0, 200, n),
    )


def test_spec_hints_are_registered():
    assert set(SPEC_DIMS) <= set(HINT_NAMES)


@pytest.mark.parametrize("name", HINT_NAMES)
def test_hint_shape_equals_declared_dim(name, params):
    hint = envs.make_hint("pendulum", name)
    if name in SPEC_DIMS:
        assert hint.dim == SPEC_DIMS[name]
    if name in hints_module._HINTS["pendulum"]:  # a single registered hint: its declared dim
        spec = hints_module._HINTS["pendulum"][name]
        assert hint.dim == spec.dim and hint.units == {name: spec.unit}
        assert np.asarray(spec.fn(S(0.4, -1.0, 0.2), params)).size == spec.dim
    value = hint(S(0.4, -1.0, 0.2), params)
    assert value.shape == (hint.dim,) and value.dtype == jnp.float32
    assert np.all(np.isfinite(np.asarray(value)))
    batched = jax.vmap(hint, in_axes=(0, None))(random_states(5), params)
    assert batched.shape == (5, hint.dim)
    # The env's observation carries it.
    env = envs.make("pendulum", hint=name, observe=("hint",))
    np.testing.assert_array_equal(
        np.asarray(env.observation(S(0.4, -1.0, 0.2), params)["hint"]), np.asarray(value)
    )


# (state, name, expected) at hand-computed states; the goal is 0 unless given.
HAND_COMPUTED = [
    # upright at rest
    (S(0.0, 0.0), "goal_distance", [0.0]),
    (S(0.0, 0.0), "angular_velocity", [0.0]),
    (S(0.0, 0.0), "torque", [0.0]),
    (S(0.0, 0.0), "partial_state", [1.0, 0.0]),
    (S(0.0, 0.0), "state", [1.0, 0.0, 0.0]),
    (S(0.0, 0.0), "composite", [0.0, 0.0]),
    # upright, one turn on (theta is unwrapped)
    (S(2 * np.pi, 0.0), "goal_distance", [0.0]),
    (S(2 * np.pi, 0.0), "torque", [0.0]),
    # hanging at rest
    (S(np.pi, 0.0), "goal_distance", [2.0]),
    (S(np.pi, 0.0), "partial_state", [-1.0, 0.0]),
    (S(np.pi, 0.0), "state", [-1.0, 0.0, 0.0]),
    (S(np.pi, 0.0), "composite", [0.0, 2.0]),
    (S(-np.pi, 0.0), "goal_distance", [2.0]),
    # horizontal and moving
    (S(np.pi / 2, 3.0), "angular_velocity", [3.0]),
    (S(np.pi / 2, 3.0), "goal_distance", [1.0]),
    (S(np.pi / 2, 3.0), "partial_state", [0.0, 1.0]),
    (S(np.pi / 2, 3.0), "state", [0.0, 1.0, 3.0]),
    (S(np.pi / 2, 3.0), "composite", [3.0, 1.0]),
    (S(-np.pi / 2, -2.0), "state", [0.0, -1.0, -2.0]),
    (S(-np.pi / 2, -2.0), "composite", [-2.0, 1.0]),
    (S(np.pi / 3, 0.0), "goal_distance", [0.5]),
    # torque near upright: PD hold -(10 err + 2 dtheta)
    (S(0.1, 0.0), "torque", [-1.0]),
    (S(-0.1, 0.0), "torque", [1.0]),
    (S(0.3, -1.0), "torque", [-1.0]),
    (S(0.1, 0.5), "torque", [-2.0]),
    (S(0.2, 2.0), "torque", [-2.0]),  # -(2 + 4) clipped to the max torque
    # torque far from upright: energy pumping 2 (E* - E) sign(dtheta), E = dtheta^2/6 + 5 cos theta
    (S(np.pi, 0.1), "torque", [2.0]),  # E ~ -5: pump hard along the motion, clipped
    (S(np.pi, -0.1), "torque", [-2.0]),
    (S(np.pi / 2, np.sqrt(30.0)), "torque", [0.0]),  # E = E* = 5: nothing to add
    (S(np.pi / 2, 5.6), "torque", [2 * (5 - 5.6**2 / 6)]),  # slightly too much energy: -0.4533
    (S(-np.pi / 2, -5.6), "torque", [-2 * (5 - 5.6**2 / 6)]),
    # swingto: distances and errors are about the goal angle
    (S(0.2, 0.0, goal=1.0), "goal_distance", [np.cos(1.0) - np.cos(0.2)]),
    (S(1.0, 0.0, goal=1.0), "goal_distance", [0.0]),
    (S(np.pi, 0.0, goal=-np.pi / 2), "goal_distance", [1.0]),
    (S(-0.5, 0.7, goal=-0.5), "composite", [0.7, 0.0]),
    (S(1.1, 0.0, goal=1.0), "torque", [-1.0]),
]


HAND_COMPUTED_IDS = [f"{name}-{i}" for i, (_, name, _) in enumerate(HAND_COMPUTED)]


@pytest.mark.parametrize("state,name,expected", HAND_COMPUTED, ids=HAND_COMPUTED_IDS)
def test_hint_values_at_hand_computed_states(state, name, expected, params, swingto_params):
    for p in (params, swingto_params):  # the goal lives in the state, not the params
        np.testing.assert_allclose(hint_value(name, state, p), expected, rtol=1e-5, atol=1e-5)


def test_composites_are_concatenations(params):
    states = random_states(20, seed=1)
    one = lambda name: jax.vmap(envs.make_hint("pendulum", name), in_axes=(0, None))(states, params)  # noqa: E731
    composite = np.asarray(one("composite"))
    expected = np.concatenate(
        [np.asarray(one("angular_velocity")), np.asarray(one("goal_distance"))], axis=1
    )
    np.testing.assert_allclose(composite, expected, rtol=0, atol=0)
    np.testing.assert_array_equal(np.asarray(one("angular_velocity+goal_distance")), composite)
    np.testing.assert_array_equal(np.asarray(one("angular_velocity + goal_distance")), composite)
    theta, dtheta, goal = (
        np.asarray(x, np.float64) for x in (states.theta, states.dtheta, states.goal)
    )
    np.testing.assert_allclose(
        composite, np.stack([dtheta, np.cos(goal) - np.cos(theta)], 1), atol=1e-5
    )
    np.testing.assert_allclose(
        np.asarray(one("state")), np.stack([np.cos(theta), np.sin(theta), dtheta], 1), atol=1e-5
    )
    np.testing.assert_allclose(
        np.asarray(one("partial_state")), np.stack([np.cos(theta), np.sin(theta)], 1), atol=1e-5
    )
    mixed = envs.make_hint("pendulum", "composite+torque")
    assert mixed.dim == 3
    np.testing.assert_array_equal(
        np.asarray(jax.vmap(mixed, in_axes=(0, None))(states, params)),
        np.concatenate([composite, np.asarray(one("torque"))], axis=1),
    )


def test_state_hint_equals_state_observation(env, params):
    states = random_states(10, seed=2)
    for i in range(10):
        s = jax.tree.map(lambda x: x[i], states)
        np.testing.assert_array_equal(
            hint_value("state", s, params), np.asarray(env.state_obs(s, params))
        )


def test_unknown_hint_raises_choice_error_listing_valid_names():
    for spec in ("nope", "angular_velocity+nope", ""):
        with pytest.raises(envs.ChoiceError) as err:
            envs.make_hint("pendulum", spec)
        message = str(err.value)
        for name in HINT_NAMES:
            assert name in message
    with pytest.raises(envs.ChoiceError, match="nope"):
        envs.make_hint("pendulum", "nope")


def test_user_hint_registers_and_combines(monkeypatch, params):
    """SPEC 3: a user hint is one function plus `register_hint`, then usable in a '+' spec."""
    monkeypatch.setattr(
        hints_module, "_HINTS", {k: dict(v) for k, v in hints_module._HINTS.items()}
    )

    @envs.register_hint("pendulum", "tip_height_test", dim=1, unit="m")
    def tip_height(state, p):
        """Height of the tip above the pivot."""
        return jnp.cos(state.theta)[None]

    hint = envs.make_hint("pendulum", "tip_height_test+goal_distance")
    assert hint.dim == 2 and hint.units == {"tip_height_test": "m", "goal_distance": "m"}
    np.testing.assert_allclose(np.asarray(hint(S(np.pi / 3, 0.0), params)), [0.5, 0.5], atol=1e-6)
    assert "tip_height_test" in envs.hint_names("pendulum")


# -- the torque hint swings the pendulum up ----------------------------------------------------

SWING_STARTS = [
    (np.pi, 0.1),
    (np.pi, -0.1),
    (-np.pi, 0.05),
    (np.pi + 0.01, 0.0),
    (np.pi - 0.05, -0.2),
    (np.pi, 0.3),
]


@pytest.fixture(scope="module")
def torque_hint():
    return jax.jit(jax.vmap(envs.make_hint("pendulum", "torque"), in_axes=(0, None)))


def test_torque_hint_swings_up_and_holds(torque_hint, vstep, params):
    """From hanging (nearly) at rest, following the torque hint reaches upright and stays there.

    Measured: every start is within 0.1 rad of upright by step ~71, and |wrap(theta)| < 1e-6 and
    |dtheta| < 1e-5 at step 200.
    """
    theta0, dtheta0 = (np.array(x, np.float32) for x in zip(*SWING_STARTS))
    n = len(SWING_STARTS)
    state = S(theta0, dtheta0, np.zeros(n), np.zeros(n))
    keys = jax.random.split(jax.random.key(0), n)
    theta, dtheta, actions, truncated = [], [], [], []
    for _ in range(200):  # the env's batched step (shared, already compiled), action = the hint
        action = torque_hint(state, params)
        ts = vstep(keys, state, action, params)
        state = ts.state
        theta.append(np.asarray(state.theta))
        dtheta.append(np.asarray(state.dtheta))
        actions.append(np.asarray(action)[:, 0])
        truncated.append(np.asarray(ts.truncated))
    final = state
    theta, dtheta, actions, truncated = (
        np.stack(x, axis=1) for x in (theta, dtheta, actions, truncated)
    )
    wrapped = np.abs(np.asarray(wrap_angle(theta)))
    assert np.abs(np.asarray(actions)).max() <= 2.0 + 1e-6
    assert np.abs(np.asarray(actions)).max() == pytest.approx(2.0)  # it has to pump at full torque
    # It starts hanging, so reaching upright takes a real swing-up.
    assert (wrapped[:, 0] > 2.5).all() and (wrapped[:, :40] > 0.5).all()
    # Near upright (within 0.05 rad, ~3 degrees) for the last 50 steps, at rest at the end.
    assert wrapped[:, 150:].max() < 0.05
    assert np.abs(np.asarray(wrap_angle(final.theta))).max() < 0.01
    assert np.abs(np.asarray(final.dtheta)).max() < 0.05
    assert np.asarray(truncated)[:, -1].all() and not np.asarray(truncated)[:, :-1].any()
