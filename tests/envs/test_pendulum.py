"""Pendulum: parity with Gymnasium `Pendulum-v1`, the picture, batching (SPEC section 2)."""

from __future__ import annotations

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.envs.pendulum import HALF_EXTENT, Pendulum, PendulumState, wrap_angle


S = PendulumState.at


KEY = jax.random.key(0)
SIZE = 64

# -- parity with Gymnasium ---------------------------------------------------------------------


def gym_pendulum():
    env = gym.make("Pendulum-v1").unwrapped
    env.reset(seed=0)
    return env


def test_one_step_parity_with_gymnasium(step, params):
    """Along Gymnasium's own trajectory, our state is reset to gym's before every step.

    400 steps, restarted every 50 steps from an unwrapped angle in [-3pi, 3pi] and a speed of
    6 to 8 rad/s in either direction; actions in [-4, 4], so about half are clipped to +-2 and
    the velocity clip at 8 acts many times. Both sides start each step from the same
    float32-representable state; gym computes in float64, we in float32.
    Measured (CPU, jax 0.10.2): max |d theta| 9.5e-7 (|theta| up to ~10, where one float32 ulp
    is 9.5e-7), |d dtheta| 4.3e-7, |d obs| 9.4e-7, |d reward| 8.2e-6 (|reward| up to ~16, i.e.
    5e-7 relative). Tolerances: 1e-5 on state and obs, 5e-5 on reward (5 to 10x margin).
    """
    gym_env = gym_pendulum()
    rng = np.random.default_rng(0)
    n_steps, clipped_actions, clipped_speeds = 400, 0, 0
    for i in range(n_steps):
        if i % 50 == 0:
            speed = rng.uniform(6.0, 8.0) * rng.choice([-1.0, 1.0])
            gym_env.state = np.array([rng.uniform(-3 * np.pi, 3 * np.pi), speed])
        theta, dtheta = np.asarray(gym_env.state, np.float32)
        gym_env.state = np.array([theta, dtheta], np.float64)
        action = np.float32(rng.uniform(-4.0, 4.0))
        clipped_actions += abs(action) > 2.0

        ts = step(KEY, S(theta, dtheta), jnp.array([action]), params)
        obs, reward, terminated, truncated, _ = gym_env.step(np.array([action], np.float32))
        clipped_speeds += abs(gym_env.state[1]) == 8.0

        np.testing.assert_allclose(
            float(ts.state.theta), gym_env.state[0], rtol=0, atol=1e-5, err_msg=f"step {i}"
        )
        np.testing.assert_allclose(
            float(ts.state.dtheta), gym_env.state[1], rtol=0, atol=1e-5, err_msg=f"step {i}"
        )
        np.testing.assert_allclose(
            np.asarray(ts.obs["state"]), obs, rtol=0, atol=1e-5, err_msg=f"step {i}"
        )
        np.testing.assert_allclose(float(ts.reward), reward, rtol=0, atol=5e-5, err_msg=f"step {i}")
        assert not bool(ts.terminated) and not terminated and not truncated
        assert int(ts.state.t) == 1
    # The test must exercise both clips, or it would not test them.
    assert clipped_actions > 100
    assert clipped_speeds > 20


# Trajectory parity: independent float32 (ours) and float64 (gym) rollouts of 100 steps under
# the same actions in [-3, 3]. Errors compound (fast spinning amplifies them): measured max
# over these start states |d theta| 6.5e-5, |d dtheta| 1.5e-4, |d obs| 1.5e-4, |d reward| 5.0e-4
# (over 200 steps from other starts we saw up to 6e-3 in dtheta, so 100 steps is the horizon).
# Tolerances: 2e-3 on state and obs, 1e-2 on reward (over 10x margin). Checked by mutation:
# the rod's inertia off by 20%, explicit instead of semi-implicit Euler, or either clip
# removed, each fails these tolerances.
TRAJ_STARTS = [
    (np.pi, 0.5),
    (0.07427746, 7.207419),
    (-0.08694537, -7.144916),
    (1.83253, 1.6821854),
    (-2.9, -7.9),
    (2.5, 3.0),
]
TRAJ_ATOL_STATE, TRAJ_ATOL_REWARD = 2e-3, 1e-2


@pytest.mark.parametrize("theta0,dtheta0", TRAJ_STARTS)
def test_trajectory_parity_with_gymnasium(step, params, theta0, dtheta0):
    gym_env = gym_pendulum()
    theta0, dtheta0 = np.float32(theta0), np.float32(dtheta0)
    gym_env.state = np.array([theta0, dtheta0], np.float64)
    state = S(theta0, dtheta0)
    rng = np.random.default_rng(1)
    for i in range(100):
        action = np.float32(rng.uniform(-3.0, 3.0))
        ts = step(KEY, state, jnp.array([action]), params)
        state = ts.state
        obs, reward, *_ = gym_env.step(np.array([action], np.float32))
        ours = [float(state.theta), float(state.dtheta)]
        np.testing.assert_allclose(
            ours, gym_env.state, rtol=0, atol=TRAJ_ATOL_STATE, err_msg=f"step {i}"
        )
        np.testing.assert_allclose(
            np.asarray(ts.obs["state"]), obs, rtol=0, atol=TRAJ_ATOL_STATE, err_msg=f"step {i}"
        )
        np.testing.assert_allclose(
            float(ts.reward), reward, rtol=0, atol=TRAJ_ATOL_REWARD, err_msg=f"step {i}"
        )
    assert int(state.t) == 100


def test_wrap_angle_matches_gymnasium():
    from gymnasium.envs.classic_control.pendulum import angle_normalize

    x = np.linspace(-20.0, 20.0, 2001, dtype=np.float32)
    np.testing.assert_allclose(
        np.asarray(wrap_angle(jnp.asarray(x))), angle_normalize(x), atol=1e-5
    )
    out = np.asarray(wrap_angle(jnp.asarray(x)))
    assert out.min() >= -np.pi - 1e-6 and out.max() < np.pi + 1e-6


def test_initial_state_distribution(env, params, swingto_params):
    """Pendulum-v1's reset: theta ~ U[-pi, pi], dtheta ~ U[-1, 1]; goal 0 (swingup) or
    U[-pi/2, pi/2]."""
    keys = jax.random.split(jax.random.key(7), 2000)
    init = jax.jit(jax.vmap(env.initial_state, in_axes=(0, None)))
    for p, goal_bound in ((params, 0.0), (swingto_params, np.pi / 2)):
        s = jax.tree.map(np.asarray, init(keys, p))
        assert s.theta.dtype == np.float32 and s.t.dtype == np.int32
        assert np.all(s.t == 0)
        assert np.abs(s.theta).max() <= np.pi and np.abs(s.theta).max() > 0.99 * np.pi
        assert np.abs(s.dtheta).max() <= 1.0 and np.abs(s.dtheta).max() > 0.99
        assert abs(s.theta.mean()) < 0.15 and abs(s.dtheta.mean()) < 0.05
        assert np.abs(s.goal).max() <= goal_bound + 1e-6
        if goal_bound:
            assert np.abs(s.goal).max() > 0.99 * goal_bound and len(np.unique(s.goal)) > 1900
        assert len(np.unique(s.theta)) > 1900


# -- the picture -------------------------------------------------------------------------------


def world_coords(rows, cols):
    """World (x, y) of pixel centres; row 0 is the top."""
    pixel = 2 * HALF_EXTENT / SIZE
    return -HALF_EXTENT + (cols + 0.5) * pixel, HALF_EXTENT - (rows + 0.5) * pixel


def rod_centroid(image):
    img = np.asarray(image).astype(int)
    mask = (img[..., 0] - img[..., 1]) > 60  # rod is (204, 77, 77); nothing else is red
    rows, cols = np.nonzero(mask)
    assert len(rows) > 10, "no rod pixels"
    x, y = world_coords(rows, cols)
    return x.mean(), y.mean()


def test_render_shape_and_dtype(render, params):
    image = render(S(0.3, 0.0), params)
    assert image.shape == (SIZE, SIZE, 3) and image.dtype == jnp.uint8
    img = np.asarray(image)
    assert (img == 255).all(-1).mean() > 0.8  # mostly white ground
    # The pivot (radius 0.06, under one pixel at 64x64) darkens the four centre pixels: they are
    # blended black over the rod, never pure black.
    centre = img[SIZE // 2 - 1 : SIZE // 2 + 1, SIZE // 2 - 1 : SIZE // 2 + 1]
    assert centre.max() < 120


@pytest.mark.parametrize(
    "theta", [0.0, np.pi / 2, np.pi, -np.pi / 2, 1.0, -2.5, 2 * np.pi + 0.3, -7.0]
)
def test_rod_pixels_follow_angle(render, params, theta):
    """The rod's centroid lies half-way to the tip at (x, z) = (sin theta, cos theta)."""
    cx, cy = rod_centroid(render(S(theta, 0.0), params))
    assert 0.4 < np.hypot(cx, cy) < 0.7
    direction_error = wrap_angle(jnp.float32(np.arctan2(cx, cy) - theta))
    assert abs(float(direction_error)) < 0.05
    tip_x, tip_y = np.sin(theta), np.cos(theta)
    for world, tip in ((cx, tip_x), (cy, tip_y)):
        if abs(tip) > 0.5:
            assert np.sign(world) == np.sign(tip)
        else:
            assert abs(world) < 0.5 * abs(tip) + 0.05


def test_rod_above_below_and_beside_centre(render, params):
    up, down, right = (rod_centroid(render(S(th, 0.0), params)) for th in (0.0, np.pi, np.pi / 2))
    assert up[1] > 0.4 and abs(up[0]) < 0.05
    assert down[1] < -0.4 and abs(down[0]) < 0.05
    assert right[0] > 0.4 and abs(right[1]) < 0.05


def test_goal_line_drawn_at_goal_angle(render, swingto_params):
    """The swingto goal is drawn as a grey line from the pivot towards (sin goal, cos goal)."""
    for goal in (1.0, -1.2, 0.4):
        img = np.asarray(render(S(np.pi, 0.0, goal=goal), swingto_params)).astype(int)
        grey = (np.ptp(img, axis=-1) < 8) & (img[..., 0] < 245) & (img[..., 0] > 100)
        rows, cols = np.nonzero(grey)
        x, y = world_coords(rows, cols)
        far = np.hypot(x, y) > 0.25  # away from the pivot's anti-aliased rim
        assert far.sum() > 5
        angle = np.arctan2(x[far].mean(), y[far].mean())
        assert abs(angle - goal) < 0.1


def test_vmap_render_equals_loop(env, render, params):
    rng = np.random.default_rng(3)
    n = 12
    batch = S(rng.uniform(-7, 7, n), rng.uniform(-8, 8, n), rng.uniform(-1.5, 1.5, n), np.arange(n))
    images = jax.jit(jax.vmap(env.render, in_axes=(0, None)))(batch, params)
    assert images.shape == (n, SIZE, SIZE, 3) and images.dtype == jnp.uint8
    for i in range(n):
        single = render(jax.tree.map(lambda x: x[i], batch), params)
        np.testing.assert_array_equal(np.asarray(images[i]), np.asarray(single))
    assert len({np.asarray(im).tobytes() for im in images}) == n


# -- batching ----------------------------------------------------------------------------------


def test_vmap_step_equals_loop(step, vstep, params):
    rng = np.random.default_rng(4)
    n = 6  # the batch size test_hints' swing-up uses, so vstep compiles once per session
    batch = S(
        rng.uniform(-7, 7, n),
        rng.uniform(-8, 8, n),
        rng.uniform(-1.5, 1.5, n),
        rng.integers(0, 199, n),
    )
    actions = jnp.asarray(rng.uniform(-3, 3, (n, 1)), jnp.float32)
    keys = jax.random.split(jax.random.key(5), n)
    batched = vstep(keys, batch, actions, params)
    assert batched.obs["pixels"].shape == (n, SIZE, SIZE, 3)
    assert batched.reward.shape == (n,)
    for i in range(n):
        single = step(keys[i], jax.tree.map(lambda x: x[i], batch), actions[i], params)
        leaves_b, tree_b = jax.tree.flatten(jax.tree.map(lambda x: x[i], batched))
        leaves_s, tree_s = jax.tree.flatten(single)
        assert tree_b == tree_s
        for b, s in zip(leaves_b, leaves_s):
            if jnp.issubdtype(s.dtype, jnp.floating):
                np.testing.assert_allclose(np.asarray(b), np.asarray(s), rtol=1e-6, atol=1e-6)
            else:
                np.testing.assert_array_equal(np.asarray(b), np.asarray(s))


def test_sizes(env):
    assert isinstance(env, Pendulum)
    assert env.state_size == 3 and env.action_size == 1 and env.max_steps == 200
    assert isinstance(env.initial_state(jax.random.key(0), env.default_params()), PendulumState)
    assert env.default_params() == envs.make_params("pendulum")
