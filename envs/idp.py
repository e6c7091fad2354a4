"""InvertedDoublePendulum on MJX: Gymnasium `InvertedDoublePendulum-v5`, drawn at 64x64.

Gymnasium's own model (a cart on a rail, two poles, RK4, frame skip 5) with Newton capped at 2
iterations; v5's reward and termination; angles from upright; a fixed side view.

More of what it owns and why: docs/design.md, "Module notes", envs/idp.py.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax.envs import raster
from hintsjax.envs.core import Step
from hintsjax.envs.hints import register_hint, register_link_velocity_hints
from hintsjax.envs.mjx_env import MjxEnv
from hintsjax.envs.physics import Readout

NAME = "idp"

POLE = 0.6  # length of each pole (m), from the MJCF
MJCF = f"""
<mujoco model="cartpole">
  <compiler coordinate="local" inertiafromgeom="true"/>
  <default>
    <joint damping="0.05"/>
    <geom contype="0" friction="1 0.1 0.1" rgba="0.7 0.7 0 1"/>
  </default>
  <option gravity="1e-5 0 -9.81" integrator="RK4" timestep="0.01" solver="Newton" iterations="2" ls_iterations="4"/>
  <size nstack="3000"/>
  <worldbody>
    <geom name="floor" pos="0 0 -3.0" rgba="0.8 0.9 0.8 1" size="40 40 40" type="plane"/>
    <geom name="rail" pos="0 0 0" quat="0.707 0 0.707 0" rgba="0.3 0.3 0.7 1" size="0.02 1" type="capsule"/>
    <body name="cart" pos="0 0 0">
      <joint axis="1 0 0" limited="true" margin="0.01" name="slider" pos="0 0 0" range="-1 1" type="slide"/>
      <geom name="cart" pos="0 0 0" quat="0.707 0 0.707 0" size="0.1 0.1" type="capsule"/>
      <body name="pole" pos="0 0 0">
        <joint axis="0 1 0" name="hinge" pos="0 0 0" type="hinge"/>
        <geom fromto="0 0 0 0 0 {POLE}" name="cpole" rgba="0 0.7 0.7 1" size="0.045 0.3" type="capsule"/>
        <body name="pole2" pos="0 0 {POLE}">
          <joint axis="0 1 0" name="hinge2" pos="0 0 0" type="hinge"/>
          <geom fromto="0 0 0 0 0 {POLE}" name="cpole2" rgba="0 0.7 0.7 1" size="0.045 0.3" type="capsule"/>
          <site name="tip" pos="0 0 {POLE}" size="0.01 0.01"/>
        </body>
      </body>
    </body>
  </worldbody>
  <actuator>
    <motor ctrllimited="true" ctrlrange="-1 1" gear="500" joint="slider" name="slide"/>
  </actuator>
</mujoco>
"""  # noqa: E501


@struct.dataclass
class IDPParams:
    frame_skip: int = struct.field(pytree_node=False, default=5)
    healthy_reward: float = 10.0
    reset_noise_scale: float = 0.1
    min_tip_height: float = 1.0  # the tip at or below this height ends the episode


@struct.dataclass
class IDPState:
    """qpos = [cart x (m), phi1, phi2 (rad, from upright)], qvel; what MuJoCo's last stage left:
    the tip's world (x, z) and the slider's constraint force; the step count."""

    qpos: jax.Array
    qvel: jax.Array
    tip: jax.Array
    slider_force: jax.Array
    t: jax.Array


VARIANTS = {"standard": IDPParams()}

# Colours of the MJCF: blue rail, yellow cart, teal poles; a pale sky behind them.
RAIL, CART, POLE_COLOUR, BACKGROUND = (
    (0.3, 0.3, 0.7),
    (0.7, 0.7, 0.0),
    (0.0, 0.7, 0.7),
    (0.92, 0.95, 1.0),
)
CENTRE, HALF_EXTENT = (0.0, 0.5), 1.8  # the view: x in [-1.8, 1.8], z in [-1.3, 2.3]
# Drawn sizes (m). The poles are drawn thicker than their 0.045 m capsules so that a 64x64
# picture (0.056 m per pixel) shows them as solid lines rather than anti-aliased wisps.
RAIL_RADIUS, CART_RADIUS, CART_HALF_LENGTH, POLE_RADIUS = 0.03, 0.1, 0.12, 0.08


def pole_ends(qpos: jax.Array) -> tuple[jax.Array, jax.Array, jax.Array]:
    """World (x, z) of the cart, the middle hinge and the tip."""
    cart = jnp.stack([qpos[0], jnp.zeros_like(qpos[0])])
    phi1, phi12 = qpos[1], qpos[1] + qpos[2]
    hinge = cart + POLE * jnp.stack([jnp.sin(phi1), jnp.cos(phi1)])
    tip = hinge + POLE * jnp.stack([jnp.sin(phi12), jnp.cos(phi12)])
    return cart, hinge, tip


class InvertedDoublePendulum(MjxEnv):
    name = NAME
    mjcf = MJCF
    max_steps = 1000
    action_size = 1

    def default_params(self) -> IDPParams:
        return VARIANTS["standard"]

    def _state(self, data: Readout, t: jax.Array) -> IDPState:
        tip = data.site_xpos[self.site_ids["tip"]][jnp.array([0, 2])]
        return IDPState(data.qpos, data.qvel, tip, data.qfrc_constraint[0], t)

    def state_at(self, qpos, qvel, t=0) -> IDPState:
        """The state at (qpos, qvel) with MuJoCo's kinematics and constraint force computed."""
        f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
        data = self.physics.run(
            f32(qpos), f32(qvel), jnp.zeros(1, jnp.float32), 0, contact_forces=False
        )
        return self._state(data, jnp.asarray(t, jnp.int32))

    def initial_state(self, key: jax.Array, params: IDPParams) -> IDPState:
        k_pos, k_vel = jax.random.split(key)
        noise = params.reset_noise_scale
        qpos = jax.random.uniform(k_pos, (3,), jnp.float32, -noise, noise)
        qvel = noise * jax.random.normal(k_vel, (3,), jnp.float32)
        return self.state_at(qpos, qvel)

    def action_range(self, params: IDPParams) -> tuple[jax.Array, jax.Array]:
        return -jnp.ones(1), jnp.ones(1)  # the slider's ctrlrange

    def transition(self, key, state: IDPState, action, params: IDPParams) -> Step:
        ctrl = jnp.clip(jnp.reshape(action, (1,)), *self.action_range(params))
        data = self.physics.run(
            state.qpos, state.qvel, ctrl, params.frame_skip, contact_forces=False
        )
        next_state = self._state(data, state.t)
        x, y = next_state.tip[0], next_state.tip[1]
        terminated = y <= params.min_tip_height
        w1, w2 = data.qvel[1], data.qvel[2]
        distance_penalty = 0.01 * x**2 + (y - 2) ** 2
        velocity_penalty = 1e-3 * w1**2 + 5e-3 * w2**2
        alive_bonus = params.healthy_reward * (~terminated)
        return Step(next_state, alive_bonus - distance_penalty - velocity_penalty, terminated)

    def render(self, state: IDPState, params: IDPParams) -> jax.Array:
        """uint8[64, 64, 3]: fixed side view of the rail, the cart and the two poles."""
        size = self.image_size
        pixel = 2 * HALF_EXTENT / size
        points = raster.pixel_centres(size, HALF_EXTENT, CENTRE)
        cart, hinge, tip = pole_ends(state.qpos)
        along = jnp.array([CART_HALF_LENGTH, 0.0], jnp.float32)
        shapes = (
            (
                raster.segment_distance(points, jnp.array([-1.0, 0.0]), jnp.array([1.0, 0.0])),
                RAIL_RADIUS,
                RAIL,
            ),
            (raster.segment_distance(points, cart - along, cart + along), CART_RADIUS, CART),
            (raster.segment_distance(points, cart, hinge), POLE_RADIUS, POLE_COLOUR),
            (raster.segment_distance(points, hinge, tip), POLE_RADIUS, POLE_COLOUR),
        )
        image = raster.canvas(size, BACKGROUND)
        for distance, radius, colour in shapes:
            image = raster.paint(image, raster.coverage(distance, radius, pixel), colour)
        return raster.to_uint8(image)

    def state_obs(self, state: IDPState, params: IDPParams) -> jax.Array:
        return observation(state)


def observation(state: IDPState) -> jax.Array:
    """float32[9] = [x, sin phi1, sin phi2, cos phi1, cos phi2, clip(qvel, 10), clip(slider force,
    10)]."""
    q = state.qpos
    return jnp.concatenate(
        [
            q[:1],
            jnp.sin(q[1:]),
            jnp.cos(q[1:]),
            jnp.clip(state.qvel, -10, 10),
            jnp.clip(state.slider_force, -10, 10)[None],
        ]
    )


# -- hints (SPEC section 3) ---------------------------------------------------------------------


register_link_velocity_hints(NAME, lambda state: state.qvel[1:])


@register_hint(NAME, "goal_distance", dim=1, unit="m")
def goal_distance(state: IDPState, params: IDPParams) -> jax.Array:
    """D_goal = sum l_i - sum l_i cos(phi_i), phi_i = pole i's absolute angle from upright."""
    q = state.qpos
    return 2 * POLE - POLE * (jnp.cos(q[1]) + jnp.cos(q[1] + q[2]))


@register_hint(NAME, "partial_state", dim=7, unit="1, 1, 1, m/s, rad/s, rad/s, N")
def partial_state(state: IDPState, params: IDPParams) -> jax.Array:
    """The state observation without its first two entries (cart x and sin phi1)."""
    return observation(state)[2:]


@register_hint(NAME, "state", dim=9, unit="m, 1, 1, 1, 1, m/s, rad/s, rad/s, N")
def full_state(state: IDPState, params: IDPParams) -> jax.Array:
    """The full state observation."""
    return observation(state)


# Training defaults, RunConfig layers over the dataclasses' (hintsjax/settings/env_defaults.py): the
# hint, deploy variants and PPO settings of every agent; `learners`, the layer of every agent but
# the converged references; `agents`, an agent's own layer (the references' budgets and settings).
# Early IDP episodes last ~10 steps, so an episode count would be a tiny budget: we count
# 200 full-length episodes (200 K steps), the pendulum's budget. 128 envs per seed (rollouts
# of 8 steps per 1024-transition batch): MJX's RK4 with the rail's constraint solver is
# kernel-launch bound at small batches on a GPU (16 envs x 5 seeds ran ~6 K steps/s).
# Its expert and GAIL step 512 envs per seed in batches of 4096 (4x fewer sequential steps).
# GAIL's reward is Ho and Ermon's -log(1 - D) > 0 here: with the signed log odds, mostly
# negative at first, ending an episode early pays, and idp's episodes end by falling (GAIL
# scored 71 that way; measured in experiments/results/classic_table2.md).
EXPERT_PPO = dict(total_env_steps=1_000_000, num_envs=512, batch_size=4096)
TRAINING = dict(
    hint="composite",
    ppo=dict(total_env_steps=200_000, num_envs=128, reward_scale=0.1),
    agents=dict(
        expert_ppo=dict(ppo=EXPERT_PPO),
        gail=dict(ppo=EXPERT_PPO, gail=dict(reward="original")),
        dagger=dict(ppo=dict(total_env_steps=100_000), dagger=dict(buffer_size=100_000)),
    ),
)
