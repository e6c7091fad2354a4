"""Any MJX task that keeps its own reset and step (a MuJoCo Playground env, a Brax env) as a
hintsjax Env: `env=playground:CartpoleSwingup`, `env=brax:hopper` (docs/playground.md).

The task steps itself; the adapter adds what hintsjax needs around it:
- termination from the task's `done`, and truncation, kept apart, at the task's episode length
  (what Brax's EpisodeWrapper would count, in control steps of `action_repeat` task steps);
- the picture: render3d's drawing of the model's geoms (envs/render3d.py), from the variant's
  camera: `tracking` (a camera following the centre of mass, as the locomotion envs') or one of
  the model's named cameras;
- the state a hint reads (`AdaptedState`: the task's own state, its `mjx.Data` as `.data`, and
  the last step's reward) and the generic hints every adapted env has (`register_generic_hints`).

A source (envs/playground.py, envs/brax_env.py) loads a task into a `Task`; the registry
(envs/__init__.py) makes one entry per `<source>:<task>` name when it is first asked for.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import jax
import jax.numpy as jnp
import mujoco
from flax import struct

from hintsjax.envs import render3d
from hintsjax.envs.core import OBS_KEYS, Env, Step
from hintsjax.envs.errors import ChoiceError
from hintsjax.envs.hints import Hint, register_hint

# the variant whose camera follows the centre of mass; the others are the model's cameras
TRACK = "tracking"


class EnvUnavailable(ChoiceError):
    """An adapted env that cannot be made here (its package missing, its model not loading, a geom
    the picture cannot draw): reported in one line, like an unknown name."""

    def __init__(self, message: str):
        ValueError.__init__(self, message)


@dataclass(frozen=True)
class Task:
    """A loaded task: its hintsjax name (`source:task`), the task's env (`reset(rng)`,
    `step(state, action)`, `action_size`), its MuJoCo C model, which field of the task's state
    holds its `mjx.Data`, the control steps before a time limit, the task steps per control step
    and the camera of the default variant."""

    name: str
    env: Any
    mj_model: mujoco.MjModel
    data_field: str
    episode_length: int
    action_repeat: int = 1
    camera: str = TRACK


@struct.dataclass
class AdaptedParams:
    """The variant's camera: `tracking` or a named camera of the model (static: a program per
    camera)."""

    camera: str = struct.field(pytree_node=False, default=TRACK)


@struct.dataclass
class AdaptedState:
    """The task's own state (Playground's `State`, Brax's `State`), the reward of the last step
    (0 after a reset) and the control step `t`. `data` is the task's `mjx.Data`. Arrays of size 0
    (an `mjx.Data`'s `act` in a model without activations, ...) are None here: a checkpoint cannot
    hold them, and the adapter puts them back before the task steps."""

    task: Any
    reward: jax.Array
    t: jax.Array
    data_field: str = struct.field(pytree_node=False, default="data")

    @property
    def data(self) -> Any:
        """The task's `mjx.Data` (qpos, qvel, xpos, sensordata, ...), as MuJoCo names its fields."""
        return getattr(self.task, self.data_field)


_RESET_SHAPES: dict[str, Any] = {}


def reset_shapes(task: Task) -> Any:
    """The shapes and dtypes of the task's reset state (traced once per task and process: a Brax
    reset takes seconds to trace)."""
    if task.name not in _RESET_SHAPES:
        _RESET_SHAPES[task.name] = jax.eval_shape(
            task.env.reset, jax.random.key_data(jax.random.key(0))
        )
    return _RESET_SHAPES[task.name]


def observation_size(task: Task) -> int:
    """The length of the task's observation (`task_observation`)."""
    obs = reset_shapes(task).obs
    obs = obs.get("state") if isinstance(obs, dict) else obs
    if obs is None:
        raise EnvUnavailable(f"{task.name}: its observation is a dictionary without 'state'")
    return math.prod(obs.shape)


def camera_names(mj_model: mujoco.MjModel) -> list[str]:
    """The model's cameras by name (`camera<i>` for an unnamed one)."""
    return [mj_model.camera(i).name or f"camera{i}" for i in range(mj_model.ncam)]


def variants(task: Task) -> dict[str, AdaptedParams]:
    """The task's variants, one per camera, the task's default camera first."""
    names = [TRACK, *(c for c in camera_names(task.mj_model) if c != TRACK)]
    if task.camera not in names:
        raise ChoiceError("camera", task.camera, names, where=task.name)
    return {
        name: AdaptedParams(name) for name in [task.camera, *(n for n in names if n != task.camera)]
    }


def make_scene(task: Task) -> render3d.Scene:
    """render3d's scene of the task's model; EnvUnavailable naming the task and the first geom
    render3d cannot draw (a mesh, a height field)."""
    try:
        return render3d.make_scene(task.mj_model)
    except ValueError as e:
        raise EnvUnavailable(f"{task.name}: cannot draw its model: {e}") from None


class AdaptedEnv(Env):
    """A `Task` as an Env: its reset and step, with the adapter's picture, state observation,
    truncation and hints. Made by `envs.make('<source>:<task>', ...)`."""

    def __init__(
        self,
        hint: Hint,
        observe: tuple[str, ...] = OBS_KEYS,
        image_size: int | None = None,
        *,
        task: Task,
    ):
        super().__init__(hint, observe, image_size)
        self.task = task
        self.name = task.name
        self.mj_model = task.mj_model
        self.max_steps = task.episode_length // task.action_repeat
        self.action_size = int(task.env.action_size)
        self.cameras = camera_names(task.mj_model)
        self._variants = variants(task)
        self.scene = make_scene(task) if "pixels" in self.observe else None
        limited = task.mj_model.actuator_ctrllimited.astype(bool)[:, None]
        self.ctrl_range = jnp.asarray(
            jnp.where(limited, task.mj_model.actuator_ctrlrange, jnp.asarray([-1.0, 1.0])),
            jnp.float32,
        )
        self.extent = float(task.mj_model.stat.extent)
        self._shapes = reset_shapes(task)
        self.centre_height = float(task.mj_model.stat.center[2])

    def default_params(self) -> AdaptedParams:
        return next(iter(self._variants.values()))

    @property
    def state_size(self) -> int:
        return observation_size(self.task)

    def _state(self, task_state: Any, reward, t) -> AdaptedState:
        kept = jax.tree.map(lambda x: None if jnp.size(x) == 0 else x, task_state)
        return AdaptedState(
            kept, jnp.asarray(reward, jnp.float32), jnp.asarray(t, jnp.int32), self.task.data_field
        )

    def task_state(self, state: AdaptedState) -> Any:
        """The task's own state, its arrays of size 0 put back."""
        return jax.tree.map(
            lambda shape, x: jnp.zeros(shape.shape, shape.dtype) if x is None else x,
            self._shapes,
            state.task,
        )

    def initial_state(self, key: jax.Array, params: AdaptedParams) -> AdaptedState:
        # the tasks take raw keys
        raw = jax.random.key_data(key) if jnp.issubdtype(key.dtype, jax.dtypes.prng_key) else key
        return self._state(self.task.env.reset(raw), 0.0, 0)

    def action_range(self, params: AdaptedParams) -> tuple[jax.Array, jax.Array]:
        # the actuators' ctrlrange ([-1, 1] where unlimited)
        return self.ctrl_range[:, 0], self.ctrl_range[:, 1]

    def transition(self, key, state: AdaptedState, action, params: AdaptedParams) -> Step:
        """`action_repeat` steps of the task, their rewards summed (Brax's EpisodeWrapper); the
        task's `done` is a termination, the time limit (Env.step) a truncation."""
        ctrl = jnp.clip(jnp.reshape(action, (self.action_size,)), *self.action_range(params))
        task_state, reward = self.task_state(state), jnp.zeros((), jnp.float32)
        for _ in range(self.task.action_repeat):
            task_state = self.task.env.step(task_state, ctrl)
            reward = reward + jnp.asarray(task_state.reward, jnp.float32)
        return Step(
            self._state(task_state, reward, state.t), reward, jnp.asarray(task_state.done) > 0.5
        )

    def state_obs(self, state: AdaptedState, params) -> jax.Array:
        """float32[n] the task's observation (its `state` entry where it is a dictionary)."""
        return task_observation(self.task, state.task.obs)

    def camera(self, data: Any, params: AdaptedParams) -> render3d.Camera:
        """The variant's camera: `tracking` looks along +y at the centre of mass (at the model's
        centre height) from 1.5 model extents, 20 degrees above; a named camera is the model's."""
        if params.camera == TRACK:
            com = data.subtree_com[0]
            target = jnp.stack([com[0], com[1], jnp.float32(self.centre_height)])
            return render3d.tracking_camera(target, 1.5 * self.extent, -20.0, 90.0)
        i = self.cameras.index(params.camera)
        return render3d.Camera(
            data.cam_xpos[i], data.cam_xmat[i].reshape(3, 3), float(self.mj_model.cam_fovy[i])
        )

    def render(self, state: AdaptedState, params: AdaptedParams) -> jax.Array:
        """uint8[64, 64, 3]: the model's geoms from the variant's camera."""
        scene = self.scene if self.scene is not None else make_scene(self.task)
        data = state.data
        return render3d.render(
            scene, data.geom_xpos, data.geom_xmat, self.camera(data, params), self.image_size
        )


def task_observation(task: Task, obs: Any) -> jax.Array:
    """float32[n] a task's observation: the array, or a dictionary's `state` entry."""
    if isinstance(obs, dict):
        if "state" not in obs:
            raise EnvUnavailable(
                f"{task.name}: its observation is a dictionary without 'state' ({', '.join(obs)})"
            )
        obs = obs["state"]
    return jnp.asarray(obs, jnp.float32).reshape(-1)


# -- the hints every adapted env has -----------------------------------------------------------


def last_reward(state: AdaptedState, params) -> jax.Array:
    """The reward of the last step (0 at the start)."""
    return state.reward


def body_velocity(data: Any, body: int, root: int) -> jax.Array:
    """float32[3] the world-frame linear velocity of body `body`'s centre of mass, as MuJoCo's
    mj_objectVelocity (mjOBJ_BODY) reads it from `cvel` (spatial, at the subtree centre of mass
    of the body's root `root`): as the data holds it, so after a step the velocity it began with."""
    angular, linear = data.cvel[body, :3], data.cvel[body, 3:]
    return linear + jnp.cross(angular, data.xipos[body] - data.subtree_com[root])


def register_generic_hints(task: Task) -> None:
    """The hints of any adapted env, no code needed: `reward` (the last step's), `state` (the
    task's observation), `sensor:<name>` (a named sensor's reading, in the sensor's unit) and
    `body_velocity:<name>` (a body's centre of mass's velocity, m/s, world frame) for each of the
    model's."""
    model = task.mj_model
    register_hint(task.name, "reward", dim=1, unit="reward")(last_reward)

    def full_state(state: AdaptedState, params) -> jax.Array:
        """The task's observation."""
        return task_observation(task, state.task.obs)

    register_hint(task.name, "state", dim=observation_size(task), unit="the task's observation")(
        full_state
    )
    for i in range(model.nsensor):
        adr, dim = int(model.sensor_adr[i]), int(model.sensor_dim[i])

        def sensor(state: AdaptedState, params, adr=adr, dim=dim) -> jax.Array:
            """A sensor's reading (MuJoCo's sensordata)."""
            return state.data.sensordata[adr : adr + dim]

        register_hint(
            task.name,
            f"sensor:{model.sensor(i).name or f'sensor{i}'}",
            dim=dim,
            unit="the sensor's",
        )(sensor)
    for b in range(1, model.nbody):
        root = int(model.body_rootid[b])

        def velocity(state: AdaptedState, params, b=b, root=root) -> jax.Array:
            """A body's centre of mass's velocity (world frame)."""
            return body_velocity(state.data, b, root)

        register_hint(
            task.name, f"body_velocity:{model.body(b).name or f'body{b}'}", dim=3, unit="m/s"
        )(velocity)
