"""Every registered env under extreme actions: observations, rewards and pictures stay finite, and
AutoReset keeps starting episodes. Slow (`make test-slow`): 10^6 steps per env where they cost a few
minutes on a 2-core CPU, fewer where they cost more and episodes end sooner (DRIVE_STEPS). Measured
in the slow tier on 2 cores (2026-11-28, two tests at once), a step under these actions cost 6.1 ms
for the ant (8 Newton iterations and 16 line-search steps since 2026-11-26: its 2 x 10^5 steps took
20 minutes), 2.5 ms for the humanoid, 0.62 for the halfcheetah, 0.54 for the car, 0.39 for ant_fast
and 0.17 for the idp. HINTSJAX_DRIVE_STEPS=1000000 drives every env the full 10^6.

Actions of +-1e6 are clipped by each env to its range (the pendulum's torque to +-2, MJX envs'
controls to their ctrlrange, the car's steering, gas and brake to theirs). A NaN action is not
sanitised: it makes that env's state NaN, as Gymnasium's envs do; in training the non-finite guard
(hintsjax/training/guards.py) stops the run at the first non-finite loss, before any such state is
saved.
"""

from __future__ import annotations

import os

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax import envs

STEPS_PER_ENV = 10**6
# Steps for the envs whose 10^6 would take more than about 5 minutes of the slow tier (the
# docstring's costs)
# The halfcheetah and the car keep 10^6: their episodes end only at the 1000-step limit under these
# actions, which 1000 envs reach only in 10^6 steps (at 5 x 10^5 none ended, 2026-11-28)
DRIVE_STEPS = {"ant": 10**5, "humanoid": 10**5, "ant_fast": 5 * 10**5}
EXTREMES = jnp.array([1e6, -1e6, 0.0])


def steps_for(name: str) -> int:
    """How many steps the drive gives env `name` (a multiple of 10^5): $HINTSJAX_DRIVE_STEPS for
    every env, else STEPS_PER_ENV, or DRIVE_STEPS' count."""
    return int(os.environ.get("HINTSJAX_DRIVE_STEPS", 0)) or DRIVE_STEPS.get(name, STEPS_PER_ENV)


def drive(name: str, num_envs: int, chunks: int, chunk_steps: int) -> dict:
    """`chunks` x `chunk_steps` steps of `num_envs` envs under actions drawn from +-1e6 and 0;
    each chunk's last states are drawn as pictures. Whether observations (state and hint),
    rewards and pictures stayed finite, and how many episodes ended."""
    hint = "state" if "state" in envs.hint_names(name) else envs.NO_HINT
    env = envs.AutoReset(envs.make(name, hint, ("state", "hint")))
    params = envs.make_params(name)
    ts = jax.vmap(env.reset, in_axes=(0, None))(
        jax.random.split(jax.random.key(0), num_envs), params
    )

    @jax.jit
    def chunk(state, key):
        def step(carry, key):
            state, finite, ended = carry
            k_act, k_env = jax.random.split(key)
            action = jax.random.choice(k_act, EXTREMES, (num_envs, env.action_size))
            ts = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_env, num_envs), state, action, params
            )
            values = [ts.reward, *jax.tree.leaves(ts.obs)]
            finite = finite & jnp.all(jnp.stack([jnp.all(jnp.isfinite(x)) for x in values]))
            return (ts.state, finite, ended + jnp.sum(ts.terminated | ts.truncated)), None

        (state, finite, ended), _ = jax.lax.scan(
            step, (state, True, 0), jax.random.split(key, chunk_steps)
        )
        pictures = jax.vmap(env.render, in_axes=(0, None))(state.env_state, params)
        return state, finite, ended, pictures

    state, finite, ended, drawn = ts.state, True, 0, 0
    for key in jax.random.split(jax.random.key(1), chunks):
        state, ok, n, pictures = chunk(state, key)
        finite, ended = finite and bool(ok), ended + int(n)
        pictures = np.asarray(pictures)
        # drawn, not blank
        assert pictures.dtype == np.uint8 and pictures.shape[0] == num_envs and pictures.std() > 0
        drawn += 1
    return {
        "finite": finite,
        "ended": ended,
        "steps": chunks * chunk_steps * num_envs,
        "pictures": drawn,
    }


@pytest.mark.slow
@pytest.mark.parametrize("name", envs.env_names())
def test_extreme_actions_keep_every_env_finite_and_resetting(name):
    num_envs, chunk_steps, steps = 1000, 100, steps_for(name)
    result = drive(name, num_envs, steps // (num_envs * chunk_steps), chunk_steps)
    assert result["steps"] == steps
    assert result["finite"], f"{name}: a non-finite observation or reward under actions of +-1e6"
    assert result["ended"] > 0, f"{name}: no episode ended (or was reset) in {steps} steps"
