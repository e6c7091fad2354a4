"""What Ant, HalfCheetah and Humanoid share: Gymnasium v5's MuJoCo locomotion tasks on MJX.

Each task is Gymnasium's own MJCF (envs/assets/, verbatim) stepped `frame_skip` times by MJX per
control step, followed, as Gymnasium does, by `mj_rnePostConstraint` so that the external
(contact) forces `cfrc_ext` are filled in. A task module supplies the model file, its solver
overrides (each documented there), its params, what the forward reward differentiates, its
reward and health rules and its observation; this module supplies the state, the step, the
reset and the picture (the shared ray caster `render3d`, from a camera that follows the centre
of mass at a fixed height, so that a fall shows as a fall). Which quantities are stale after a
step, as in MuJoCo C and Gymnasium, and how actions are clipped and charged:
docs/environments.md, "Locomotion in detail".
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco
from flax import struct

from hintsjax.envs import render3d
from hintsjax.envs.core import Step
from hintsjax.envs.mjx_env import MjxEnv
from hintsjax.envs.physics import Readout


@struct.dataclass
class LocomotionParams:
    """Gymnasium v5's constructor arguments (each task's defaults are in its VARIANTS)."""

    frame_skip: int = struct.field(pytree_node=False, default=5)
    forward_reward_weight: float = 1.0
    ctrl_cost_weight: float = 0.1
    contact_cost_weight: float = 0.0
    healthy_reward: float = 0.0
    healthy_z_low: float = -jnp.inf
    healthy_z_high: float = jnp.inf
    reset_noise_scale: float = 0.1
    target_height: float = 0.0  # the torso height that the `goal_height` hint is measured from (m)
    # Charge the control cost on the action as given (Gymnasium's rule) instead of the clipped one
    # (ours by default: module docstring); for comparison with published Gymnasium returns.
    raw_action_ctrl_cost: bool = struct.field(pytree_node=False, default=False)


@struct.dataclass
class LocomotionState:
    """The integrated qpos and qvel, and what the step computed from the last physics stage:
    the v5 observation, the geoms' poses (for the picture), the centre of mass, and the
    position the forward reward differentiates, with the velocity and reward of the last step
    (0 after a reset) and the largest forward velocity seen this episode."""

    qpos: jax.Array
    qvel: jax.Array
    obs: jax.Array
    geom_xpos: jax.Array
    geom_xmat: jax.Array
    com: jax.Array  # float32[3] the centre of mass of the whole robot (world frame)
    position: jax.Array  # float32[2] what the forward reward differentiates
    velocity: jax.Array  # float32[2] its rate over the last step (m/s)
    reward: jax.Array
    max_velocity: jax.Array  # the largest velocity[0] this episode (starts at 0)
    t: jax.Array


# The one change to Gymnasium's models: Newton capped at 8 iterations and 16 line-search steps
# instead of MuJoCo's 100 and 50 (MJX runs every iteration for every env under vmap). From
# Gymnasium's states, MuJoCo C at this cap steps as at 100 (to 1e-13) and MJX as closely as at 100;
# at the earlier caps of 4 and 8 the HalfCheetah's running states missed by up to 1.2 in a
# velocity and the Ant's by 0.011. 8 cost 1.09-1.46x the training time of 4 (docs/environments.md,
# "Fidelity"; experiments/results/fidelity.json).
SOLVER = dict(solver=mujoco.mjtSolver.mjSOL_NEWTON, iterations=8, ls_iterations=16)


class LocomotionEnv(MjxEnv):
    """The shared step, reset and picture. A task sets `asset`, `variants`, `action_size` and
    `camera` and implements `position`, `outcome` and `observe_data`."""

    options = SOLVER
    # physics=auto gives these MJX-Warp on an NVIDIA GPU: 3-6x MJX-JAX's env steps (the ant's
    # command 9 min against 28), and the ant learns alike on both at full budget (10 JAX seeds
    # against 20 Warp seeds, undecided; experiments/results/physics_learning_full.md)
    warp_by_default = True
    variants: dict[str, LocomotionParams] = {}
    max_steps = 1000
    camera: dict[str, float] = dict(distance=4.0, elevation_deg=-20.0, azimuth_deg=90.0)
    camera_height: float = 0.5  # the camera aims at the centre of mass's (x, y) at this height (m)
    # Humanoid draws qvel uniformly; Ant and HalfCheetah normally
    uniform_velocity_noise: bool = False
    contact_forces: bool = True  # the task reads `cfrc_ext` (mj_rnePostConstraint after each step)

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.scene = render3d.make_scene(self.mj_model)
        self.ctrl_range = jnp.asarray(self.mj_model.actuator_ctrlrange, jnp.float32)
        self.dt = float(self.mj_model.opt.timestep) * self.default_params().frame_skip
        self.body_mass = jnp.asarray(self.mj_model.body_mass, jnp.float32)

    def default_params(self) -> LocomotionParams:
        return self.variants["standard"]

    # -- what each task supplies --------------------------------------------------------------
    def position(self, data: Readout) -> jax.Array:
        """float32[2] what the forward reward differentiates (x, y; y may be 0)."""
        raise NotImplementedError

    def outcome(
        self, data: Readout, velocity: jax.Array, ctrl: jax.Array, params
    ) -> tuple[jax.Array, jax.Array]:
        """(reward, terminated) of a step that ended in `data` with `velocity` (float32[2]), its
        control cost charged on `ctrl` (the clipped action, or the raw one:
        `raw_action_ctrl_cost`)."""
        raise NotImplementedError

    def observe_data(self, data: Readout) -> jax.Array:
        """float32[n] Gymnasium v5's observation of `data`."""
        raise NotImplementedError

    # -- shared ---------------------------------------------------------------------------------
    def mass_centre(self, data: Readout) -> jax.Array:
        """float32[3] the mass-weighted mean of the bodies' centres (Gymnasium's `mass_center`)."""
        return self.body_mass @ data.xipos / jnp.sum(self.body_mass)

    def _state(self, data: Readout, position, velocity, reward, max_velocity, t) -> LocomotionState:
        return LocomotionState(
            qpos=data.qpos,
            qvel=data.qvel,
            obs=self.observe_data(data),
            geom_xpos=data.geom_xpos,
            geom_xmat=data.geom_xmat,
            com=self.mass_centre(data),
            position=position,
            velocity=velocity,
            reward=jnp.asarray(reward, jnp.float32),
            max_velocity=jnp.asarray(max_velocity, jnp.float32),
            t=jnp.asarray(t, jnp.int32),
        )

    def state_at(self, qpos, qvel, t=0) -> LocomotionState:
        """The state at (qpos, qvel) after MuJoCo's forward pass, as Gymnasium's `set_state`
        leaves it (with the contact forces filled in), and no step behind it."""
        f32 = lambda x: jnp.asarray(x, jnp.float32)  # noqa: E731
        data = self.physics.run(
            f32(qpos), f32(qvel), jnp.zeros(self.mj_model.nu, jnp.float32), 0, self.contact_forces
        )
        zero = jnp.zeros((), jnp.float32)
        return self._state(data, self.position(data), jnp.zeros(2, jnp.float32), zero, zero, t)

    def draw_start(self, key: jax.Array, params: LocomotionParams) -> tuple[jax.Array, jax.Array]:
        """(qpos, qvel) of a fresh episode: qpos0 + U(-s, s) and s N(0, 1) (Humanoid: U(-s, s))."""
        k_pos, k_vel = jax.random.split(key)
        noise = params.reset_noise_scale
        nq, nv = self.mj_model.nq, self.mj_model.nv
        qpos = jnp.asarray(self.mj_model.qpos0, jnp.float32) + jax.random.uniform(
            k_pos, (nq,), jnp.float32, -noise, noise
        )
        if self.uniform_velocity_noise:
            qvel = jax.random.uniform(k_vel, (nv,), jnp.float32, -noise, noise)
        else:
            qvel = noise * jax.random.normal(k_vel, (nv,), jnp.float32)
        return qpos, qvel

    def initial_state(self, key: jax.Array, params: LocomotionParams) -> LocomotionState:
        return self.state_at(*self.draw_start(key, params))

    def action_range(self, params: LocomotionParams) -> tuple[jax.Array, jax.Array]:
        return self.ctrl_range[:, 0], self.ctrl_range[:, 1]  # the actuators' ctrlrange

    def transition(self, key, state: LocomotionState, action, params: LocomotionParams) -> Step:
        action = jnp.reshape(action, (self.action_size,))
        ctrl = jnp.clip(action, *self.action_range(params))
        data = self.physics.run(
            state.qpos, state.qvel, ctrl, params.frame_skip, self.contact_forces
        )
        position = self.position(data)
        velocity = (position - state.position) / self.dt
        charged = action if params.raw_action_ctrl_cost else ctrl
        reward, terminated = self.outcome(data, velocity, charged, params)
        max_velocity = jnp.maximum(state.max_velocity, velocity[0])
        return Step(
            self._state(data, position, velocity, reward, max_velocity, state.t), reward, terminated
        )

    def state_obs(self, state: LocomotionState, params) -> jax.Array:
        return state.obs

    def render_camera(self, state: LocomotionState) -> render3d.Camera:
        """The camera that follows the robot's centre of mass, aimed at `camera_height`."""
        target = jnp.stack([state.com[0], state.com[1], jnp.float32(self.camera_height)])
        return render3d.tracking_camera(target, **self.camera)

    def render(self, state: LocomotionState, params) -> jax.Array:
        """uint8[64, 64, 3]: the robot from a camera following its centre of mass."""
        return render3d.render(
            self.scene, state.geom_xpos, state.geom_xmat, self.render_camera(state), self.image_size
        )


# -- hints that more than one task shares (SPEC section 3) ----------------------------------


def forward_velocity(state: LocomotionState, params) -> jax.Array:
    """The forward (x) velocity over the last step, as the reward measures it."""
    return state.velocity[0]


def torso_height_above_target(state: LocomotionState, params) -> jax.Array:
    """The torso's height minus the task's target height (its height at the start)."""
    return state.qpos[2] - params.target_height
