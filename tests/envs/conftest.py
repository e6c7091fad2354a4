"""Shared, session-scoped env objects and jitted functions for the env tests.

MJX graphs take seconds to compile on CPU, so each jitted function is built once here and
reused by every test file (jit caches per function object).
"""

from __future__ import annotations

import jax
import pytest

from hintsjax import envs


@pytest.fixture(scope="session")
def params():
    return envs.make_params("pendulum", "swingup")


@pytest.fixture(scope="session")
def swingto_params():
    return envs.make_params("pendulum", "swingto")


@pytest.fixture(scope="session")
def env():
    """Pendulum with every observation key and the composite hint."""
    return envs.make("pendulum", hint="composite")


@pytest.fixture(scope="session")
def step(env):
    return jax.jit(env.step)


@pytest.fixture(scope="session")
def vstep(env):
    return jax.jit(jax.vmap(env.step, in_axes=(0, 0, 0, None)))


@pytest.fixture(scope="session")
def render(env):
    return jax.jit(env.render)


# -- acrobot and idp: one env and one jitted step each, shared by their test files ------------


@pytest.fixture(scope="session")
def acrobot_env():
    return envs.make("acrobot", hint="composite")


@pytest.fixture(scope="session")
def acrobot_step(acrobot_env):
    return jax.jit(acrobot_env.step)


@pytest.fixture(scope="session")
def idp_env():
    return envs.make("idp", hint="composite")


@pytest.fixture(scope="session")
def idp_step(idp_env):
    return jax.jit(idp_env.step)


@pytest.fixture(scope="session")
def idp_state_at(idp_env):
    """jitted (qpos, qvel) -> IDPState with MuJoCo's kinematics and constraint force."""
    return jax.jit(idp_env.state_at)
