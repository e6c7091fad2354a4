"""The `physics` setting (envs/physics.py): how auto, jax and warp resolve and fail, the vmap
folding that sizes MJX-Warp's buffers, and MJX-Warp against MuJoCo C (Gymnasium) and against
MJX's JAX solver. Warp runs here through its CPU path (warp-lang is in the test extra), where
its kernels compile once into Warp's kernel cache (~/.cache/warp: about a minute the first time
on 2 cores); the same tests run on a GPU (tests/envs/test_physics.py under `device`)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest
import xla_tier  # tests/xla_tier.py

from gym_parity import KEY, Compiled, parity  # tests/envs/gym_parity.py
from hintsjax import envs
from hintsjax.envs import physics
from hintsjax.envs.ant import Ant
from hintsjax.system.errors import UsageError
from hintsjax.settings.layers import run_config

warp_lang = pytest.mark.skipif(
    not physics.warp_installed(), reason="warp-lang not installed (pip install -e '.[gpu]')"
)

# The default tier's programs compile at LLVM's cheapest level (tests/conftest.py); Warp's CPU
# kernels here too (warp.config.optimization_level 0, not Warp's -O2): with Warp's kernel cache
# cold, the file took 118 s at -O2 and 96 s at 0, alone (2026-11-29, 2 cores). The slow tier keeps
# Warp's -O2.
KERNELS_AT_O0 = xla_tier.at_o0() and jax.default_backend() == "cpu"


@pytest.fixture(scope="module", autouse=True)
def warp_kernels_at_o0():
    """Warp's CPU kernels at -O0 while this file runs in the default tier (its subprocess sets the
    same)."""
    if not (KERNELS_AT_O0 and physics.warp_installed()):
        yield
        return
    import warp

    before, warp.config.optimization_level = warp.config.optimization_level, 0
    yield
    warp.config.optimization_level = before


def test_auto_picks_warp_only_on_an_nvidia_gpu_with_warp_lang(monkeypatch):
    monkeypatch.setattr(physics, "warp_installed", lambda: True)
    assert physics.resolve("auto", "gpu") == "warp"
    assert physics.resolve("auto", "cpu") == "jax"  # CPU runs and the tests stay bit-reproducible
    # the pendulum and the acrobot
    assert physics.resolve("auto", "gpu", warp_by_default=False) == "jax"
    assert physics.resolve("jax", "gpu") == "jax" and physics.resolve("warp", "cpu") == "warp"
    monkeypatch.setattr(physics, "warp_installed", lambda: False)
    assert physics.resolve("auto", "gpu") == "jax"


def test_auto_gives_warp_to_the_locomotion_envs_on_an_nvidia_gpu(monkeypatch):
    """On one NVIDIA GPU with warp-lang, auto steps the locomotion envs with MJX-Warp
    (envs/locomotion.py `warp_by_default`) and keeps JAX's solver for the classic-control models
    and every env without a MuJoCo model; on several GPUs (or processes) it keeps JAX, which spreads
    the seeds over them; physics=warp asks for Warp on any MJCF env."""
    monkeypatch.setattr(physics, "warp_installed", lambda: True)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    monkeypatch.setattr(jax, "device_count", lambda: 1)
    warp = {name for name in envs.env_names() if envs.resolve_physics(name) == "warp"}
    assert warp == {"halfcheetah", "ant", "ant_fast", "humanoid"}
    assert {envs.resolve_physics(name, "warp") for name in envs.mjx_env_names()} == {"warp"}
    assert set(envs.mjx_env_names()) == {
        "pendulum",
        "acrobot",
        "idp",
        "halfcheetah",
        "ant",
        "ant_fast",
        "humanoid",
    }
    # several GPUs (or processes): JAX spreads the seeds
    monkeypatch.setattr(jax, "device_count", lambda: 2)
    assert {envs.resolve_physics(name) for name in envs.env_names()} == {"jax"}
    assert envs.resolve_physics("ant", "warp") == "warp"
    monkeypatch.setattr(jax, "device_count", lambda: 1)
    monkeypatch.setattr(jax, "default_backend", lambda: "cpu")
    # CPU runs stay reproducible
    assert {envs.resolve_physics(name) for name in envs.env_names()} == {"jax"}


def test_physics_warp_without_warp_lang_is_one_line_naming_the_gpu_extra(
    monkeypatch, tmp_path, capsys
):
    from hintsjax import run

    monkeypatch.setattr(physics, "warp_installed", lambda: False)
    assert (
        run.main_from_values({"env": "ant", "physics": "warp", "out_dir": str(tmp_path / "runs")})
        == 2
    )
    lines = capsys.readouterr().err.strip().splitlines()
    assert (
        len(lines) == 1 and "physics=warp needs warp-lang: pip install -e '.[gpu]'" in lines[0]
    ), lines
    assert not (tmp_path / "runs").exists()
    with pytest.raises(physics.PhysicsUnavailable, match="gpu"):
        envs.make("ant", physics="warp")


def test_the_config_keeps_the_physics_a_run_is_stepped_with():
    """auto is resolved when the config is built (jax on a CPU; on an NVIDIA GPU, warp for the
    locomotion envs), so config.yaml and eval.json say what stepped the run, and a
    resumed run keeps it; a config saved before the setting existed was stepped by JAX."""
    assert run_config({"env": "ant"}).physics == physics.resolve(
        "auto", jax.default_backend(), Ant.warp_by_default
    )
    if jax.default_backend() == "cpu":
        assert run_config({"env": "ant"}).physics == "jax"
    assert run_config({"env": "pendulum"}).physics == "jax"
    assert run_config({"env": "car_racing", "physics": "jax"}).physics == "jax"
    saved = {"env": "ant", "hint": "speed"}
    assert run_config({**saved, "physics": "warp"}, resolved=True).physics == "warp"
    assert run_config(saved, resolved=True).physics == "jax"
    with pytest.raises(UsageError, match="valid choices: auto, jax, warp"):
        run_config({"env": "ant", "physics": "fast"})


def test_collapse_vmaps_runs_the_body_once_on_every_vmapped_axis_flattened():
    seen = []

    def body(x, y):
        seen.append(x.shape)
        return {"sum": x.sum(-1, keepdims=True) + y, "twice": 2 * x}

    f = physics.collapse_vmaps(body)
    x, y = jnp.arange(24.0).reshape(2, 3, 4), jnp.ones((3, 1))
    batched = jax.jit(jax.vmap(jax.vmap(f), in_axes=(0, None)))  # y unbatched over the outer axis
    out = batched(x, y)
    assert seen[-1] == (2, 3, 4)  # both axes folded into the arguments (earlier calls: shapes only)
    products = [
        line for line in batched.lower(x, y).as_text().splitlines() if "stablehlo.multiply" in line
    ]
    # the program runs the body once
    assert len(products) == 1 and "tensor<2x3x4xf32>" in products[0]
    for i in range(2):
        for j in range(3):
            np.testing.assert_array_equal(out["sum"][i, j], x[i, j].sum(keepdims=True) + 1)
    np.testing.assert_array_equal(out["twice"], 2 * x)
    # unbatched: the body as it is
    np.testing.assert_array_equal(f(x[0, 0], y[0])["twice"], 2 * x[0, 0])


def test_capacities_are_the_contacts_and_rows_the_collision_pairs_can_make():
    assert physics.capacities(Ant.make_mj_model()) == (25, 108)


# -- MJX-Warp ------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def warp_cheetah() -> Compiled:
    return Compiled(envs.make("halfcheetah", "none", ("state",), physics="warp"))


@pytest.fixture(scope="module")
def warp_ant() -> Compiled:
    return Compiled(envs.make("ant", "none", ("state",), physics="warp"))


# Warp's CPU kernels for another model: 33 s on 2 cores; the ant and the idp keep Warp in the
# default tier
@pytest.mark.slow
@warp_lang
def test_warp_halfcheetah_parity(warp_cheetah):
    """MJX-Warp against HalfCheetah-v5, with the bounds of the JAX path's parity test
    (test_halfcheetah_parity; JAX measured |d obs| 1.5e-4, |d reward| 1.5e-6). Measured (CPU,
    warp-lang 1.18.0, 60 steps, 30 with contacts): |d obs| = |d qvel| 1.05e-3, |d reward| 5.2e-6."""
    worst = parity(warp_cheetah, "HalfCheetah-v5", 60)
    assert worst["contact"] > 20
    assert worst["obs"] < 2e-3 and worst["reward"] < 2e-5


# 43 s of the suite; Warp in the fast tier: test_warp_equals_jax_and_its_nested_vmap_equals_a_loop
@pytest.mark.slow
@warp_lang
def test_warp_ant_parity_as_shipped(warp_ant):
    """MJX-Warp against Ant-v5 as Gymnasium ships it (pyramidal cones; Newton capped at 8
    iterations since 2026-11-26, 4 when measured), with the JAX path's bounds
    (test_ant_parity_as_shipped; JAX measured |d obs| 1.49, |d reward| 0.41). Measured (CPU, 60
    steps, 24 with contacts): |d obs| 2.0 (a clipped contact force at +1 on one side, -1 on the
    other), |d qvel| 1.49, |d reward| 0.41; termination identical."""
    worst = parity(warp_ant, "Ant-v5", 60)
    assert worst["contact"] > 20 and worst["terminal"] >= 0
    assert worst["obs"] < 3.0 and worst["reward"] < 1.0


# slow tier (75 s on 2 cores, most of it compiling Warp's kernels and both physics' programs); the
# default tier keeps Warp's kernels compiled and stepped by its overflow check (below)
@warp_lang
@pytest.mark.slow
def test_warp_equals_jax_and_its_nested_vmap_equals_a_loop():
    """The inverted double pendulum (its cart's rail limits in the constraint solver, frame skip
    5): MJX-Warp and MJX's JAX solver agree to float32 rounding over a step of random states and
    actions; and Warp's nested vmap (seeds x envs, folded into one batch of worlds) gives each
    world what stepping it alone gives."""
    warp_idp, jax_idp = (
        Compiled(envs.make("idp", "none", ("state",), physics=p)) for p in ("warp", "jax")
    )
    params = jax_idp.params
    qpos = np.asarray(jax.random.uniform(KEY, (2, 3, 3), minval=-0.5, maxval=0.5), np.float32)
    qvel = np.asarray(jax.random.normal(jax.random.key(1), (2, 3, 3)), np.float32)
    action = np.asarray(
        jax.random.uniform(jax.random.key(2), (2, 3, 1), minval=-1, maxval=1), np.float32
    )

    def stepped(c):
        return jax.jit(
            jax.vmap(
                jax.vmap(lambda q, v, a: c.env.transition(KEY, c.env.state_at(q, v), a, params))
            )
        )

    warp, jax_out = stepped(warp_idp)(qpos, qvel, action), stepped(jax_idp)(qpos, qvel, action)
    for field in ("qpos", "qvel", "tip"):
        np.testing.assert_allclose(
            getattr(warp.state, field), getattr(jax_out.state, field), atol=1e-4
        )
    np.testing.assert_allclose(warp.reward, jax_out.reward, atol=1e-4)
    for i, j in ((0, 0), (1, 2)):
        alone = warp_idp.transition(
            KEY, warp_idp.state_at(qpos[i, j], qvel[i, j]), action[i, j], params
        )
        np.testing.assert_allclose(warp.state.qvel[i, j], alone.state.qvel, atol=1e-5)


# one idp step through MJX-Warp in a fresh process, where Warp initialises and loads its kernels
# (the default tier's, at -O0)
_ONE_WARP_STEP = (
    ("import warp; warp.config.optimization_level = 0\n" if KERNELS_AT_O0 else "")
    + """
import jax, jax.numpy as jnp
from hintsjax.envs import physics
from hintsjax.envs.idp import InvertedDoublePendulum
model = InvertedDoublePendulum.make_mj_model()
warp = physics.WarpPhysics(model)
out = jax.jit(lambda q: warp.run(q, jnp.zeros(model.nv), jnp.zeros(model.nu), 1, False))(jnp.asarray(model.qpos0))
print("stepped", bool(jnp.isfinite(out.qpos).all()))
"""  # noqa: E501
)


@pytest.mark.slow  # 35 s of the default tier's 10 minutes on a clean clone (2026-12-07)
@warp_lang
def test_warp_prints_no_banner_or_module_lines_unless_debugging():
    """Warp's init banner and its line per kernel module ("Module ... load on device 'cuda:0'
    took ... (compiled)", 34 on the ant's command) never reach a user's terminal; with
    HINTSJAX_DEBUG=1 they do. A fresh process each way (about 7 s on 2 cores once Warp's kernel
    cache holds the idp's kernels, 30 s before)."""
    banner = re.compile(r"Module \S+ .*load on device|Warp \d+\.\d+\S* initialized")

    def banner_lines(debug: str) -> list[str]:
        env = {**os.environ, "HINTSJAX_DEBUG": debug}  # the suite's conftest sets it to 1
        done = subprocess.run(
            [sys.executable, "-c", _ONE_WARP_STEP],
            env=env,
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert done.returncode == 0 and "stepped True" in done.stdout, done.stderr[-2000:]
        return [line for line in (done.stdout + done.stderr).splitlines() if banner.match(line)]

    assert banner_lines("0") == []
    kept = banner_lines("1")
    assert any(line.startswith("Module ") for line in kept) and any(
        line.startswith("Warp ") for line in kept
    ), kept


@warp_lang
def test_a_warp_overflow_poisons_the_world_and_is_reported():
    """Contacts that do not fit are never dropped silently: a world whose contacts overflowed
    reads NaN, and `overflow_seen` names the buffer (the run loop stops with one line naming
    warp_capacity)."""
    small = physics.WarpPhysics(Ant.make_mj_model())
    small.contacts_per_world = 1  # an ant lying on the floor touches it in more places
    physics.clear_overflow()
    qpos = Ant.make_mj_model().qpos0.astype(np.float32)
    qpos[2] = 0.3
    out = jax.jit(lambda q: small.run(q, jnp.zeros(14), jnp.zeros(8), 1, True))(qpos)
    assert np.isnan(np.asarray(out.qpos)).all() and int(out.overflow) & physics.LOST_MASK
    assert "(naconmax)" in physics.overflow_seen()
    physics.clear_overflow()
    fine = jax.jit(
        lambda q: physics.WarpPhysics(Ant.make_mj_model()).run(
            q, jnp.zeros(14), jnp.zeros(8), 1, True
        )
    )(qpos)
    assert np.isfinite(np.asarray(fine.qpos)).all() and physics.overflow_seen() is None


@pytest.mark.slow  # 30 s on 2 cores
@warp_lang
def test_under_warp_drawing_only_the_ended_starts_steps_as_every_envs_start():
    """AutoReset.step_ended under MJX-Warp: 16 ants under actions of +-1e6 for 40 steps, the ended
    envs' starts drawn 2 at a time (another batch shape for Warp's kernels than the step's 16),
    take the same rewards, ends, observations and states as the vmapped step that draws every
    env's start each step (measured: 14 ends, every value equal). What PPO's rollout under Warp
    needs before hintsjax.algorithms.ppo.ENDED_STARTS_PHYSICS may name it; its speed is GPU work."""
    n, steps = 16, 40
    env = envs.AutoReset(envs.make("ant", envs.NO_HINT, ("state",), physics=envs.WARP))
    params = envs.make_params("ant")
    start = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(KEY, n), params).state
    extremes = jnp.array([1e6, -1e6, 0.0])

    def roll(ended: bool):
        def step(state, key):
            k_act, k_env = jax.random.split(key)
            action = jax.random.choice(k_act, extremes, (n, env.action_size))
            keys = jax.random.split(k_env, n)
            if ended:
                ts = env.step_ended(keys, state, action, params, 2)
            else:
                ts = jax.vmap(env.step, in_axes=(0, 0, 0, None))(keys, state, action, params)
            return ts.state, (ts.reward, ts.terminated | ts.truncated, ts.obs)

        keys = jax.random.split(jax.random.key(1), steps)
        return jax.jit(lambda s: jax.lax.scan(step, s, keys))(start)

    chosen, every = roll(True), roll(False)
    ends = np.asarray(chosen[1][1])
    assert 0 < ends.sum() and ends.sum(axis=1).max() < n, ends.sum(axis=1)  # some, never all
    for a, b in zip(jax.tree.leaves(chosen), jax.tree.leaves(every)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.slow  # as the halfcheetah's: 40 s on 2 cores
@warp_lang
def test_warp_humanoid_parity():
    """MJX-Warp's humanoid against Humanoid-v5 with our integrator (Euler) on both sides, with the
    JAX path's bounds (test_humanoid_parity; JAX measured |d obs| 6.7e-3, |d reward| 1.0e-5).
    Measured (CPU, 40 steps, 10 with contacts): |d obs| 7.1e-3, |d reward| 7.3e-6."""
    import mujoco

    humanoid = Compiled(envs.make("humanoid", "none", ("state",), physics="warp"))
    worst = parity(
        humanoid, "Humanoid-v5", 40, gym_options=dict(integrator=mujoco.mjtIntegrator.mjINT_EULER)
    )
    assert worst["contact"] > 5
    assert worst["obs"] < 0.07 and worst["reward"] < 1e-4
