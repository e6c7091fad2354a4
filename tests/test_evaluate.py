"""Evaluation: each episode counts rewards up to its own end and no further (SPEC sections 6, 8)."""

from __future__ import annotations

import jax
import numpy as np

# registers the "countdown" env (tests/ is on pytest's path: its rootdir conftest)
import countdown_env
from hintsjax.envs.core import Env
from hintsjax.settings.layers import run_config
from hintsjax.algorithms.ppo import make_network
from hintsjax.evaluation.evaluator import eval_keys, make_evaluator, summarize

# summarize's keys for an env without metrics (what eval.json held before env metrics existed)
PLAIN_KEYS = [
    "mean",
    "std",
    "seed_means",
    "seed_std",
    "outlier_seeds",
    "seeds",
    "episodes_per_seed",
    "mean_length",
    "returns",
]


def evaluate_countdown(episodes: int):
    cfg = run_config({"env": "countdown", "agent": "ppo_state", "seeds": 2})
    env = cfg.make_env()
    params = jax.vmap(
        lambda k: make_network(cfg, env).init(k, {"state": np.zeros((1, 1), np.float32)})
    )(cfg.seed_keys())
    keys = eval_keys(cfg)
    return env, keys, jax.jit(jax.vmap(make_evaluator(cfg, None, episodes)))(params, keys)


def test_episodes_stop_at_their_own_end():
    """Countdown episodes terminate on a drawn step L (or are truncated at 10): the evaluator
    must report return = length = min(L, 10) for each, and the metric steps_left of the state
    each ended in, L - min(L, 10), computed here from the same reset keys."""
    episodes = 64
    env, keys, result = evaluate_countdown(episodes)
    for seed, key in enumerate(keys):
        k_reset, _ = jax.random.split(key)  # the evaluator's own split: reset keys, then step keys
        drawn = np.array(
            [int(env.initial_state(k, ()).length) for k in jax.random.split(k_reset, episodes)]
        )
        expected = np.minimum(drawn, env.max_steps)
        np.testing.assert_array_equal(np.asarray(result.episode_length[seed]), expected)
        np.testing.assert_array_equal(
            np.asarray(result.episode_return[seed]), expected.astype(np.float32)
        )
        np.testing.assert_array_equal(
            np.asarray(result.metrics["steps_left"][seed]), drawn - expected
        )
        assert (drawn < env.max_steps).any() and (drawn > env.max_steps).any()  # both endings occur
    summary = summarize(result)
    steps_left = np.asarray(result.metrics["steps_left"], np.float64)
    assert list(summary) == [
        *PLAIN_KEYS[:-1],
        "steps_left_mean",
        "steps_left_std",
        "steps_left_seed_means",
        "returns",
    ]
    np.testing.assert_allclose(summary["steps_left_mean"], steps_left.mean())
    np.testing.assert_allclose(summary["steps_left_std"], steps_left.std())
    np.testing.assert_allclose(summary["steps_left_seed_means"], steps_left.mean(axis=1))


def test_an_env_without_metrics_adds_no_summary_keys(monkeypatch):
    monkeypatch.setattr(countdown_env.CountdownEnv, "metrics", Env.metrics)
    _, _, result = evaluate_countdown(4)
    assert result.metrics == {}
    assert list(summarize(result)) == PLAIN_KEYS
