"""The env protocol: time limit, AutoReset, registry errors, observation keys (SPEC 2 and 8)."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.envs.core import EpisodeState
from hintsjax.envs.pendulum import PendulumState


S = PendulumState.at


@pytest.fixture(scope="module")
def auto(env):
    wrapped = envs.AutoReset(env)
    return wrapped, jax.jit(wrapped.reset), jax.jit(wrapped.step)


def expected_obs(state, render, params):
    """The composite-hint env's observation of `state`, computed independently of the env."""
    theta, dtheta, goal = float(state.theta), float(state.dtheta), float(state.goal)
    return {
        "pixels": np.asarray(render(state, params)),
        "state": np.array([np.cos(theta), np.sin(theta), dtheta], np.float32),
        "hint": np.array([dtheta, np.cos(goal) - np.cos(theta)], np.float32),
    }


def assert_obs_equal(a, b, atol=1e-6):
    assert set(a) == set(b)
    for k in a:
        if k == "pixels":
            np.testing.assert_array_equal(np.asarray(a[k]), np.asarray(b[k]), err_msg=k)
        else:
            np.testing.assert_allclose(
                np.asarray(a[k]), np.asarray(b[k]), rtol=0, atol=atol, err_msg=k
            )


# -- time limit --------------------------------------------------------------------------------


def test_truncates_exactly_at_step_200(step, params):
    """Pendulum never terminates; `truncated` is set on the step that reaches t = 200, only."""
    state = S(np.pi, 0.5)
    rng = np.random.default_rng(0)
    truncated_at = []
    for i in range(1, 201):
        ts = step(jax.random.key(i), state, jnp.array([rng.uniform(-2, 2)], jnp.float32), params)
        state = ts.state
        assert int(state.t) == i
        assert not bool(ts.terminated)
        assert ts.truncated.dtype == jnp.bool_ and ts.terminated.dtype == jnp.bool_
        if bool(ts.truncated):
            truncated_at.append(i)
    assert truncated_at == [200]


def test_truncation_depends_on_t_only(step, params):
    for t, expected in ((0, False), (198, False), (199, True)):
        ts = step(jax.random.key(0), S(0.0, 0.0, t=t), jnp.array([0.0]), params)
        assert bool(ts.truncated) is expected and not bool(ts.terminated)


# -- AutoReset ---------------------------------------------------------------------------------


def test_autoreset_full_episode(auto, step, render, params):
    """Across a whole episode: stats accumulate, and the ending step resets with final_obs kept."""
    wrapped, reset, astep = auto
    ts = reset(jax.random.key(0), params)
    assert int(ts.state.env_state.t) == 0
    assert float(ts.info["episode_return"]) == 0.0 and int(ts.info["episode_length"]) == 0
    assert_obs_equal(ts.obs, expected_obs(ts.state.env_state, render, params))
    assert_obs_equal(ts.final_obs, ts.obs, atol=0)

    rng = np.random.default_rng(1)
    key = jax.random.key(1)
    rewards = []
    for i in range(1, 201):
        key, k = jax.random.split(key)
        action = jnp.array([rng.uniform(-2.5, 2.5)], jnp.float32)
        prev = ts
        ts = astep(k, prev.state, action, params)
        rewards.append(float(ts.reward))
        if i < 200:
            assert not bool(ts.terminated | ts.truncated)
            assert int(ts.state.env_state.t) == i
            assert_obs_equal(ts.final_obs, ts.obs, atol=0)
            assert int(ts.info["episode_length"]) == i
            np.testing.assert_allclose(float(ts.info["episode_return"]), sum(rewards), rtol=1e-5)

    # The ending step (t reaches 200): truncated, not terminated.
    assert bool(ts.truncated) and not bool(ts.terminated)
    # final_obs is the observation of the state the episode ended in: what the plain env returns.
    step_key, _ = jax.random.split(k)
    plain = step(step_key, prev.state.env_state, action, params)
    assert bool(plain.truncated) and int(plain.state.t) == 200
    assert_obs_equal(ts.final_obs, plain.obs, atol=0)
    np.testing.assert_allclose(float(ts.reward), float(plain.reward), rtol=1e-6)
    # obs is a fresh episode's first observation; the state is that fresh state, at t = 0.
    fresh = ts.state.env_state
    assert int(fresh.t) == 0
    assert abs(float(fresh.theta)) <= np.pi and abs(float(fresh.dtheta)) <= 1.0
    assert_obs_equal(ts.obs, expected_obs(fresh, render, params))
    assert not np.array_equal(np.asarray(ts.obs["pixels"]), np.asarray(ts.final_obs["pixels"]))
    assert not np.allclose(np.asarray(ts.obs["state"]), np.asarray(ts.final_obs["state"]))
    # info carries the finished episode's statistics; the running ones restart at zero.
    assert int(ts.info["episode_length"]) == 200
    np.testing.assert_allclose(float(ts.info["episode_return"]), sum(rewards), rtol=1e-5)
    assert float(ts.state.episode_return) == 0.0 and int(ts.state.episode_length) == 0

    # The next step belongs to the new episode.
    nxt = astep(jax.random.key(99), ts.state, jnp.array([0.5]), params)
    assert int(nxt.state.env_state.t) == 1
    assert int(nxt.info["episode_length"]) == 1
    np.testing.assert_allclose(float(nxt.info["episode_return"]), float(nxt.reward), rtol=1e-6)
    assert not bool(nxt.truncated)


def ending_state(goal):
    """An AutoReset state one step before the time limit."""
    env_state = S(0.3, 0.5, goal=goal, t=199)
    return EpisodeState(env_state, jnp.float32(-5.0), jnp.int32(199))


def test_autoreset_fresh_start_depends_on_reset_key(auto, swingto_params):
    """swingto: each reset key gives a different fresh state and a different fresh goal."""
    _, _, astep = auto
    state = ending_state(goal=0.7)
    outs = [astep(jax.random.key(s), state, jnp.array([1.0]), swingto_params) for s in range(8)]
    thetas = [float(o.state.env_state.theta) for o in outs]
    dthetas = [float(o.state.env_state.dtheta) for o in outs]
    goals = [float(o.state.env_state.goal) for o in outs]
    for o in outs:
        assert bool(o.truncated) and int(o.state.env_state.t) == 0
        np.testing.assert_allclose(
            float(o.info["episode_return"]), -5.0 + float(o.reward), rtol=1e-6
        )
        assert int(o.info["episode_length"]) == 200
        # The ended episode is the same whatever the reset key.
        assert_obs_equal(o.final_obs, outs[0].final_obs, atol=0)
        # ... and it is observed with its own goal (0.7), not the fresh one.
        cos_theta = float(o.final_obs["state"][0])
        np.testing.assert_allclose(
            float(o.final_obs["hint"][1]), np.cos(0.7) - cos_theta, atol=1e-6
        )
    assert len(set(thetas)) == 8 and len(set(dthetas)) == 8 and len(set(goals)) == 8
    assert all(abs(g) <= np.pi / 2 for g in goals) and 0.7 not in goals
    assert all(abs(th) <= np.pi for th in thetas) and all(abs(d) <= 1.0 for d in dthetas)
    # The fresh goal is part of the fresh observation (the composite hint's goal distance).
    for o, th, g in zip(outs, thetas, goals):
        np.testing.assert_allclose(float(o.obs["hint"][1]), np.cos(g) - np.cos(th), atol=1e-6)


def test_autoreset_starts_from_a_given_fresh_start(auto, swingto_params):
    """`fresh` (AutoReset.fresh_start) is where an ending episode goes on; other steps ignore it."""
    wrapped, _, _ = auto
    step = jax.jit(wrapped.step)
    fresh = wrapped.fresh_start(jax.random.key(7), swingto_params)
    key, action = jax.random.key(3), jnp.array([1.0])
    ended = step(key, ending_state(goal=0.7), action, swingto_params, fresh)
    assert bool(ended.truncated) and int(ended.info["episode_length"]) == 200
    assert_obs_equal(ended.obs, fresh.obs, atol=0)
    for a, b in zip(jax.tree.leaves(ended.state.env_state), jax.tree.leaves(fresh.state)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    assert_obs_equal(
        ended.final_obs, step(key, ending_state(goal=0.7), action, swingto_params).final_obs, atol=0
    )
    running = EpisodeState(S(0.3, 0.5, goal=0.7, t=50), jnp.float32(-5.0), jnp.int32(50))
    given, drawn = (
        step(key, running, action, swingto_params, fresh),
        step(key, running, action, swingto_params),
    )
    assert_obs_equal(given.obs, drawn.obs, atol=0)
    assert int(given.state.env_state.t) == 51


def test_autoreset_swingup_fresh_goal_is_upright(auto, params):
    _, _, astep = auto
    outs = [
        astep(jax.random.key(s), ending_state(goal=0.0), jnp.array([0.0]), params) for s in range(3)
    ]
    assert all(float(o.state.env_state.goal) == 0.0 for o in outs)
    assert len({float(o.state.env_state.theta) for o in outs}) == 3


class CountedStarts:
    """An env whose every start (reset) adds its batch's rows to `rows` as it runs."""

    def __init__(self, env):
        self.env, self.rows = env, []

    def __getattr__(self, name):
        return getattr(self.env, name)

    def reset(self, key, params):
        jax.debug.callback(lambda k: self.rows.append(max(1, np.size(k) // 2)), key)
        return self.env.reset(key, params)


@pytest.mark.parametrize("ending", [(), (1,), (0, 3, 4, 6, 7), tuple(range(8))])
def test_step_ended_is_a_vmapped_step_drawing_only_the_ended_starts(env, swingto_params, ending):
    """AutoReset.step_ended equals `step` vmapped over 8 envs, leaf for leaf (each ended env
    starts where its own key puts it), while drawing starts in chunks of 2 envs only for as
    many chunks as episodes ended (none where none ended)."""
    counted = CountedStarts(env)
    auto = envs.AutoReset(counted)
    t = np.full(8, 50)
    t[list(ending)] = 199
    states = jax.vmap(lambda ti, g: EpisodeState(S(0.3, 0.5, goal=g, t=ti), 1.0, ti))(
        jnp.asarray(t), jnp.linspace(-1.0, 1.0, 8)
    )
    keys = jax.random.split(jax.random.key(5), 8)
    action = jnp.linspace(-2.0, 2.0, 8)[:, None]
    want = jax.jit(jax.vmap(auto.step, in_axes=(0, 0, 0, None)))(
        keys, states, action, swingto_params
    )
    jax.effects_barrier()
    counted.rows.clear()
    got = jax.jit(lambda *a: auto.step_ended(*a, swingto_params, 2))(keys, states, action)
    jax.effects_barrier()
    assert sum(counted.rows) == 2 * -(-len(ending) // 2)
    assert jax.tree.structure(got) == jax.tree.structure(want)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want)):  # two programs: float ulps
        assert a.dtype == b.dtype and a.shape == b.shape
        np.testing.assert_allclose(np.asarray(a), np.asarray(b), rtol=1e-6, atol=1e-6)
    assert np.array_equal(np.asarray(got.truncated), t == 199)


@pytest.mark.parametrize("asked", [(), (4,), (0, 5, 11), (1, 2, 3, 6, 7, 8, 9), tuple(range(12))])
def test_rows_where_runs_only_the_asked_rows_and_in_as_few_chunks(asked):
    """rows_where equals the whole batch's `fn` where asked and zeros elsewhere, every leaf of
    its output, with `fn` run on chunks of 3 rows: as many chunks as the asked rows fill (none
    for none), each row's result its own."""
    xs = {"x": jnp.arange(12 * 2, dtype=jnp.float32).reshape(12, 2) ** 1.5, "y": jnp.ones(12)}
    where = jnp.zeros(12, bool).at[jnp.asarray(asked, jnp.int32)].set(True)

    def fn(rows):
        value = rows["x"][:, 0] - 2.0 * rows["x"][:, 1] + rows["y"]
        return {"value": value, "pair": jnp.stack([value, -value], 1).astype(jnp.int32)}

    calls = []

    def counted(rows):
        jax.debug.callback(lambda: calls.append(1))
        return fn(rows)

    got = jax.jit(lambda o, w: envs.rows_where(counted, o, w, 3))(xs, where)
    jax.effects_barrier()
    whole = fn(xs)
    np.testing.assert_array_equal(got["value"], jnp.where(where, whole["value"], 0.0))
    np.testing.assert_array_equal(got["pair"], jnp.where(where[:, None], whole["pair"], 0))
    assert got["pair"].dtype == jnp.int32
    assert len(calls) == -(-len(asked) // 3)


# -- registry and observation keys -------------------------------------------------------------


def test_unknown_env_names_valid_envs():
    with pytest.raises(envs.ChoiceError) as err:
        envs.make("nope")
    assert "pendulum" in str(err.value) and "nope" in str(err.value)
    assert isinstance(err.value, ValueError)
    with pytest.raises(envs.ChoiceError, match="pendulum"):
        envs.make_params("nope")


def test_unknown_variant_names_valid_variants():
    with pytest.raises(envs.ChoiceError) as err:
        envs.make_params("pendulum", "bad")
    message = str(err.value)
    assert "swingup" in message and "swingto" in message and "bad" in message
    assert envs.variant_names("pendulum") == ["swingup", "swingto"]
    assert envs.make_params("pendulum") == envs.make_params("pendulum", "swingup")
    assert "pendulum" in envs.env_names()


def test_unknown_hint_in_make_names_valid_hints():
    with pytest.raises(envs.ChoiceError) as err:
        envs.make("pendulum", hint="nope")
    for name in envs.hint_names("pendulum"):
        assert name in str(err.value)


def test_observe_selects_keys(params):
    for observe in (("state",), ("pixels", "hint"), envs.OBS_KEYS):
        env = envs.make("pendulum", hint="goal_distance", observe=observe)
        ts = jax.eval_shape(env.reset, jax.random.key(0), params)
        assert set(ts.obs) == set(observe)
        shapes = {"pixels": (64, 64, 3), "state": (3,), "hint": (1,)}
        for k in observe:
            assert ts.obs[k].shape == shapes[k]
    with pytest.raises(ValueError, match="valid"):
        envs.make("pendulum", observe=("pixels", "depth"))


def test_no_hint_is_empty(params):
    env = envs.make("pendulum")
    ts = jax.eval_shape(env.reset, jax.random.key(0), params)
    assert ts.obs["hint"].shape == (0,) and env.hint.dim == 0
    assert ts.obs["pixels"].dtype == jnp.uint8 and ts.obs["state"].dtype == jnp.float32


def test_reset_outputs(auto, params):
    _, reset, _ = auto
    a, b = reset(jax.random.key(0), params), reset(jax.random.key(1), params)
    for ts in (a, b):
        assert float(ts.reward) == 0.0 and not bool(ts.terminated) and not bool(ts.truncated)
        assert int(ts.state.env_state.t) == 0
    assert float(a.state.env_state.theta) != float(b.state.env_state.theta)
    again = reset(jax.random.key(0), params)
    assert float(again.state.env_state.theta) == float(a.state.env_state.theta)
