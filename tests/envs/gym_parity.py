"""Parity of an env with its Gymnasium v5 reference along Gymnasium's own trajectories: before
every step our state is set to gym's (rounded to float32), both take the same action, and the
next observation, reward and termination are compared (MuJoCo C computes in float64, MJX in
float32). Shared by the locomotion tests and the physics tests (either implementation)."""

from __future__ import annotations

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np

KEY = jax.random.key(0)


def f32(x):
    """x rounded to float32 and back, so that both sides start from the same state."""
    return np.asarray(x, np.float32).astype(np.float64)


class Compiled:
    """An env observing its state, with its transition and `state_at` jitted once."""

    def __init__(self, env):
        self.env, self.params = env, env.default_params()
        self.transition, self.state_at = jax.jit(env.transition), jax.jit(env.state_at)


def parity(
    compiled: Compiled,
    gym_id: str,
    steps: int,
    gym_options: dict | None = None,
    adapt=None,
    same_termination: bool = True,
    policy=None,
    episode_steps: int = 20,
) -> dict[str, float]:
    """Worst |d obs|, |d reward|, |d qpos|, |d qvel| along gym's trajectories (a fresh gym
    episode every `episode_steps` steps and after each termination), asserting equal termination
    (or, with `same_termination` False, counting the steps where it differs); counts of terminal
    and contact steps. Actions are uniform in the action space, or `policy(gym's observation)`
    clipped to it. gym's model takes `gym_options` and then `adapt(model)`, if given."""
    params, step, state_at = compiled.params, compiled.transition, compiled.state_at
    gym_env = gym.make(gym_id).unwrapped
    for field, value in (gym_options or {}).items():
        setattr(gym_env.model.opt, field, value)
    if adapt is not None:
        adapt(gym_env.model)
    rng = np.random.default_rng(0)
    low, high = gym_env.action_space.low, gym_env.action_space.high
    worst = dict(
        obs=0.0, reward=0.0, qpos=0.0, qvel=0.0, terminal=0, contact=0, termination_differs=0
    )
    fresh = True
    for i in range(steps):
        if fresh or i % episode_steps == 0:
            gym_env.reset(seed=i)
        qpos, qvel = f32(gym_env.data.qpos), f32(gym_env.data.qvel)
        gym_env.set_state(qpos, qvel)
        if policy is None:
            action = rng.uniform(low, high).astype(np.float32)
        else:
            action = np.clip(
                np.asarray(policy(jnp.asarray(gym_env._get_obs(), jnp.float32))), low, high
            ).astype(np.float32)
        out = step(KEY, state_at(qpos, qvel), jnp.asarray(action), params)
        obs, reward, terminated, _, _ = gym_env.step(action)
        assert bool(out.terminated) == terminated or not same_termination, f"step {i}"
        worst["termination_differs"] += bool(out.terminated) != terminated
        worst["obs"] = max(worst["obs"], float(np.abs(np.asarray(out.state.obs) - obs).max()))
        worst["reward"] = max(worst["reward"], abs(float(out.reward) - reward))
        for name in ("qpos", "qvel"):
            gap = np.abs(np.asarray(getattr(out.state, name)) - getattr(gym_env.data, name)).max()
            worst[name] = max(worst[name], float(gap))
        worst["terminal"] += terminated
        worst["contact"] += gym_env.data.ncon > 0
        fresh = terminated
    print(gym_id, worst)
    return worst
