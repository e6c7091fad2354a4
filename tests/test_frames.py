"""The last pictures side by side (`frames=`, envs/frames.py): what the stack holds, where an
episode starts, what passes through unchanged, and that an agent learns from it what one picture
cannot show (tests/flash_env.py: the cue is in the previous picture only)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import flash_env
from test_learning import LEARN_PPO  # the cue task's budget: 12 updates of 256 steps
from hintsjax import envs
from hintsjax.algorithms import group, ppo
from hintsjax.envs.frames import FrameStack, grey
from hintsjax.settings.layers import run_config
from hintsjax.system import memory
from hintsjax.system.errors import UsageError


@pytest.fixture(scope="module")
def pendulum():
    inner = envs.make("pendulum", "composite", ("pixels", "state", "hint"), image_size=36)
    return inner, FrameStack(inner, 3), inner.default_params()


def test_the_stack_holds_the_last_pictures_oldest_first(pendulum):
    inner, stacked, params = pendulum
    key = jax.random.key(3)
    ts, ref = stacked.reset(key, params), inner.reset(key, params)
    pictures = [np.asarray(ref.obs["pixels"])]
    for i in range(4):
        k = jax.random.fold_in(key, i)
        action = jax.random.uniform(jax.random.fold_in(k, 1), (1,), minval=-2, maxval=2)
        ts, ref = (
            stacked.step(k, ts.state, action, params),
            inner.step(k, ref.state, action, params),
        )
        pictures.append(np.asarray(ref.obs["pixels"]))
        shown = np.asarray(ts.obs["pixels"])
        assert shown.shape == (36, 36, 9) and shown.dtype == np.uint8
        for j, back in enumerate((2, 1, 0)):  # channels 3j..3j+2: the picture `back` steps ago
            np.testing.assert_array_equal(
                shown[..., 3 * j : 3 * j + 3], pictures[max(0, i + 1 - back)]
            )
        # the rest is the wrapped env's
        for name in ("state", "hint"):
            np.testing.assert_array_equal(ts.obs[name], ref.obs[name])
        np.testing.assert_array_equal(ts.reward, ref.reward)
        assert int(ts.state.t) == int(ref.state.t) == i + 1
        np.testing.assert_array_equal(stacked.render(ts.state, params), pictures[-1])
    assert len({p.tobytes() for p in pictures}) > 1  # the pendulum moved: the check can tell


def test_grey_is_the_mean_of_the_channels_rounded():
    rgb = jnp.array([[[10, 20, 33], [0, 0, 1], [255, 255, 254], [200, 0, 100]]], jnp.uint8)
    out = grey(rgb)
    assert out.shape == (1, 4, 1) and out.dtype == jnp.uint8
    np.testing.assert_array_equal(out[0, :, 0], [21, 0, 255, 100])


@pytest.mark.parametrize("k", [1, 3])
def test_a_grey_stack_holds_one_channel_a_picture(pendulum, k):
    """colour=grey: the last k pictures, each its channels' mean, oldest first; a video still
    gets an RGB picture (grey in each channel)."""
    inner, _, params = pendulum
    stacked = FrameStack(inner, k, "grey")
    key = jax.random.key(4)
    ts, ref = stacked.reset(key, params), inner.reset(key, params)
    pictures = [np.asarray(grey(ref.obs["pixels"]))]
    for i in range(3):
        k_step = jax.random.fold_in(key, i)
        ts = stacked.step(k_step, ts.state, jnp.array([1.5]), params)
        ref = inner.step(k_step, ref.state, jnp.array([1.5]), params)
        pictures.append(np.asarray(grey(ref.obs["pixels"])))
        shown = np.asarray(ts.obs["pixels"])
        assert shown.shape == (36, 36, k) and shown.dtype == np.uint8
        for j in range(k):  # channel j: the picture k - 1 - j steps ago
            back = k - 1 - j
            np.testing.assert_array_equal(shown[..., j : j + 1], pictures[max(0, i + 1 - back)])
        video = np.asarray(stacked.render(ts.state, params))
        assert video.shape == (36, 36, 3)
        np.testing.assert_array_equal(video, np.repeat(pictures[-1], 3, axis=-1))
    assert len({p.tobytes() for p in pictures}) > 1


def test_a_new_episode_starts_from_its_first_picture_repeated():
    env = envs.AutoReset(
        FrameStack(flash_env.FlashEnv(envs.make_hint("flash", "none"), ("pixels",)), 2)
    )
    params = env.default_params()
    ts = env.reset(jax.random.key(0), params)
    first = np.asarray(ts.obs["pixels"])
    np.testing.assert_array_equal(first[..., :3], first[..., 3:])
    assert int(first[0, 0, 0]) in (0, 255)
    ts = env.step(jax.random.key(1), ts.state, jnp.zeros(1), params)
    acting = np.asarray(ts.obs["pixels"])  # what the second action sees: the cue's, then grey
    assert int(acting[0, 0, 0]) == int(first[0, 0, 0]) and int(acting[0, 0, 3]) == flash_env.GREY
    ts = env.step(jax.random.key(2), ts.state, jnp.zeros(1), params)
    assert bool(ts.truncated)
    ended = np.asarray(ts.final_obs["pixels"])  # the episode's last two pictures, both grey
    assert (ended == flash_env.GREY).all()
    fresh = np.asarray(ts.obs["pixels"])
    np.testing.assert_array_equal(fresh[..., :3], fresh[..., 3:])
    assert int(fresh[0, 0, 0]) in (0, 255)


def test_vmapped_stacks_equal_one_at_a_time(pendulum):
    _, stacked, params = pendulum
    keys = jax.random.split(jax.random.key(7), 3)
    actions = jnp.array([[-1.0], [0.5], [2.0]])

    def two_steps(key, action):
        ts = stacked.reset(key, params)
        ts = stacked.step(key, ts.state, action, params)
        return stacked.step(jax.random.fold_in(key, 1), ts.state, action, params).obs["pixels"]

    batched = jax.vmap(two_steps)(keys, actions)
    for i in range(3):
        np.testing.assert_array_equal(batched[i], two_steps(keys[i], actions[i]))


def test_a_runs_frames_reach_its_env_memory_bound_and_group():
    cfg = run_config({"env": "pendulum", "agent": "ppo_rgb", "frames": 3, "image_size": 40})
    for env in (cfg.make_env(), cfg.make_env(deploy=True)):
        assert isinstance(env, FrameStack) and env.k == 3
    assert memory.picture_bytes(cfg) == 3 * 3 * 40 * 40
    assert not isinstance(run_config({"env": "pendulum"}).make_env(), FrameStack)
    one = run_config({"env": "pendulum", "agent": "ppo_rgb", "image_size": 40})
    with pytest.raises(UsageError, match="frames"):
        group.check_group([cfg, one])
    for k in (1, 2):  # grey: one channel a picture, one picture too
        values = {"env": "pendulum", "agent": "ppo_rgb", "frames": k, "image_size": 40}
        grey_cfg = run_config({**values, "colour": "grey"})
        env = grey_cfg.make_env()
        assert isinstance(env, FrameStack) and (env.k, env.colour) == (k, "grey")
        assert memory.picture_bytes(grey_cfg) == k * 40 * 40
        pixels = env.reset(jax.random.key(0), grey_cfg.task_params(None)).obs["pixels"]
        assert pixels.shape == (40, 40, k)
    with pytest.raises(UsageError, match="colour"):
        group.check_group([run_config(values), grey_cfg])


@pytest.mark.parametrize("frames, colour", [(1, "rgb"), (2, "rgb"), (2, "grey")])
def test_two_pictures_show_what_one_cannot(frames, colour):
    values = dict(env="flash", agent="ppo_rgb", seeds=1, frames=frames, colour=colour)
    cfg = run_config({**values, "ppo": LEARN_PPO})
    _, metrics = jax.jit(ppo.make_trainer(cfg).train)(jax.random.key(0))
    final = float(np.asarray(metrics["episode_return"])[-3:].mean())
    if frames == 1:  # blind to the cue when it acts on it: E[-(a - c)^2] <= -1
        assert final < -0.7, final
    else:
        assert final > -0.3, final
