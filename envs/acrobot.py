"""Acrobot on MJX: Gymnasium `Acrobot-v1`'s "book" dynamics with a continuous torque, at 64x64.

Two unit links (mass 1, centre of mass at the middle, moment of inertia 1 about it) hang from a
fixed pivot; only the elbow is driven. theta1 is the first link's angle from hanging straight
down, theta2 the second link's angle relative to the first. MuJoCo's RK4 integrator with one
0.2 s step is Gymnasium's `rk4` over [0, dt] with the torque held; after it the angles are
wrapped into [-pi, pi) and the speeds clipped to 4 pi and 9 pi, as Gymnasium does.

The action is a torque in [-1, 1] (clipped), so Gymnasium's three discrete actions are the
points -1, 0 and 1 of ours and negative torque is reachable. Reward -1 per step until the tip
rises above height 1 (one link length above the pivot), which terminates with reward 0.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax.envs import raster
from hintsjax.envs.core import Step
from hintsjax.envs.hints import register_hint, register_link_velocity_hints
from hintsjax.envs.mjx_env import MjxEnv
from hintsjax.envs.pendulum import wrap_angle

NAME = "acrobot"

# Acrobot-v1's constants; they define the MJCF below, so they are not params.
LENGTH, MASS, MOI, GRAVITY, DT = 1.0, 1.0, 1.0, 9.8, 0.2

# The hinge axis is -y so that a positive angle moves the link towards +x (Gymnasium's
# x = sin theta1), and the links hang along -z at theta = 0.
MJCF = f"""
<mujoco model="acrobot">
  <option timestep="{DT}" gravity="0 0 -{GRAVITY}" integrator="RK4"/>
  <worldbody>
    <body name="link1">
      <joint name="shoulder" type="hinge" axis="0 -1 0"/>
      <inertial pos="0 0 -{LENGTH / 2}" mass="{MASS}" diaginertia="{MOI} {MOI} {MOI}"/>
      <geom type="capsule" fromto="0 0 0 0 0 -{LENGTH}" size="0.05" contype="0" conaffinity="0"/>
      <body name="link2" pos="0 0 -{LENGTH}">
        <joint name="elbow" type="hinge" axis="0 -1 0"/>
        <inertial pos="0 0 -{LENGTH / 2}" mass="{MASS}" diaginertia="{MOI} {MOI} {MOI}"/>
        <geom type="capsule" fromto="0 0 0 0 0 -{LENGTH}" size="0.05" contype="0" conaffinity="0"/>
        <site name="tip" pos="0 0 -{LENGTH}"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor joint="elbow" gear="1"/></actuator>
</mujoco>
"""


@struct.dataclass
class AcrobotParams:
    max_torque: float = 1.0
    max_speed_1: float = 4 * jnp.pi
    max_speed_2: float = 9 * jnp.pi
    init_range: float = 0.1  # every state entry starts uniform in [-init_range, init_range]
    goal_height: float = 1.0  # the tip above this height ends the episode


@struct.dataclass
class AcrobotState:
    """qpos = [theta1, theta2] (rad, wrapped), qvel = [dtheta1, dtheta2] (rad/s), step count."""

    qpos: jax.Array
    qvel: jax.Array
    t: jax.Array

    @classmethod
    def at(cls, theta1, theta2, dtheta1=0.0, dtheta2=0.0, t=0) -> "AcrobotState":
        """A hand-set state from numbers (or equal-shaped arrays, for a batch)."""
        t1, t2, v1, v2, t = jnp.broadcast_arrays(
            *(jnp.asarray(x) for x in (theta1, theta2, dtheta1, dtheta2, t))
        )
        f32 = lambda *x: jnp.stack(x, -1).astype(jnp.float32)  # noqa: E731
        return cls(f32(t1, t2), f32(v1, v2), t.astype(jnp.int32))


VARIANTS = {"standard": AcrobotParams()}

# Colours of Gymnasium's acrobot render: teal links, yellow joints, black goal line, white ground.
LINK, JOINT, GOAL, BACKGROUND = (0.0, 0.8, 0.8), (0.8, 0.8, 0.0), (0.0, 0.0, 0.0), (1.0, 1.0, 1.0)
HALF_EXTENT = 2.2  # 2 link lengths + 0.2, as in Gymnasium
LINK_RADIUS, JOINT_RADIUS, GOAL_RADIUS = 0.1, 0.1, 0.02


def link_ends(qpos: jax.Array) -> tuple[jax.Array, jax.Array]:
    """World (x, z) of the elbow and of the tip (pivot at the origin, z up)."""
    theta1, theta12 = qpos[0], qpos[0] + qpos[1]
    elbow = LENGTH * jnp.stack([jnp.sin(theta1), -jnp.cos(theta1)])
    tip = elbow + LENGTH * jnp.stack([jnp.sin(theta12), -jnp.cos(theta12)])
    return elbow, tip


class Acrobot(MjxEnv):
    name = NAME
    mjcf = MJCF
    max_steps = 500
    action_size = 1

    def default_params(self) -> AcrobotParams:
        return VARIANTS["standard"]

    def initial_state(self, key: jax.Array, params: AcrobotParams) -> AcrobotState:
        s = jax.random.uniform(key, (4,), jnp.float32, -params.init_range, params.init_range)
        return AcrobotState(qpos=s[:2], qvel=s[2:], t=jnp.zeros((), jnp.int32))

    def action_range(self, params: AcrobotParams) -> tuple[jax.Array, jax.Array]:
        return -params.max_torque * jnp.ones(1), params.max_torque * jnp.ones(1)

    def transition(self, key, state: AcrobotState, action, params: AcrobotParams) -> Step:
        torque = jnp.clip(jnp.reshape(action, (1,)), *self.action_range(params))
        data = self.physics.run(state.qpos, state.qvel, torque, 1, contact_forces=False)
        qpos = wrap_angle(data.qpos)
        limit = jnp.stack([params.max_speed_1, params.max_speed_2])
        qvel = jnp.clip(data.qvel, -limit, limit)
        next_state = state.replace(qpos=qpos, qvel=qvel)
        terminated = tip_height(next_state) > params.goal_height
        return Step(next_state, jnp.where(terminated, 0.0, -1.0), terminated)

    def render(self, state: AcrobotState, params: AcrobotParams) -> jax.Array:
        """uint8[64, 64, 3]: white ground, goal line at the goal height, two links, joints."""
        size = self.image_size
        pixel = 2 * HALF_EXTENT / size
        points = raster.pixel_centres(size, HALF_EXTENT)
        origin = jnp.zeros(2, jnp.float32)
        elbow, tip = link_ends(state.qpos)
        line = jnp.abs(points[..., 1] - params.goal_height)
        image = raster.canvas(size, BACKGROUND)
        image = raster.paint(image, raster.coverage(line, GOAL_RADIUS, pixel), GOAL)
        for a, b in ((origin, elbow), (elbow, tip)):
            image = raster.paint(
                image,
                raster.coverage(raster.segment_distance(points, a, b), LINK_RADIUS, pixel),
                LINK,
            )
        for c in (origin, elbow):
            image = raster.paint(
                image, raster.coverage(raster.point_distance(points, c), JOINT_RADIUS, pixel), JOINT
            )
        return raster.to_uint8(image)

    def state_obs(self, state: AcrobotState, params: AcrobotParams) -> jax.Array:
        return observation(state)


def observation(state: AcrobotState) -> jax.Array:
    """float32[6] = [cos t1, sin t1, cos t2, sin t2, dt1, dt2], Acrobot-v1's observation."""
    q, v = state.qpos, state.qvel
    return jnp.stack([jnp.cos(q[0]), jnp.sin(q[0]), jnp.cos(q[1]), jnp.sin(q[1]), v[0], v[1]])


def tip_height(state: AcrobotState) -> jax.Array:
    """Height of the tip above the pivot, -cos t1 - cos(t1 + t2), as Gymnasium's terminal test."""
    return -jnp.cos(state.qpos[0]) - jnp.cos(state.qpos[0] + state.qpos[1])


# -- hints (SPEC section 3) ---------------------------------------------------------------------


register_link_velocity_hints(NAME, lambda state: state.qvel)


@register_hint(NAME, "goal_distance", dim=1, unit="m")
def goal_distance(state: AcrobotState, params: AcrobotParams) -> jax.Array:
    """D_goal = sum l_i - sum l_i cos(phi_i), phi_i = link i's angle from upright (0 to 4)."""
    # phi_1 = pi - theta1 and phi_2 = pi - (theta1 + theta2), so cos(phi_i) = -cos(...).
    return 2 * LENGTH + LENGTH * (jnp.cos(state.qpos[0]) + jnp.cos(state.qpos[0] + state.qpos[1]))


@register_hint(NAME, "partial_state", dim=4, unit="1, 1, rad/s, rad/s")
def partial_state(state: AcrobotState, params: AcrobotParams) -> jax.Array:
    """[cos t2, sin t2, dt1, dt2]: the state observation without its first two entries."""
    return observation(state)[2:]


@register_hint(NAME, "state", dim=6, unit="1, 1, 1, 1, rad/s, rad/s")
def full_state(state: AcrobotState, params: AcrobotParams) -> jax.Array:
    """[cos t1, sin t1, cos t2, sin t2, dt1, dt2]: the full state observation."""
    return observation(state)


# Training defaults, RunConfig layers over the dataclasses' (hintsjax/settings/env_defaults.py): the
# hint, deploy variants and PPO settings of every agent; `learners`, the layer of every agent but
# the converged references; `agents`, an agent's own layer (the references' budgets and settings).
# 700 episodes of at most 500 steps (the paper's 700 episodes, counted at their length).
EXPERT_PPO = dict(total_env_steps=1_000_000)
TRAINING = dict(
    hint="composite",
    ppo=dict(total_env_steps=350_000, reward_scale=0.1),
    agents=dict(
        expert_ppo=dict(ppo=EXPERT_PPO),
        gail=dict(ppo=EXPERT_PPO),
        dagger=dict(ppo=dict(total_env_steps=100_000), dagger=dict(buffer_size=100_000)),
    ),
)
