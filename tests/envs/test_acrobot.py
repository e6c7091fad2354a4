"""Acrobot: parity with Gymnasium `Acrobot-v1`, the continuous torque, the picture (SPEC 2)."""

from __future__ import annotations

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.envs.acrobot import Acrobot, AcrobotState, HALF_EXTENT, link_ends, tip_height

S = AcrobotState.at
KEY = jax.random.key(0)
SIZE = 64


def gym_acrobot():
    env = gym.make("Acrobot-v1").unwrapped
    env.reset(seed=0)
    return env


def angle_diff(a, b):
    return (np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi


def test_one_step_parity_with_gymnasium(acrobot_step):
    """Gymnasium's discrete actions 0, 1, 2 are our torques -1, 0, 1.

    600 steps along Gymnasium's trajectory, restarted every 50 steps from angles uniform in
    [-pi, pi] and speeds up to 3 pi (shoulder) and 6 pi (elbow), so both velocity clips act;
    each step starts both sides from the same float32 state (gym computes in float64).
    Measured (CPU, jax 0.10.2): max |d obs| 4.2e-5 at speeds near the clips (about 2e-6
    relative), reward and termination identical. Tolerance 2e-4 (5x margin). Checked by
    mutation: the first link's moment of inertia 1.2 instead of 1 gives |d obs| 3.9, no velocity
    clip 10.5.
    """
    gym_env = gym_acrobot()
    rng = np.random.default_rng(0)
    worst, clipped, terminal = 0.0, 0, 0
    for i in range(600):
        if i % 50 == 0:
            gym_env.state = rng.uniform(-np.pi, np.pi, 4) * np.array([1, 1, 3, 6])
        s = np.asarray(gym_env.state, np.float32)
        gym_env.state = s.astype(np.float64)
        a = int(rng.integers(3))
        ts = acrobot_step(KEY, S(*s), jnp.array([a - 1.0]), envs.make_params("acrobot"))
        obs, reward, terminated, _, _ = gym_env.step(a)
        clipped += int(abs(gym_env.state[2]) == 4 * np.pi or abs(gym_env.state[3]) == 9 * np.pi)
        terminal += int(terminated)
        worst = max(worst, float(np.abs(np.asarray(ts.obs["state"]) - obs).max()))
        np.testing.assert_allclose(
            np.asarray(ts.obs["state"]), obs, rtol=0, atol=2e-4, err_msg=f"step {i}"
        )
        np.testing.assert_allclose(angle_diff(ts.state.qpos, gym_env.state[:2]), 0, atol=2e-4)
        assert float(ts.reward) == reward and bool(ts.terminated) == terminated, f"step {i}"
    assert clipped >= 5 and 20 < terminal < 580  # both clips and both outcomes were exercised
    print(f"max |d obs| {worst:.2g}, clipped {clipped}, terminal {terminal}")
    assert worst > 0  # float32 against float64: an exact match would mean we compared gym to itself


def test_trajectory_parity_with_gymnasium(acrobot_step):
    """100 steps from Gymnasium's start distribution under the same random torques, integrated
    independently (ours float32, gym float64). Measured max |d obs| 8.8e-6; tolerance 1e-4."""
    params = envs.make_params("acrobot")
    gym_env = gym_acrobot()
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(2):
        gym_env.reset(seed=int(rng.integers(1 << 30)))
        gym_env.state = np.asarray(gym_env.state, np.float32).astype(np.float64)
        state = S(*gym_env.state)
        for i in range(100):
            a = int(rng.integers(3))
            ts = acrobot_step(KEY, state, jnp.array([a - 1.0]), params)
            obs, reward, terminated, _, _ = gym_env.step(a)
            np.testing.assert_allclose(
                np.asarray(ts.obs["state"]), obs, rtol=0, atol=1e-4, err_msg=f"step {i}"
            )
            assert float(ts.reward) == reward
            worst = max(worst, float(np.abs(np.asarray(ts.obs["state"]) - obs).max()))
            if terminated:
                break
            state = ts.state
    print(f"max |d obs| {worst:.2g}")


def test_negative_torque_is_reachable(acrobot_step):
    """From rest hanging down, torque -1 and +1 turn the elbow in opposite directions, and the
    torque is clipped to [-1, 1] (the authors' action mapping could not produce negative torque)."""
    params = envs.make_params("acrobot")
    rest = S(0.0, 0.0)
    speeds = {
        u: float(acrobot_step(KEY, rest, jnp.array([u]), params).state.qvel[1])
        for u in (-5.0, -1.0, 0.0, 1.0)
    }
    assert speeds[0.0] == 0.0
    assert speeds[-1.0] < -0.1 and speeds[1.0] > 0.1
    np.testing.assert_allclose(speeds[-1.0], -speeds[1.0], rtol=1e-5)
    assert speeds[-5.0] == speeds[-1.0]


@pytest.mark.parametrize(
    "qpos,above",
    [
        ((np.pi, 0.0), True),
        ((0.0, 0.0), False),
        ((1.2, 1.0), False),
        ((2.0, 0.5), True),
        ((np.pi / 2, -np.pi / 2), False),
    ],
)
def test_terminates_when_tip_rises_above_one(acrobot_step, qpos, above):
    """Taking a zero-torque step from a state at rest; gym's rule is -cos t1 - cos(t1 + t2) > 1."""
    params = envs.make_params("acrobot")
    ts = acrobot_step(KEY, S(*qpos), jnp.zeros(1), params)
    assert bool(ts.terminated) == (float(tip_height(ts.state)) > 1.0) == above
    assert float(ts.reward) == (0.0 if above else -1.0)


def test_initial_state_distribution(acrobot_env):
    states = jax.vmap(acrobot_env.initial_state, in_axes=(0, None))(
        jax.random.split(KEY, 2000), envs.make_params("acrobot")
    )
    values = np.concatenate([np.asarray(states.qpos), np.asarray(states.qvel)], axis=1)
    assert np.abs(values).max() <= 0.1 and np.abs(values).max() > 0.099
    assert np.abs(values.mean(0)).max() < 0.01 and np.all(np.asarray(states.t) == 0)


def test_episode_truncates_at_500(acrobot_step):
    ts = acrobot_step(KEY, S(0.0, 0.0, t=499), jnp.zeros(1), envs.make_params("acrobot"))
    assert bool(ts.truncated) and not bool(ts.terminated) and int(ts.state.t) == 500


# -- the picture -------------------------------------------------------------------------------


def link_pixels(image):
    """World (x, y) of the teal link pixels (0, 204, 204): red low, green and blue high."""
    img = np.asarray(image).astype(int)
    rows, cols = np.nonzero((img[..., 0] < 60) & (img[..., 1] > 150) & (img[..., 2] > 150))
    pixel = 2 * HALF_EXTENT / SIZE
    return -HALF_EXTENT + (cols + 0.5) * pixel, HALF_EXTENT - (rows + 0.5) * pixel


@pytest.mark.parametrize(
    "qpos", [(0.0, 0.0), (np.pi, 0.0), (np.pi / 2, 0.0), (-1.0, 2.0), (2.5, -1.5)]
)
def test_link_pixels_follow_the_state(acrobot_env, qpos):
    """The links' pixels lie along pivot -> elbow -> tip, and cover both links."""
    image = jax.jit(acrobot_env.render)(S(*qpos), envs.make_params("acrobot"))
    assert image.shape == (SIZE, SIZE, 3) and image.dtype == jnp.uint8
    x, y = link_pixels(image)
    assert len(x) > 40
    elbow, tip = (np.asarray(p) for p in link_ends(jnp.asarray(qpos, jnp.float32)))
    points = np.stack([x, y], -1)

    def dist(a, b):
        t = np.clip(((points - a) @ (b - a)) / ((b - a) @ (b - a)), 0, 1)
        return np.linalg.norm(points - (a + t[:, None] * (b - a)), axis=-1)

    nearest = np.minimum(dist(np.zeros(2), elbow), dist(elbow, tip))
    assert nearest.max() < 0.2  # within the link's half-width plus a pixel
    # the elbow itself is a joint disc
    for end in (0.75 * elbow, tip, 0.5 * elbow, 0.5 * (elbow + tip)):
        assert np.linalg.norm(points - end, axis=-1).min() < 0.1


def test_vmap_render_equals_loop(acrobot_env):
    params = envs.make_params("acrobot")
    rng = np.random.default_rng(3)
    n = 8
    batch = S(rng.uniform(-np.pi, np.pi, n), rng.uniform(-np.pi, np.pi, n))
    images = jax.jit(jax.vmap(acrobot_env.render, in_axes=(0, None)))(batch, params)
    render = jax.jit(acrobot_env.render)
    for i in range(n):
        np.testing.assert_array_equal(
            np.asarray(images[i]), np.asarray(render(jax.tree.map(lambda x: x[i], batch), params))
        )
    assert len({np.asarray(im).tobytes() for im in images}) == n


def test_sizes(acrobot_env):
    assert isinstance(acrobot_env, Acrobot)
    assert (
        acrobot_env.state_size == 6
        and acrobot_env.action_size == 1
        and acrobot_env.max_steps == 500
    )
