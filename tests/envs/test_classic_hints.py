"""Acrobot and IDP hints (SPEC section 3): registration, shape, unit, and values at hand-computed
states (upright, hanging, moving). Pendulum's hints are in test_hints.py."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.envs import hints as hints_module
from hintsjax.envs.acrobot import AcrobotState

PI = np.pi

SPEC_DIMS = {
    "acrobot": {
        "angular_velocity_1": 1,
        "angular_velocity_2": 1,
        "joint": 1,
        "goal_distance": 1,
        "composite": 2,
        "partial_state": 4,
        "state": 6,
    },
    "idp": {
        "angular_velocity_1": 1,
        "angular_velocity_2": 1,
        "joint": 1,
        "goal_distance": 1,
        "composite": 2,
        "partial_state": 7,
        "state": 9,
    },
}
CASES = [(env, name) for env in SPEC_DIMS for name in envs.hint_names(env)]


@pytest.fixture(scope="module")
def states(idp_state_at):
    """Named hand-set states of each env."""
    return {
        "acrobot": {
            "hanging": AcrobotState.at(0.0, 0.0),
            "upright": AcrobotState.at(PI, 0.0),
            "moving": AcrobotState.at(PI / 2, -PI / 2, 1.5, -2.0),
        },
        "idp": {
            "upright": idp_state_at([0.3, 0.0, 0.0], [0.0, 0.0, 0.0]),
            "hanging": idp_state_at([0.0, PI, 0.0], [0.0, 0.0, 0.0]),
            "moving": idp_state_at([0.2, PI / 2, -PI / 2], [0.5, 1.0, -3.0]),
        },
    }


def test_spec_hints_are_registered():
    for env, dims in SPEC_DIMS.items():
        assert set(dims) == set(envs.hint_names(env)), env


@pytest.mark.parametrize("env,name", CASES)
def test_shape_unit_and_observation(env, name, states):
    hint = envs.make_hint(env, name)
    params = envs.make_params(env)
    assert hint.dim == SPEC_DIMS[env][name]
    if name in hints_module._HINTS[env]:
        spec = hints_module._HINTS[env][name]
        assert hint.units == {name: spec.unit} and len(spec.unit.split(",")) == spec.dim
    state = states[env]["moving"]
    value = hint(state, params)
    assert value.shape == (hint.dim,) and value.dtype == jnp.float32
    batch = jax.tree.map(lambda *x: jnp.stack(x), *states[env].values())
    np.testing.assert_allclose(
        np.asarray(jax.vmap(hint, in_axes=(0, None))(batch, params))[2], np.asarray(value)
    )
    observed = envs.make(env, hint=name, observe=("hint",)).observation(state, params)["hint"]
    np.testing.assert_array_equal(np.asarray(observed), np.asarray(value))


# (env, state name, hint, expected), worked out by hand from the SPEC's definitions.
# acrobot: link lengths 1, angles from hanging down, D_goal = 2 + cos t1 + cos(t1 + t2).
# idp: pole lengths 0.6, angles from upright, D_goal = 1.2 - 0.6 (cos p1 + cos(p1 + p2)).
HAND_COMPUTED = [
    ("acrobot", "hanging", "goal_distance", [4.0]),
    ("acrobot", "hanging", "state", [1, 0, 1, 0, 0, 0]),
    ("acrobot", "hanging", "composite", [0, 0]),
    ("acrobot", "upright", "goal_distance", [0.0]),
    ("acrobot", "upright", "partial_state", [1, 0, 0, 0]),
    ("acrobot", "moving", "angular_velocity_1", [1.5]),
    ("acrobot", "moving", "angular_velocity_2", [-2.0]),
    ("acrobot", "moving", "joint", [-0.5]),
    ("acrobot", "moving", "goal_distance", [3.0]),  # first link level, second hanging
    ("acrobot", "moving", "composite", [1.5, -2.0]),
    ("acrobot", "moving", "partial_state", [0, -1, 1.5, -2.0]),
    ("acrobot", "moving", "state", [0, 1, 0, -1, 1.5, -2.0]),
    ("idp", "upright", "goal_distance", [0.0]),
    ("idp", "upright", "composite", [0, 0]),
    ("idp", "upright", "state", [0.3, 0, 0, 1, 1, 0, 0, 0, 0]),
    ("idp", "hanging", "goal_distance", [2.4]),
    ("idp", "hanging", "partial_state", [0, -1, 1, 0, 0, 0, 0]),
    ("idp", "moving", "angular_velocity_1", [1.0]),
    ("idp", "moving", "angular_velocity_2", [-3.0]),
    ("idp", "moving", "joint", [-2.0]),
    ("idp", "moving", "goal_distance", [0.6]),  # lower pole level, upper pole upright
    ("idp", "moving", "composite", [1.0, -3.0]),
    ("idp", "moving", "state", [0.2, 1, -1, 0, 0, 0.5, 1.0, -3.0, 0]),
    ("idp", "moving", "partial_state", [-1, 0, 0, 0.5, 1.0, -3.0, 0]),
]


@pytest.mark.parametrize("env,state,name,expected", HAND_COMPUTED)
def test_hint_values_at_hand_computed_states(env, state, name, expected, states):
    value = envs.make_hint(env, name)(states[env][state], envs.make_params(env))
    np.testing.assert_allclose(np.asarray(value), expected, atol=1e-5)


def test_idp_slider_force_enters_the_state_hint(idp_state_at):
    """Past the rail's limit (|x| > 0.99, the margin) the constraint pushes back: the last
    observation entry is the slider's constraint force, negative at the right end."""
    state = idp_state_at([1.05, 0.0, 0.0], [0.0, 0.0, 0.0])
    force = float(envs.make_hint("idp", "state")(state, envs.make_params("idp"))[-1])
    assert force < -0.1
