"""InvertedDoublePendulum: parity with Gymnasium `InvertedDoublePendulum-v5` (MuJoCo C), the
reset distribution, the picture (SPEC 2)."""

from __future__ import annotations

import gymnasium as gym
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.envs.idp import CENTRE, HALF_EXTENT, InvertedDoublePendulum, pole_ends

KEY = jax.random.key(0)
SIZE = 64


def f32(x):
    """x rounded to float32 and back, so that both sides start from the same state."""
    return np.asarray(x, np.float32).astype(np.float64)


def test_parity_with_gymnasium(idp_step, idp_state_at):
    """Along Gymnasium's own trajectories, restarted every 25 steps from a random state (cart
    anywhere on the rail, so the slider's limit acts; poles up to 0.3 rad; speeds N(0, 1)) and
    driven by actions in [-1.2, 1.2] (clipped to [-1, 1]). Before every step our state is set
    to gym's, rounded to float32; MuJoCo C computes in float64, MJX in float32.

    Measured (CPU, jax 0.10.2, mujoco 3.17.0): max |d obs| 6.9e-6, |d reward| 1.2e-6,
    termination identical. Tolerances: 5e-5 on observation and reward (about 10x margin).
    """
    params = envs.make_params("idp")
    gym_env = gym.make("InvertedDoublePendulum-v5").unwrapped
    gym_env.reset(seed=0)
    rng = np.random.default_rng(0)
    worst_obs = worst_reward = 0.0
    terminal = limit = alive = 0
    terminal_last = False
    for i in range(200):
        if i % 25 == 0 or terminal_last:
            qpos = rng.uniform(-0.3, 0.3, 3) * np.array([3.3, 1, 1])
            qvel = rng.normal(0, 1, 3)
        else:
            qpos, qvel = gym_env.data.qpos.copy(), gym_env.data.qvel.copy()
        qpos, qvel = f32(qpos), f32(qvel)
        gym_env.set_state(qpos, qvel)
        action = np.float32(rng.uniform(-1.2, 1.2))
        ts = idp_step(KEY, idp_state_at(qpos, qvel), jnp.array([action]), params)
        obs, reward, terminated, _, _ = gym_env.step(np.array([action]))
        worst_obs = max(worst_obs, float(np.abs(np.asarray(ts.obs["state"]) - obs).max()))
        worst_reward = max(worst_reward, abs(float(ts.reward) - reward))
        np.testing.assert_allclose(
            np.asarray(ts.obs["state"]), obs, rtol=0, atol=5e-5, err_msg=f"step {i}"
        )
        np.testing.assert_allclose(float(ts.reward), reward, rtol=0, atol=5e-5, err_msg=f"step {i}")
        assert bool(ts.terminated) == terminated, f"step {i}"
        terminal_last = terminated
        terminal += terminated
        alive += not terminated
        limit += obs[-1] != 0.0
    print(
        f"max |d obs| {worst_obs:.2g}, |d reward| {worst_reward:.2g}; {terminal} terminal, {limit} "
        "at the limit"
    )
    assert terminal > 10 and alive > 50 and limit > 5  # every branch was exercised
    assert worst_obs > 0  # float32 against float64


def test_reset_matches_gymnasium_distribution(idp_env):
    """qpos uniform in [-0.1, 0.1], qvel N(0, 0.1^2): compared with Gymnasium's own resets."""
    params = envs.make_params("idp")
    n = 2000
    states = jax.jit(jax.vmap(idp_env.initial_state, in_axes=(0, None)))(
        jax.random.split(KEY, n), params
    )
    qpos, qvel = np.asarray(states.qpos), np.asarray(states.qvel)
    gym_env = gym.make("InvertedDoublePendulum-v5").unwrapped
    gym_obs = np.stack([gym_env.reset(seed=i)[0] for i in range(n)])
    assert np.abs(qpos).max() <= 0.1 and np.abs(qpos).max() > 0.099
    np.testing.assert_allclose(qvel.std(0), 0.1, rtol=0.08)
    np.testing.assert_allclose(gym_obs[:, 5:8].std(0), 0.1, rtol=0.08)  # gym's qvel, the same law
    np.testing.assert_allclose(
        np.asarray(jax.vmap(idp_env.state_obs, in_axes=(0, None))(states, params)).mean(0),
        gym_obs.mean(0),
        atol=0.01,
    )
    assert np.all(np.asarray(states.t) == 0)


def test_terminates_when_the_tip_drops_to_one(idp_step, idp_state_at):
    """Lean the poles until the tip's height is below 1: terminated, no alive bonus."""
    params = envs.make_params("idp")
    upright = idp_step(KEY, idp_state_at([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]), jnp.zeros(1), params)
    # The tip at rest upright is at height 1.2, so the best reward is 10 - (1.2 - 2)^2 = 9.36.
    assert not bool(upright.terminated) and float(upright.reward) == pytest.approx(9.36, abs=1e-4)
    fallen = idp_step(KEY, idp_state_at([0.0, 1.2, 0.5], [0.0, 0.0, 0.0]), jnp.zeros(1), params)
    x, y = np.asarray(fallen.state.tip)
    assert y <= 1.0 and bool(fallen.terminated)
    np.testing.assert_allclose(
        float(fallen.reward),
        -(0.01 * x**2 + (y - 2) ** 2)
        - 1e-3 * float(fallen.state.qvel[1]) ** 2
        - 5e-3 * float(fallen.state.qvel[2]) ** 2,
        rtol=1e-5,
    )


def test_episode_truncates_at_1000(idp_step, idp_state_at):
    state = idp_state_at([0.0, 0.0, 0.0], [0.0, 0.0, 0.0]).replace(t=jnp.int32(999))
    ts = idp_step(KEY, state, jnp.zeros(1), envs.make_params("idp"))
    assert bool(ts.truncated) and not bool(ts.terminated) and int(ts.state.t) == 1000


def test_tip_is_mujocos_site(idp_state_at):
    """The picture's geometry (pole_ends) agrees with MuJoCo's tip site."""
    for qpos in ([0.0, 0.0, 0.0], [0.5, 0.3, -0.8], [-0.9, 2.0, 1.0]):
        state = idp_state_at(qpos, [0.0, 0.0, 0.0])
        np.testing.assert_allclose(
            np.asarray(pole_ends(jnp.asarray(qpos, jnp.float32))[2]),
            np.asarray(state.tip),
            atol=1e-5,
        )


# -- the picture -------------------------------------------------------------------------------


def pixels_of(image, colour, tol=40):
    """World (x, z) of the pixels within `tol` of `colour` (0-255) in every channel."""
    img = np.asarray(image).astype(int)
    rows, cols = np.nonzero(np.all(np.abs(img - np.asarray(colour)) < tol, axis=-1))
    pixel = 2 * HALF_EXTENT / SIZE
    return CENTRE[0] - HALF_EXTENT + (cols + 0.5) * pixel, CENTRE[1] + HALF_EXTENT - (
        rows + 0.5
    ) * pixel


@pytest.mark.parametrize(
    "qpos", [[0.0, 0.0, 0.0], [0.6, 0.4, -0.6], [-0.8, -0.7, 0.2], [0.2, np.pi, 0.0]]
)
def test_cart_and_poles_follow_the_state(idp_env, idp_state_at, qpos):
    image = jax.jit(idp_env.render)(idp_state_at(qpos, [0.0, 0.0, 0.0]), envs.make_params("idp"))
    assert image.shape == (SIZE, SIZE, 3) and image.dtype == jnp.uint8
    cart, hinge, tip = (np.asarray(p) for p in pole_ends(jnp.asarray(qpos, jnp.float32)))
    x, z = pixels_of(image, (178, 178, 0))  # the yellow cart
    assert len(x) >= 4 and abs(x.mean() - cart[0]) < 0.06 and abs(z.mean()) < 0.06
    x, z = pixels_of(image, (0, 178, 178))  # the teal poles
    assert len(x) > 20
    points = np.stack([x, z], -1)
    for target in (0.5 * (cart + hinge), hinge, 0.5 * (hinge + tip), 0.9 * tip + 0.1 * hinge):
        assert np.linalg.norm(points - target, axis=-1).min() < 0.06


def test_vmap_render_equals_loop(idp_env, idp_state_at):
    params = envs.make_params("idp")
    rng = np.random.default_rng(3)
    states = [idp_state_at(rng.uniform(-1, 1, 3) * [1, 3, 3], [0.0, 0.0, 0.0]) for _ in range(6)]
    batch = jax.tree.map(lambda *x: jnp.stack(x), *states)
    images = jax.jit(jax.vmap(idp_env.render, in_axes=(0, None)))(batch, params)
    render = jax.jit(idp_env.render)
    for image, state in zip(images, states):
        np.testing.assert_array_equal(np.asarray(image), np.asarray(render(state, params)))
    assert len({np.asarray(im).tobytes() for im in images}) == len(states)


def test_sizes(idp_env):
    assert isinstance(idp_env, InvertedDoublePendulum)
    assert idp_env.state_size == 9 and idp_env.action_size == 1 and idp_env.max_steps == 1000
