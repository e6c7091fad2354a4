"""Playground and Brax tasks as hintsjax envs (envs/adapter.py): the adapter steps exactly as the
task's own env does, keeps truncation apart from termination, draws the model's geoms from the
model's own camera (depth checked against a plane worked out by hand), reads generic hints as
MuJoCo C computes them, loads a user's hint file, and takes its defaults from its table."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import chex
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest
from mujoco import mjx

pytest.importorskip(
    "mujoco_playground",
    reason="the Playground adapter needs the playground extra: pip install -e '.[playground]'",
)

import playground_stub  # noqa: E402
from hintsjax import envs  # noqa: E402
from hintsjax.envs import adapter, render3d  # noqa: E402

CARTPOLE = "playground:CartpoleSwingup"
HINT_FILE = Path(__file__).resolve().parents[1] / "data" / "hints" / "cartpole_hints.py"
STEPS = 4
ACTIONS = jnp.asarray([[1.0], [-0.5], [0.3], [-1.0]], jnp.float32)


@pytest.fixture(scope="module")
def cartpole():
    """The adapted cartpole (state and hint observed) and its own Playground env, with one jitted
    reset and step each, shared by the tests below."""
    env = envs.make(CARTPOLE, "pole_angle+reward+body_velocity:pole_1", ("state", "hint"))
    params = envs.make_params(CARTPOLE)
    return env, params, jax.jit(env.reset), jax.jit(chex.assert_max_traces(env.step, n=1))


def raw(key: jax.Array) -> jax.Array:
    return jax.random.key_data(key)


def test_reset_and_step_match_the_playground_env_own(cartpole):
    env, params, reset, step = cartpole
    own = env.task.env  # Playground's CartpoleSwingup, as registry.load made it
    key = jax.random.key(3)
    ts, ref = reset(key, params), jax.jit(own.reset)(raw(key))
    np.testing.assert_array_equal(ts.state.data.qpos, ref.data.qpos)
    np.testing.assert_array_equal(ts.obs["state"], ref.obs)
    own_step = jax.jit(own.step)
    for i in range(STEPS):
        ts, ref = step(key, ts.state, ACTIONS[i], params), own_step(ref, ACTIONS[i])
        np.testing.assert_array_equal(ts.state.data.qpos, ref.data.qpos)
        np.testing.assert_array_equal(ts.state.data.qvel, ref.data.qvel)
        np.testing.assert_array_equal(ts.obs["state"], ref.obs)
        # the `reward` hint: the last step's
        assert ts.reward == ref.reward and ts.obs["hint"][1] == ref.reward
        assert not ts.terminated and not ts.truncated and int(ts.state.t) == i + 1
    chex.assert_shape(ts.obs["hint"], (1 + 1 + 3,))
    assert ts.reward > 0  # the dense swing-up reward is positive everywhere


def test_an_action_outside_the_range_is_clipped_as_the_actuator_would(cartpole):
    env, params, reset, step = cartpole
    ts = reset(jax.random.key(0), params)
    far, edge = (
        step(jax.random.key(0), ts.state, jnp.asarray([7.0]), params),
        step(jax.random.key(0), ts.state, jnp.ones(1), params),
    )
    np.testing.assert_array_equal(far.state.data.qvel, edge.state.data.qvel)


def test_the_time_limit_truncates_and_a_broken_state_terminates(cartpole):
    env, params, reset, step = cartpole
    assert env.max_steps == 1000  # Playground's episode_length, one task step per control step
    ts = reset(jax.random.key(0), params)
    before = step(jax.random.key(0), ts.state.replace(t=jnp.int32(998)), jnp.zeros(1), params)
    last = step(jax.random.key(0), before.state, jnp.zeros(1), params)
    assert (bool(before.truncated), bool(last.truncated), bool(last.terminated)) == (
        False,
        True,
        False,
    )
    # Playground's cartpole ends an episode only on NaN physics: a termination, not a truncation
    broken = ts.state.replace(
        task=ts.state.task.replace(
            data=ts.state.data.replace(qpos=jnp.full(2, jnp.nan, jnp.float32))
        )
    )
    ended = step(jax.random.key(0), broken, jnp.zeros(1), params)
    assert (bool(ended.terminated), bool(ended.truncated)) == (True, False)
    assert (
        dataclasses.replace(env.task, episode_length=1000, action_repeat=4).episode_length // 4
        == 250
    )


def test_body_velocity_is_mujocos_object_velocity(cartpole):
    """The generic `body_velocity:<body>` hint equals MuJoCo C's mj_objectVelocity of the body
    (its centre of mass; linear part, world frame) at the same qpos and qvel."""
    env, params, reset, _ = cartpole
    # Playground's reset ends in MuJoCo's forward pass, at a small random qvel
    ts = reset(jax.random.key(5), params)
    hint = ts.obs["hint"][2:]
    model = env.mj_model
    data = mujoco.MjData(model)
    data.qpos[:], data.qvel[:] = np.asarray(ts.state.data.qpos), np.asarray(ts.state.data.qvel)
    mujoco.mj_forward(model, data)
    expected = np.zeros(6)
    mujoco.mj_objectVelocity(
        model, data, mujoco.mjtObj.mjOBJ_BODY, model.body("pole_1").id, expected, 0
    )
    np.testing.assert_allclose(hint, expected[3:], rtol=1e-4, atol=1e-7)
    assert (
        np.abs(expected[3:]).max() > 1e-3
        and np.abs(expected[3:] - data.cvel[model.body("pole_1").id, 3:]).max() > 1e-4
    )


def test_the_picture_is_the_models_camera_seeing_the_floor_at_its_hand_worked_depth(cartpole):
    """Variant `fixed` is the model's camera `fixed` (its pose as MuJoCo C computes it); where that
    camera sees the floor, render3d's depth equals the ray's distance to the plane z = floor
    height worked out by hand, and where it sees something else, that is nearer than the floor."""
    env, _, reset, _ = cartpole
    params = envs.make_params(CARTPOLE, "fixed")
    assert envs.variant_names(CARTPOLE)[0] == "fixed"  # the table's camera is the default variant
    state = reset(jax.random.key(1), params).state
    camera = env.camera(state.data, params)
    model = env.mj_model
    data = mujoco.MjData(model)
    data.qpos[:] = np.asarray(state.data.qpos)
    mujoco.mj_forward(model, data)
    cam = model.camera("fixed").id
    np.testing.assert_allclose(camera.pos, data.cam_xpos[cam], atol=1e-5)
    np.testing.assert_allclose(camera.xmat, data.cam_xmat[cam].reshape(3, 3), atol=1e-5)
    assert camera.fovy == pytest.approx(model.cam_fovy[cam])

    size = 32
    scene = render3d.make_scene(model)
    hits = render3d.cast(scene, state.data.geom_xpos, state.data.geom_xmat, camera, size)
    floor = model.geom("floor").id
    # by hand: pixel centres on the image plane at distance 1, rotated into the world
    half = np.tan(np.radians(model.cam_fovy[cam]) / 2)
    c = (np.arange(size) + 0.5) * 2 * half / size - half
    rays = np.stack(np.broadcast_arrays(c[None, :], -c[:, None], -np.ones((size, size))), -1)
    rays /= np.linalg.norm(rays, axis=-1, keepdims=True)
    world = rays @ data.cam_xmat[cam].reshape(3, 3).T
    height = data.geom_xpos[floor, 2] - data.cam_xpos[cam, 2]
    plane = np.where(world[..., 2] < 0, height / np.minimum(world[..., 2], -1e-9), np.inf)
    sees_floor = np.asarray(hits.geom) == floor
    assert sees_floor.sum() > size * size // 4
    np.testing.assert_allclose(np.asarray(hits.distance)[sees_floor], plane[sees_floor], rtol=1e-4)
    other = (np.asarray(hits.geom) >= 0) & ~sees_floor
    assert other.any() and np.all(np.asarray(hits.distance)[other] <= plane[other] * (1 + 1e-5))
    picture = jax.jit(env.render)(state, params)
    chex.assert_shape(picture, (64, 64, 3))
    np.testing.assert_array_equal(
        picture, render3d.render(scene, state.data.geom_xpos, state.data.geom_xmat, camera, 64)
    )


def test_a_mesh_geom_is_refused_in_one_line_naming_it_and_the_model():
    mjcf = """<mujoco><asset><mesh name="tetra" vertex="0 0 0 1 0 0 0 1 0 0 0 1"/></asset>
      <worldbody><geom name="floor" type="plane" size="1 1 .1"/><body><freejoint/>
      <geom name="rock" type="mesh" mesh="tetra"/></body></worldbody></mujoco>"""
    task = adapter.Task("test:meshy", None, mujoco.MjModel.from_xml_string(mjcf), "data", 10)
    with pytest.raises(adapter.EnvUnavailable) as error:
        adapter.make_scene(task)
    message = str(error.value)
    assert "test:meshy" in message and "'rock' is a mesh" in message and "\n" not in message


def test_a_hint_file_loads_and_its_hints_jit(cartpole):
    env, params, reset, _ = cartpole
    module = envs.load_hints(str(HINT_FILE))
    assert envs.load_hints(str(HINT_FILE)) == module  # imported once per process
    hint = envs.make_hint(CARTPOLE, "cart_position+tip_height")
    state = reset(jax.random.key(2), params).state
    values = jax.jit(chex.assert_max_traces(hint.__call__, n=1))(state, params)
    chex.assert_shape(values, (2,))
    np.testing.assert_allclose(values, [state.data.qpos[0], np.cos(state.data.qpos[1])], rtol=1e-6)
    envs.check_hint_shapes(hint, state, params)
    with pytest.raises(envs.HintFileError, match=r"returns shape \(2,\), not the \(1,\)"):
        envs.check_hint_shapes(envs.make_hint(CARTPOLE, "two_for_one"), state, params)


def test_an_adapted_env_takes_its_defaults_from_the_table_or_the_fallback():
    from hintsjax.envs import playground
    from hintsjax.settings.layers import run_config

    cfg = run_config({"env": CARTPOLE})
    assert (
        cfg.hint == "pole_angle"
        and cfg.ppo.total_env_steps == playground.PIXEL_PPO["total_env_steps"]
    )
    assert cfg.ppo.num_envs == 128 and cfg.ppo.epochs == 4
    other = run_config({"env": "playground:PendulumSwingup", "agent": "ppo_state"})
    assert (
        other.hint == playground.FALLBACK.hint == "reward"
        and envs.variant_names("playground:PendulumSwingup")[0] == "tracking"
    )


VISION = "playground:CartpoleBalance:vision"


def playground_vision_env(monkeypatch):
    """Playground's own CartpoleBalance with `vision=True`, its renderer (MuJoCo Warp's, GPU only)
    replaced by blank pictures: its physics, reward and ends are Playground's code, the oracle."""
    from mujoco_playground import registry

    playground_stub.blank_renderer(monkeypatch)
    return registry.load("CartpoleBalance", config_overrides={"vision": True, "impl": "jax"})


def test_the_vision_configuration_pays_and_ends_as_playgrounds_vision_task(monkeypatch):
    """`playground:CartpoleBalance:vision` steps, pays and ends exactly as Playground's
    CartpoleBalance configured for pixels (its renderer aside), on random actions and from states
    past each of its two limits; episodes of 250 steps at Playground's 0.01 s a step."""
    own = playground_vision_env(monkeypatch)
    env = envs.make(VISION, "pole_angle", ("state", "hint"))
    params = envs.make_params(VISION)
    assert env.max_steps == own._config.episode_length == 250 and params.camera == "fixed"
    assert env.task.env.env.n_substeps == own.n_substeps == 1  # its config's ctrl_dt says 0.02
    key = jax.random.key(1)
    ts, ref = jax.jit(env.reset)(key, params), jax.jit(own.reset)(raw(key))
    step, own_step = jax.jit(chex.assert_max_traces(env.step, n=1)), jax.jit(own.step)
    actions = jax.random.uniform(jax.random.key(2), (STEPS, 1), minval=-1.0, maxval=1.0)
    for action in actions:
        ts, ref = step(key, ts.state, action, params), own_step(ref, action)
        np.testing.assert_array_equal(ts.state.data.qpos, ref.data.qpos)
        assert ts.reward == ref.reward and ts.state.task.metrics == ref.metrics
        assert not ts.terminated and not ref.done
    np.testing.assert_array_equal(ts.obs["hint"], ts.state.data.qpos[1:2])
    data = ts.state.data
    for qpos in ([0.1, 1.6], [3.05, 0.0]):  # the pole past horizontal; the cart past 3 m
        state = ts.state.replace(
            task=ts.state.task.replace(data=data.replace(qpos=jnp.asarray(qpos)))
        )
        ended = step(key, state, jnp.zeros(1), params)
        ref_ended = own_step(
            ref.replace(data=ref.data.replace(qpos=jnp.asarray(qpos))), jnp.zeros(1)
        )
        assert bool(ended.terminated) and not ended.truncated and bool(ref_ended.done)
        assert ended.reward == ref_ended.reward


def test_a_configuration_is_refused_for_a_task_without_it_or_by_another_name():
    with pytest.raises(envs.ChoiceError, match="unknown configuration of CartpoleBalance 'pixels'"
                       "; valid choices: vision"):  # fmt: skip
        envs.make("playground:CartpoleBalance:pixels")
    with pytest.raises(envs.ChoiceError, match="'CheetahRun'; valid choices: CartpoleBalance, "
                       "CartpoleSwingup"):  # fmt: skip
        envs.make("playground:CheetahRun:vision")


def test_a_brax_env_is_adapted_with_brax_s_own_sizes_and_names():
    env = envs.make("brax:hopper", "reward", ("state", "hint"))
    own = env.task.env
    # Brax hopper: qpos[1:] and qvel, three motors
    assert env.state_size == 11 and env.action_size == own.action_size == 3
    # Brax's MJX backend, whose data the picture reads
    assert isinstance(adapter.reset_shapes(env.task).pipeline_state, mjx.Data)
    with pytest.raises(
        envs.ChoiceError,
        match="unknown Brax env 'hoppr'; valid choices: ant, fast, halfcheetah, hopper",
    ):
        envs.make("brax:hoppr")


@pytest.mark.slow
def test_a_brax_env_steps_as_brax_does():
    """brax:hopper on Brax's MJX backend: the adapter's reset and steps equal Brax's own, and
    Brax's `done` (the hopper fell) is a termination."""
    env = envs.make("brax:hopper", "reward", ("state", "hint"))
    params = envs.make_params("brax:hopper")
    key = jax.random.key(4)
    ts, ref = jax.jit(env.reset)(key, params), jax.jit(env.task.env.reset)(raw(key))
    step, own_step = jax.jit(env.step), jax.jit(env.task.env.step)
    for i in range(2):
        action = jnp.full(env.action_size, 0.5 * (-1) ** i)
        ts, ref = step(key, ts.state, action, params), own_step(ref, action)
        np.testing.assert_array_equal(ts.obs["state"], ref.obs)
        assert ts.reward == ref.reward and bool(ts.terminated) == bool(ref.done)
    assert env.max_steps == 1000 and "sensor:" not in " ".join(envs.hint_names("brax:hopper"))
