"""Evaluation: each episode counts rewards up to its own end and no further (SPEC sections 6, 8)."""

from __future__ import annotations

import jax
import numpy as np

import countdown_env  # registers the "countdown" env (tests/ is on sys.path)
from hintsjax.config import run_config
from hintsjax.evaluate import eval_keys, make_evaluator
from hintsjax.ppo import make_network


def test_episodes_stop_at_their_own_end():
    """Countdown episodes terminate on a drawn step L (or are truncated at 10): the evaluator
    must report return = length = min(L, 10) for each, computed here from the same reset keys."""
    episodes = 64
    cfg = run_config({"env": "countdown", "agent": "ppo_state", "seeds": 2})
    env = cfg.make_env()
    params = jax.vmap(lambda k: make_network(cfg, env).init(k, {"state": np.zeros((1, 1), np.float32)}))(cfg.seed_keys())
    keys = eval_keys(cfg)
    result = jax.jit(jax.vmap(make_evaluator(cfg, None, episodes)))(params, keys)
    for seed, key in enumerate(keys):
        k_reset, _ = jax.random.split(key)  # the evaluator's own split: reset keys, then step keys
        drawn = np.array([int(env.initial_state(k, ()).length) for k in jax.random.split(k_reset, episodes)])
        expected = np.minimum(drawn, env.max_steps)
        np.testing.assert_array_equal(np.asarray(result.episode_length[seed]), expected)
        np.testing.assert_array_equal(np.asarray(result.episode_return[seed]), expected.astype(np.float32))
        assert (drawn < env.max_steps).any() and (drawn > env.max_steps).any()  # both endings occur
