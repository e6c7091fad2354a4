"""Pendulum swing-up on MJX: Gymnasium `Pendulum-v1`'s dynamics and reward, drawn at 64x64.

The model is a uniform rod (mass m, length l) on a hinge, upright at theta = 0. MJX computes the
joint acceleration (gravity and motor torque through the rod's inertia m l^2 / 3 about the
pivot); the step integrates it as Gymnasium does, semi-implicit Euler with the velocity clipped
to `max_speed` *before* the position update, which MuJoCo's own Euler step cannot reproduce.

Deploy variant `swingto`: the goal angle is drawn per episode from [-pi/2, pi/2]. The paper's
swing-to reward sum_t log(|theta_t| - |theta*|) is undefined whenever |theta_t| <= |theta*|, so we
make it finite by keeping the swing-up cost about the goal:
r = -(wrap(theta - theta*)^2 + 0.1 dtheta^2 + 0.001 u^2), which equals `Pendulum-v1`'s reward
when theta* = 0. The goal is drawn in the picture as a grey line, in both variants.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax.envs import raster
from hintsjax.envs.core import Step
from hintsjax.envs.hints import register_composite, register_hint
from hintsjax.envs.mjx_env import MjxEnv
from hintsjax.envs.physics import Readout

NAME = "pendulum"

# Gymnasium Pendulum-v1's constants; they define the MJCF below, so they are not params.
GRAVITY, MASS, LENGTH = 10.0, 1.0, 1.0

MJCF = f"""
<mujoco model="pendulum">
  <option timestep="0.05" gravity="0 0 -{GRAVITY}" integrator="Euler"/>
  <worldbody>
    <body name="pole">
      <joint name="hinge" type="hinge" axis="0 1 0"/>
      <geom type="capsule" fromto="0 0 0 0 0 {LENGTH}" size="0.05" contype="0" conaffinity="0"/>
      <inertial pos="0 0 {LENGTH / 2}" mass="{MASS}"
                diaginertia="{MASS * LENGTH**2 / 12} {MASS * LENGTH**2 / 12} 1e-6"/>
      <site name="tip" pos="0 0 {LENGTH}"/>
    </body>
  </worldbody>
  <actuator><motor joint="hinge" gear="1"/></actuator>
</mujoco>
"""


@struct.dataclass
class PendulumParams:
    """Per-task constants; the goal range is what the swingto variant changes."""

    max_speed: float = 8.0
    max_torque: float = 2.0
    dt: float = 0.05
    init_angle: float = jnp.pi
    init_speed: float = 1.0
    goal_low: float = 0.0
    goal_high: float = 0.0


@struct.dataclass
class PendulumState:
    """theta (rad, 0 upright, unwrapped), dtheta (rad/s), the episode's goal angle, step count."""

    theta: jax.Array
    dtheta: jax.Array
    goal: jax.Array
    t: jax.Array

    @classmethod
    def at(cls, theta, dtheta, goal=0.0, t=0) -> "PendulumState":
        """A hand-set state from numbers (or arrays, for a batch)."""
        f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
        return cls(f32(theta), f32(dtheta), f32(goal), jnp.asarray(t, jnp.int32))


VARIANTS = {
    "swingup": PendulumParams(),
    "swingto": PendulumParams(goal_low=-jnp.pi / 2, goal_high=jnp.pi / 2),
}

# Colours of Gymnasium's pendulum render: red-brown rod, black pivot, white ground.
ROD, PIVOT, GOAL, BACKGROUND = (0.8, 0.3, 0.3), (0.0, 0.0, 0.0), (0.75, 0.75, 0.75), (1.0, 1.0, 1.0)
HALF_EXTENT = 2.2  # world units from the centre to the picture's edge, as in Gymnasium
ROD_RADIUS, PIVOT_RADIUS, GOAL_RADIUS = 0.1, 0.06, 0.03


def wrap_angle(x: jax.Array) -> jax.Array:
    """Angle mapped into [-pi, pi), as Gymnasium's `angle_normalize`."""
    return ((x + jnp.pi) % (2 * jnp.pi)) - jnp.pi


class Pendulum(MjxEnv):
    name = NAME
    mjcf = MJCF
    max_steps = 200
    action_size = 1

    def default_params(self) -> PendulumParams:
        return VARIANTS["swingup"]

    def initial_state(self, key: jax.Array, params: PendulumParams) -> PendulumState:
        k_theta, k_speed, k_goal = jax.random.split(key, 3)
        u = lambda k, lo, hi: jax.random.uniform(k, (), jnp.float32, lo, hi)  # noqa: E731
        return PendulumState(
            theta=u(k_theta, -params.init_angle, params.init_angle),
            dtheta=u(k_speed, -params.init_speed, params.init_speed),
            goal=u(k_goal, params.goal_low, params.goal_high),
            t=jnp.zeros((), jnp.int32),
        )

    def _mjx_data(self, state: PendulumState, torque: jax.Array) -> Readout:
        return self.physics.run(
            state.theta[None], state.dtheta[None], torque[None], 0, contact_forces=False
        )

    def action_range(self, params: PendulumParams) -> tuple[jax.Array, jax.Array]:
        return -params.max_torque * jnp.ones(1), params.max_torque * jnp.ones(1)

    def transition(self, key, state: PendulumState, action, params: PendulumParams) -> Step:
        torque = jnp.clip(jnp.reshape(action, (1,)), *self.action_range(params))[0]
        cost = wrap_angle(state.theta - state.goal) ** 2 + 0.1 * state.dtheta**2 + 0.001 * torque**2
        qacc = self._mjx_data(state, torque).qacc[0]
        dtheta = jnp.clip(state.dtheta + qacc * params.dt, -params.max_speed, params.max_speed)
        theta = state.theta + dtheta * params.dt
        return Step(state.replace(theta=theta, dtheta=dtheta), -cost, jnp.zeros((), bool))

    def tip(self, state: PendulumState) -> jax.Array:
        """float32[2] world (x, z) of the rod's tip, from MJX's kinematics."""
        data = self._mjx_data(state, jnp.zeros(()))
        return data.site_xpos[self.site_ids["tip"]][jnp.array([0, 2])]

    def render(self, state: PendulumState, params: PendulumParams) -> jax.Array:
        """uint8[64, 64, 3]: white ground, grey goal line, red rod, black pivot."""
        size = self.image_size
        pixel = 2 * HALF_EXTENT / size
        points = raster.pixel_centres(size, HALF_EXTENT)
        origin = jnp.zeros(2, jnp.float32)
        goal_tip = LENGTH * jnp.stack([jnp.sin(state.goal), jnp.cos(state.goal)])
        image = raster.canvas(size, BACKGROUND)
        image = raster.paint(
            image,
            raster.coverage(raster.segment_distance(points, origin, goal_tip), GOAL_RADIUS, pixel),
            GOAL,
        )
        image = raster.paint(
            image,
            raster.coverage(
                raster.segment_distance(points, origin, self.tip(state)), ROD_RADIUS, pixel
            ),
            ROD,
        )
        image = raster.paint(
            image,
            raster.coverage(raster.point_distance(points, origin), PIVOT_RADIUS, pixel),
            PIVOT,
        )
        return raster.to_uint8(image)

    def state_obs(self, state: PendulumState, params: PendulumParams) -> jax.Array:
        """float32[3] = [cos theta, sin theta, dtheta], Pendulum-v1's observation."""
        return jnp.stack([jnp.cos(state.theta), jnp.sin(state.theta), state.dtheta])


# -- hints (SPEC section 3) ---------------------------------------------------------------------


@register_hint(NAME, "goal_distance", dim=1, unit="m")
def goal_distance(state: PendulumState, params: PendulumParams) -> jax.Array:
    """D_goal = l cos(theta*) - l cos(theta): tip height below the goal's (0 upright, 2 hanging)."""
    return LENGTH * (jnp.cos(state.goal) - jnp.cos(state.theta))


@register_hint(NAME, "angular_velocity", dim=1, unit="rad/s")
def angular_velocity(state: PendulumState, params: PendulumParams) -> jax.Array:
    """dtheta/dt."""
    return state.dtheta


@register_hint(NAME, "torque", dim=1, unit="N m")
def torque(state: PendulumState, params: PendulumParams) -> jax.Array:
    """Hand-written swing-up torque: energy pumping far from the goal, PD control near it.

    Energy E = I dtheta^2 / 2 + m g (l/2) cos(theta) with I = m l^2 / 3; the goal's energy is
    m g l / 2 (at rest, upright). Far from the goal the torque k (E* - E) sign(dtheta) pumps
    energy in or out; within 20 degrees a PD law -(10 err + 2 dtheta) holds the rod, which is
    stable for these constants (the linearised closed loop is err'' = -15 err - 6 err').
    """
    inertia = MASS * LENGTH**2 / 3
    energy = 0.5 * inertia * state.dtheta**2 + MASS * GRAVITY * LENGTH / 2 * jnp.cos(state.theta)
    target = MASS * GRAVITY * LENGTH / 2
    pump = 2.0 * (target - energy) * jnp.where(state.dtheta >= 0, 1.0, -1.0)
    err = wrap_angle(state.theta - state.goal)
    hold = -(10.0 * err + 2.0 * state.dtheta)
    return jnp.clip(
        jnp.where(jnp.abs(err) < 0.35, hold, pump), -params.max_torque, params.max_torque
    )


@register_hint(NAME, "partial_state", dim=2, unit="1")
def partial_state(state: PendulumState, params: PendulumParams) -> jax.Array:
    """[cos theta, sin theta]: the state without its velocity."""
    return jnp.stack([jnp.cos(state.theta), jnp.sin(state.theta)])


@register_hint(NAME, "state", dim=3, unit="1, 1, rad/s")
def full_state(state: PendulumState, params: PendulumParams) -> jax.Array:
    """[cos theta, sin theta, dtheta]: the full state observation."""
    return jnp.stack([jnp.cos(state.theta), jnp.sin(state.theta), state.dtheta])


register_composite(NAME, "composite", ("angular_velocity", "goal_distance"))


# Training defaults, RunConfig layers over the dataclasses' (hintsjax/settings/env_defaults.py): the
# hint, deploy variants and PPO settings of every agent; `learners`, the layer of every agent but
# the converged references; `agents`, an agent's own layer (the references' budgets and settings).
# The expert's (and GAIL's) PPO is tuned for the state pendulum. With 16 envs x 64 steps a
# batch holds one phase of the 16 synchronised 200-step episodes (all swinging up, then all
# balancing), and the greedy policy swung between good and failing from one evaluation to
# the next (at 102,400 steps seeds -550, -1076, -264). Rollouts of exactly one episode
# (16 x 200 = batch 3200), gamma 0.95, actor lr 3e-4 and 10 epochs of minibatches of 200
# reach, without the entropy bonus, -185, -177, -155, -163, -173 at 102,400 steps (5 seeds,
# 20 greedy episodes each; tests/test_imitation.py's pendulum_expert_returns). Over the full
# 1 M, the entropy bonus 0.01 holds up better: 5 seeds x 50 episodes -153 +- 83 against
# -173 +- 101 without (one GPU run each; on CPU -168 +- 99 against -376 +- 461, where one
# seed failed late), so the expert and GAIL keep it.
EXPERT_PPO = dict(
    total_env_steps=1_000_000,
    num_envs=16,
    batch_size=3200,
    minibatch_size=200,
    epochs=10,
    gamma=0.95,
    ent_coef=0.01,
    actor_lr=3e-4,
)
TRAINING = dict(
    hint="composite",
    eval_variants=("swingto",),
    ppo=dict(total_env_steps=200_000, actor_lr=1e-3, reward_scale=0.1),
    agents=dict(
        expert_ppo=dict(ppo=EXPERT_PPO),
        gail=dict(ppo=EXPERT_PPO),
        dagger=dict(ppo=dict(total_env_steps=100_000), dagger=dict(buffer_size=100_000)),
    ),
)
