"""Ant, HalfCheetah and Humanoid: parity with Gymnasium v5 (MuJoCo C), resets, and every hint
at a hand-set state (SPEC sections 2 and 3).

Parity is checked along Gymnasium's own trajectories: before every step our state is set to
gym's (rounded to float32), both take the same action, and the next observation, reward and
termination are compared. MuJoCo C computes in float64, MJX in float32.

Ant: MJX orients the friction pyramid of a plane contact along the world axes, MuJoCo C along
the capsule's; with the v5 model's pyramidal cones the two therefore solve slightly different
friction problems whenever a leg touches the floor (measured: up to 1.5 in a velocity or a
clipped contact force, 0.41 in reward; identical without contacts). A slow test steps both with
elliptic cones (rotation-invariant) and the converged solver, which isolates our reward,
observation and termination code; another bounds the difference under the real settings. They
are slow tests because the Ant takes about a minute and a half to compile on 2 cores.
"""

from __future__ import annotations

import gymnasium as gym
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.envs.ant import Ant, AntFast
from hintsjax.envs.halfcheetah import HalfCheetah
from hintsjax.envs.humanoid import Humanoid
from hintsjax.envs.locomotion import LocomotionState
from gym_parity import KEY, Compiled, parity  # tests/envs/gym_parity.py

ELLIPTIC = dict(
    solver=mujoco.mjtSolver.mjSOL_NEWTON,
    iterations=100,
    ls_iterations=50,
    cone=mujoco.mjtCone.mjCONE_ELLIPTIC,
)


# elliptic friction cones, MuJoCo's default solver budget
AntElliptic = Ant.with_options(**ELLIPTIC)


def test_with_options_changes_a_copy_of_the_model_options():
    euler = mujoco.mjtIntegrator.mjINT_EULER
    fast, shipped = (
        Ant.with_options(integrator=euler, iterations=1).make_mj_model(),
        Ant.make_mj_model(),
    )
    assert fast.opt.integrator == euler and fast.opt.iterations == 1
    assert fast.opt.ls_iterations == 16  # the rest of the shipped options stay
    assert shipped.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4 and shipped.opt.iterations == 8
    assert AntElliptic.make_mj_model().opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC


@pytest.fixture(scope="module")
def cheetah() -> Compiled:
    return Compiled(HalfCheetah(envs.make_hint("halfcheetah", "none"), ("state",)))


def test_halfcheetah_parity(cheetah):
    """Measured (CPU, jax 0.10.2, mujoco 3.17.0, 60 steps): |d obs| 1.5e-4, |d reward| 1.5e-6
    with Newton capped at 4 iterations (2 iterations missed by 1.6); 8 iterations, the cap since
    2026-11-26, alike. Tolerances ~10x."""
    worst = parity(cheetah, "HalfCheetah-v5", 60)
    assert worst["contact"] > 20
    assert worst["obs"] < 2e-3 and worst["reward"] < 2e-5


@pytest.fixture(scope="module")
def cheetah_expert():
    from hintsjax.algorithms.experts import load

    return jax.jit(load("halfcheetah").mean)


def test_halfcheetah_parity_along_its_experts_running_states(cheetah, cheetah_expert):
    """From the packaged expert's running states (two 500-step episodes on HalfCheetah-v5, where
    the feet strike the floor at speed), Newton's cap of 8 iterations steps as MuJoCo C's 100 do:
    measured |d qvel| 2.2e-3, |d reward| 3.4e-4 (experiments/fidelity.py, the `expert` states)."""
    worst = parity(cheetah, "HalfCheetah-v5", 1000, policy=cheetah_expert, episode_steps=500)
    assert worst["contact"] > 200
    assert worst["qvel"] < 0.02 and worst["reward"] < 3e-3


@pytest.mark.slow
def test_four_newton_iterations_were_too_few_for_the_cheetahs_running_states(cheetah_expert):
    """Why the cap is 8 (it was 4 until 2026-11-26): with 4, from the same states, a step misses
    HalfCheetah-v5 by up to 1.2 in a velocity and 0.033 in reward (MuJoCo C capped at 4 alike)."""
    four = HalfCheetah.with_options(iterations=4, ls_iterations=8)
    worst = parity(
        Compiled(four(envs.make_hint("halfcheetah", "none"), ("state",))),
        "HalfCheetah-v5",
        1000,
        policy=cheetah_expert,
        episode_steps=500,
    )
    assert worst["qvel"] > 0.2


@pytest.mark.slow
def test_ant_parity_elliptic():
    """Both sides with elliptic cones and MuJoCo's 100 Newton iterations. Measured (60 steps):
    |d obs| 0.018 (a contact force, in N, of forces up to ~300 N before v5's clip), |d reward|
    5e-5; ten times that is allowed."""
    worst = parity(
        Compiled(AntElliptic(envs.make_hint("ant", "none"), ("state",))),
        "Ant-v5",
        60,
        gym_options=ELLIPTIC,
    )
    assert worst["contact"] > 20 and worst["terminal"] >= 1
    assert worst["obs"] < 0.2 and worst["reward"] < 5e-4


@pytest.mark.slow
def test_ant_parity_as_shipped():
    """The shipped ant (pyramidal cones, Newton capped at 8 iterations) against Ant-v5 as
    Gymnasium ships it. Measured (60 steps, with the cap of 4 then): |d obs| 1.49, |d reward|
    0.41, both on contact steps (MJX's friction pyramid, module docstring; at 8 iterations the
    same 1.5 from random states, experiments/results/fidelity.md); termination identical."""
    worst = parity(Compiled(Ant(envs.make_hint("ant", "none"), ("state",))), "Ant-v5", 60)
    assert worst["obs"] < 3.0 and worst["reward"] < 1.0


@pytest.mark.slow
def test_ant_with_euler_against_ant_v5_as_shipped():
    """What Euler (the humanoid's integrator, ~3.6x cheaper) would cost the ant: ours with Euler
    against Ant-v5 as shipped (RK4). Measured (60 steps, 24 with contacts): |d qvel| 12.1,
    |d qpos| 0.27, |d reward| 0.47; termination identical (the shipped RK4 ant: |d obs| 1.49,
    |d reward| 0.41). 2 CPU cores, 64 envs, bench.py --quick: 1,736 env steps/s physics with
    Euler, 485 with RK4."""
    euler = Ant.with_options(integrator=mujoco.mjtIntegrator.mjINT_EULER)
    worst = parity(Compiled(euler(envs.make_hint("ant", "none"), ("state",))), "Ant-v5", 60)
    assert worst["contact"] > 10
    assert worst["qpos"] < 0.6 and worst["qvel"] < 25.0 and worst["reward"] < 1.0


def test_ant_fast_is_the_ant_with_cheaper_physics():
    """ant_fast: Euler, 2 Newton iterations, floor contacts for the torso and lower legs only
    (9, against the ant's 25), the ant's hints, and next starts drawn once per rollout."""
    from hintsjax.envs.physics import capacities
    from hintsjax.settings.layers import run_config

    fast, ant = envs.make("ant_fast", "speed"), envs.make("ant", "speed")
    assert (
        fast.mj_model.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER
        and fast.mj_model.opt.iterations == 2
    )
    assert capacities(fast.mj_model)[0] == 9 and capacities(ant.mj_model)[0] == 25
    assert envs.hint_names("ant_fast") == envs.hint_names("ant")
    assert (
        run_config({"env": "ant_fast"}).ppo.starts_per_rollout
        and not run_config({"env": "ant"}).ppo.starts_per_rollout
    )


@pytest.fixture(scope="module")
def ant_fast() -> Compiled:
    return Compiled(AntFast(envs.make_hint("ant_fast", "none"), ("state",)))


@pytest.mark.slow
def test_ant_fast_parity(ant_fast):
    """ant_fast against MuJoCo C with the same changes (AntFast.adapt on Gymnasium's model): what
    MJX changes. Measured (60 steps, 9 with contacts): |d obs| = |d qvel| 8.2, |d qpos| 0.08,
    |d reward| 0.11; termination identical. The pyramid's orientation (module docstring) weighs
    more with Euler: the ant as shipped gives |d obs| 1.49."""
    worst = parity(ant_fast, "Ant-v5", 60, adapt=AntFast.adapt)
    assert worst["contact"] > 5
    assert worst["obs"] < 20.0 and worst["qpos"] < 0.3 and worst["reward"] < 0.3


@pytest.mark.slow
def test_ant_fast_against_ant_v5_as_shipped(ant_fast):
    """What ant_fast's physics costs: against Ant-v5 as Gymnasium ships it. Measured (60 steps,
    24 with contacts): |d qvel| 12.1, |d qpos| 0.27, |d reward| 0.47, termination identical: the
    same as Euler alone (test_ant_with_euler_against_ant_v5_as_shipped), so the 2 iterations
    and the fewer contacts changed nothing on these steps."""
    worst = parity(ant_fast, "Ant-v5", 60, same_termination=False)
    assert worst["contact"] > 10
    assert worst["termination_differs"] <= 1 and worst["qvel"] < 25.0 and worst["reward"] < 1.0


@pytest.mark.slow
def test_one_newton_iteration_is_too_few_for_the_fast_ant():
    """Why ant_fast keeps 2 Newton iterations: with 1, against Ant-v5 as shipped. Measured (60
    steps): |d qvel| 73, |d reward| 1.9, one termination differing (with 2: 12.1, 0.47, none).
    1 iteration ran 1.45 M env steps/s on an H200 (physics alone, AutoReset, 25 contacts),
    against 0.94 M with 2 (experiments/results/bench_h100_locomotion.txt)."""
    one = AntFast.with_options(iterations=1)
    worst = parity(
        Compiled(one(envs.make_hint("ant_fast", "none"), ("state",))),
        "Ant-v5",
        60,
        same_termination=False,
    )
    assert worst["qvel"] > 30.0 or worst["termination_differs"] > 0


@pytest.fixture(scope="module")
def humanoid() -> Compiled:
    return Compiled(Humanoid(envs.make_hint("humanoid", "none"), ("state",)))


@pytest.mark.slow
def test_humanoid_parity(humanoid):
    """Both sides with our integrator (Euler); Gymnasium keeps its PGS (50 iterations), ours is
    Newton capped at 4. Measured (40 steps, 10 with contacts; ~25 s on 2 cores): |d obs| 6.7e-3,
    |d reward| 1.0e-5, |d qvel| 7.4e-5 (with RK4 on both sides: 3.7e-3, 6.6e-6)."""
    worst = parity(
        humanoid, "Humanoid-v5", 40, gym_options=dict(integrator=mujoco.mjtIntegrator.mjINT_EULER)
    )
    assert worst["contact"] > 5
    assert worst["obs"] < 0.07 and worst["reward"] < 1e-4


@pytest.mark.slow
def test_humanoid_parity_as_shipped(humanoid):
    """Ours (Euler) against Humanoid-v5 as Gymnasium ships it (RK4): what the integrator costs.
    Measured (40 steps): |d qpos| 0.033, |d qvel| 2.1, |d reward| 1.16 (of about 5 a step), all on
    contact steps; |d obs| 525, a contact force (cfrc_ext, unclipped); termination identical."""
    worst = parity(humanoid, "Humanoid-v5", 40)
    assert worst["contact"] > 5
    assert worst["qpos"] < 0.1 and worst["qvel"] < 6.0 and worst["reward"] < 3.0


@pytest.mark.parametrize(
    "name, gym_id",
    [("halfcheetah", "HalfCheetah-v5"), ("ant", "Ant-v5"), ("humanoid", "Humanoid-v5")],
)
def test_start_distribution_matches_gymnasium(name, gym_id):
    """qpos = qpos0 + U(-s, s); qvel = s N(0, 1) (Humanoid: U(-s, s)), with v5's s: the same
    means (within 5 standard errors) and spreads (10%) as Gymnasium's, 1000 draws each."""
    env = envs.make(name, observe=("state",))
    params = env.default_params()
    qpos, qvel = map(
        np.asarray,
        jax.jit(jax.vmap(env.draw_start, in_axes=(0, None)))(jax.random.split(KEY, 1000), params),
    )
    gym_env = gym.make(gym_id).unwrapped
    gym_qpos, gym_qvel = map(
        np.stack,
        zip(
            *[
                (gym_env.reset(seed=i) and gym_env.data.qpos.copy(), gym_env.data.qvel.copy())
                for i in range(1000)
            ]
        ),
    )
    s = params.reset_noise_scale
    deviation = np.abs(qpos - env.mj_model.qpos0).max()
    assert s * 0.99 < deviation <= s * (1 + 1e-5)
    for ours, theirs in ((qpos, gym_qpos), (qvel, gym_qvel)):
        spread = theirs.std(0)
        # 5 standard errors
        assert np.all(np.abs(ours.mean(0) - theirs.mean(0)) < 5 * np.sqrt(2 / 1000) * spread)
        np.testing.assert_allclose(ours.std(0), spread, rtol=0.1)


# -- hints at hand-set states (pure functions of the state: no physics needed) ------------------


def hand_set(name: str, **fields) -> LocomotionState:
    """A state of `name` with zeros everywhere but `fields`."""
    env_cls = envs.REGISTRY[name].cls
    model = env_cls.make_mj_model()
    zero = lambda *shape: jnp.zeros(shape, jnp.float32)  # noqa: E731
    state = LocomotionState(
        qpos=jnp.asarray(model.qpos0, jnp.float32),
        qvel=zero(model.nv),
        obs=zero(3),
        geom_xpos=zero(model.ngeom, 3),
        geom_xmat=zero(model.ngeom, 3, 3),
        com=zero(3),
        position=zero(2),
        velocity=zero(2),
        reward=zero(),
        max_velocity=zero(),
        t=jnp.zeros((), jnp.int32),
    )
    return state.replace(**{k: jnp.asarray(v, jnp.float32) for k, v in fields.items()})


def hint(name: str, spec: str, state: LocomotionState) -> np.ndarray:
    return np.asarray(envs.make_hint(name, spec)(state, envs.make_params(name)))


def test_ant_hints():
    qpos = envs.REGISTRY["ant"].cls.make_mj_model().qpos0.copy()
    qpos[2] = 0.5
    state = hand_set("ant", velocity=[3.0, -4.0], qpos=qpos, obs=np.arange(105.0))
    np.testing.assert_allclose(hint("ant", "speed", state), [5.0])  # |(3, -4)|
    np.testing.assert_allclose(hint("ant", "goal_height", state), [0.5 - 0.75], atol=1e-7)
    np.testing.assert_array_equal(hint("ant", "state", state), np.arange(105.0))
    np.testing.assert_allclose(hint("ant", "speed+goal_height", state), [5.0, -0.25], atol=1e-7)


def test_humanoid_hints():
    qpos = envs.REGISTRY["humanoid"].cls.make_mj_model().qpos0.copy()
    qpos[2] = 1.1
    state = hand_set("humanoid", velocity=[1.5, 2.0], qpos=qpos)
    np.testing.assert_allclose(hint("humanoid", "velocity", state), [1.5])
    np.testing.assert_allclose(hint("humanoid", "goal_height", state), [1.1 - 1.4], atol=1e-6)


def test_raw_action_ctrl_cost_charges_the_action_as_gymnasium_does(cheetah):
    """Out-of-range actions (2x the control range) from a Gymnasium state: with
    `raw_action_ctrl_cost` our reward is HalfCheetah-v5's (which charges the raw action); by
    default the cost is charged on the clipped action, so ours is higher by exactly the weight
    times the clipped-away part of |a|^2. The dynamics are the same either way."""
    import gymnasium as gym

    gym_env = gym.make("HalfCheetah-v5").unwrapped
    gym_env.reset(seed=3)
    qpos, qvel = (
        np.asarray(x, np.float32).astype(np.float64) for x in (gym_env.data.qpos, gym_env.data.qvel)
    )
    gym_env.set_state(qpos, qvel)
    action = np.random.default_rng(3).uniform(-2, 2, 6).astype(np.float32)
    _, gym_reward, _, _, _ = gym_env.step(action)
    state = cheetah.state_at(qpos, qvel)
    raw = cheetah.transition(
        KEY, state, jnp.asarray(action), cheetah.params.replace(raw_action_ctrl_cost=True)
    )
    clipped = cheetah.transition(KEY, state, jnp.asarray(action), cheetah.params)
    assert float(raw.reward) == pytest.approx(gym_reward, abs=2e-5)
    clipped_away = 0.1 * (
        np.sum(action.astype(np.float64) ** 2)
        - np.sum(np.clip(action, -1, 1).astype(np.float64) ** 2)
    )
    assert clipped_away > 0.2
    assert float(clipped.reward) - float(raw.reward) == pytest.approx(clipped_away, abs=1e-4)
    np.testing.assert_array_equal(raw.state.qvel, clipped.state.qvel)


def test_halfcheetah_hints():
    state = hand_set("halfcheetah", velocity=[-2.0, 0.0], max_velocity=3.5, reward=-0.7)
    np.testing.assert_allclose(hint("halfcheetah", "velocity", state), [-2.0])
    np.testing.assert_allclose(hint("halfcheetah", "max_velocity", state), [3.5])
    np.testing.assert_allclose(hint("halfcheetah", "reward", state), [-0.7], rtol=1e-6)


def test_halfcheetah_max_velocity_follows_the_episode(cheetah):
    """max_velocity is the running maximum of the per-step forward velocity (0 at the start,
    so a cheetah that only backs up keeps 0); the reward hint is the step's reward."""
    hints = envs.make_hint("halfcheetah", "velocity+max_velocity+reward")
    state = cheetah.state_at(cheetah.env.mj_model.qpos0, np.zeros(9))
    np.testing.assert_array_equal(np.asarray(hints(state, cheetah.params)), [0.0, 0.0, 0.0])
    running, velocities = 0.0, []
    for i in range(12):
        # float32, as parity's: no recompile
        action = np.full(6, 1.0 if i % 6 < 3 else -1.0, np.float32)
        out = cheetah.transition(KEY, state, jnp.asarray(action), cheetah.params)
        state = out.state
        velocity, max_velocity, reward = np.asarray(hints(state, cheetah.params))
        running = max(running, velocity)
        velocities.append(velocity)
        assert max_velocity == pytest.approx(running)
        assert reward == pytest.approx(float(out.reward))
    assert running > 0 and min(velocities) < running  # the maximum held while it slowed


def test_every_locomotion_hint_is_registered():
    """SPEC section 3's hint names per env."""
    assert set(envs.hint_names("ant")) == {"speed", "goal_height", "state"}
    assert set(envs.hint_names("halfcheetah")) == {"velocity", "max_velocity", "reward", "state"}
    assert set(envs.hint_names("humanoid")) == {"velocity", "goal_height", "state"}
