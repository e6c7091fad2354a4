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
