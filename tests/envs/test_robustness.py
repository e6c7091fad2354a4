"""Every registered env under extreme actions: observations, rewards and pictures stay finite, and
AutoReset keeps starting episodes. Slow (`make test-slow`): 100 envs at once, each stepped past its
1000-step time limit (so every env's episode ends and resets), except the ant and the humanoid,
whose episodes end sooner: 200 envs of 100 steps (DRIVES). Until 2026-12-02 every env drove 1000
envs (10^6 steps where only the time limit ends episodes: the slow tier outgrew CI's 90 minutes),
and the ant and the humanoid did until 2026-12-07 (the ant's drive alone took CI 10 minutes);
HINTSJAX_DRIVE_ENVS=1000 drives every env at that scale again, and
HINTSJAX_DRIVE_STEPS=N gives every env N steps (a multiple of 100).

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

CHUNK_STEPS = 100  # a picture of every env is drawn after each chunk
# (envs at once, steps each): 1100 steps pass the 1000-step time limit, which alone ends the
# halfcheetah's and the car's episodes under these actions (none of 1000 envs ended within 500
# steps, 2026-11-28); ants and humanoids fall within 100 steps (of 100 envs, 229 ant episodes and
# 397 humanoid ones ended there, 2026-12-07)
DRIVES = {"ant": (200, 100), "humanoid": (200, 100)}
PAST_THE_TIME_LIMIT = (100, 1100)
EXTREMES = jnp.array([1e6, -1e6, 0.0])


def drive_size(name: str) -> tuple[int, int]:
    """(envs at once, steps each) for `name`'s drive: DRIVES' or PAST_THE_TIME_LIMIT, either
    replaced by $HINTSJAX_DRIVE_ENVS and $HINTSJAX_DRIVE_STEPS (a multiple of CHUNK_STEPS)."""
    num_envs, steps = DRIVES.get(name, PAST_THE_TIME_LIMIT)
    return (
        int(os.environ.get("HINTSJAX_DRIVE_ENVS", 0)) or num_envs,
        int(os.environ.get("HINTSJAX_DRIVE_STEPS", 0)) or steps,
    )


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
    num_envs, steps = drive_size(name)
    result = drive(name, num_envs, steps // CHUNK_STEPS, CHUNK_STEPS)
    assert result["steps"] == steps * num_envs
    assert result["finite"], f"{name}: a non-finite observation or reward under actions of +-1e6"
    assert result["ended"] > 0, f"{name}: no episode ended (or was reset) in {steps} steps an env"
