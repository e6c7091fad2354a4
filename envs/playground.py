"""MuJoCo Playground's tasks as hintsjax envs: `env=playground:<name>` (docs/playground.md).

`pip install -e '.[playground]'` installs MuJoCo Playground (`playground` on the package index;
imported as `mujoco_playground`). A task is loaded with MJX's JAX physics (`impl=jax`: Playground
0.2.0's default is MuJoCo Warp), stepped by its own `step` and adapted by envs/adapter.py.

The table below (`DEFAULTS`) gives the DeepMind Control tasks this project trains (issue 48)
their camera, a natural hint and their training settings; any other task takes `FALLBACK`.
`playground:<task>:vision` is the task as Playground configures it for training from pixels
(`VisionTask`), so that both pipelines can train on one reward (issue 83).
"""

from __future__ import annotations

import contextlib
import io
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import mujoco

from hintsjax.envs.adapter import TRACK, AdaptedState, EnvUnavailable, Task
from hintsjax.envs.errors import ChoiceError
from hintsjax.envs.hints import register_hint

SOURCE = "playground"
# `<task>:vision`: Playground's `vision=True` configuration of the task (`VisionTask`)
VISION = "vision"
CARTPOLES = ("CartpoleBalance", "CartpoleBalanceSparse", "CartpoleSwingup", "CartpoleSwingupSparse")
# the tasks whose vision configuration hintsjax reproduces (the sparse ones have none)
VISION_TASKS = ("CartpoleBalance", "CartpoleSwingup")


@dataclass(frozen=True)
class TaskDefaults:
    """A task's defaults: the camera of its default variant, its default hint and the PPO
    settings of its agents (RunConfig's `ppo` section; hintsjax/settings/env_defaults.py reads
    them)."""

    camera: str = TRACK
    hint: str = "reward"
    ppo: dict[str, Any] = field(default_factory=dict)


# DeepMind Control from pixels: 1 M env steps (1000 episodes of 1000 steps), 128 envs per seed; the
# cheetah's stable pixel settings (encoder 3e-4, 4 epochs: envs/halfcheetah.py) for every task, as
# nothing here is tuned yet. The fallback for a task not in the table is the same, with the
# generic `reward` hint and the tracking camera.
PIXEL_PPO = dict(total_env_steps=1_000_000, num_envs=128, encoder_lr=3e-4, epochs=4)
FALLBACK = TaskDefaults(ppo=PIXEL_PPO)
DEFAULTS: dict[str, TaskDefaults] = {
    "CartpoleSwingup": TaskDefaults("fixed", "pole_angle", PIXEL_PPO),
    # The cheetah's reset settles it with 200 physics steps (130.8 ms for 16 envs on 2 CPU cores,
    # a step 1.6 ms). Drawn for every env at every step (before the rollout drew the ended envs'
    # alone, AutoReset.step_ended) an adapted step took 178.8 ms, 13.2 ms with one draw a rollout
    # of 8 steps, and a CheetahRun update several times as long on a GPU (docs/playground.md);
    # its 1000-step episodes end together, so step_ended may serve as well: to be measured.
    "CheetahRun": TaskDefaults(TRACK, "torso_velocity", {**PIXEL_PPO, "starts_per_rollout": True}),
    "WalkerWalk": TaskDefaults(TRACK, "torso_height_velocity", PIXEL_PPO),
    "ReacherEasy": TaskDefaults("fixed", "fingertip_to_target", PIXEL_PPO),
    # Playground's vision configuration renders the `fixed` camera (cam_active (True, False))
    **{f"{task}:{VISION}": TaskDefaults("fixed", "pole_angle", PIXEL_PPO) for task in VISION_TASKS},
}


def _registry() -> Any:
    """Playground's registry (its import prints nothing we need); EnvUnavailable without it."""
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            from mujoco_playground import registry
    except ImportError:
        raise EnvUnavailable(
            "env=playground:<name> needs MuJoCo Playground: pip install -e '.[playground]'"
        ) from None
    return registry


def names() -> list[str]:
    """Every Playground task's name."""
    return list(_registry().ALL_ENVS)


def _mend_mujoco_version_check() -> None:
    """Playground 0.2.0's reacher picks MjSpec's API by comparing version strings ("3.17.0" <
    "3.3.0"), so on MuJoCo 3.10 and later it calls `find_body`, which MuJoCo has renamed `body`."""
    if not hasattr(mujoco.MjSpec, "find_body"):
        mujoco.MjSpec.find_body = mujoco.MjSpec.body


class VisionTask:
    """A cartpole as Playground 0.2.0 configures it with `vision=True`, without its renderer
    (MuJoCo Warp's, GPU only and built for one batch size): the additive `_dense_vision_reward`,
    an end when the pole leaves the upper half-plane or the cart passes 3 m, 250 steps an episode,
    and the vision reward's terms as its metrics. Its physics steps 0.01 s a control step, as
    Playground's does: its vision branch sets the config's ctrl_dt to 0.02 after the env has read
    it. The picture is the adapter's (render3d, the `fixed` camera); Playground's agent sees three
    stacked grey frames of its own renderer instead (`frames=3 colour=grey` shows hintsjax's
    agent the same of its own pictures)."""

    TERMS = ("alive", "pole_pos_penalty", "cart_pos_penalty", "cart_vel_penalty",
             "pole_vel_penalty", "action_penalty")  # fmt: skip
    EPISODE_LENGTH = 250
    CART_LIMIT = 3.0

    def __init__(self, env: Any):
        self.env = env  # Playground's task with vision off: its physics, reset and observation
        self.mj_model, self.mjx_model = env.mj_model, env.mjx_model
        self.action_size = env.action_size

    def reset(self, rng: jax.Array) -> Any:
        state = self.env.reset(rng)
        return state.replace(metrics={f"reward/{k}": jnp.zeros(()) for k in self.TERMS})

    def step(self, state: Any, action: jax.Array) -> Any:
        from mujoco_playground._src import mjx_env

        env = self.env
        data = mjx_env.step(env.mjx_model, state.data, action, env.n_substeps)
        metrics = dict(state.metrics)  # the reward writes its terms into it
        reward = env._dense_vision_reward(data, action, state.info, metrics)
        cart, pole = data.qpos[env._slider_qposadr], data.qpos[env._hinge_1_qposadr]
        done = (
            jnp.isnan(data.qpos).any()
            | jnp.isnan(data.qvel).any()
            | (jnp.abs(cart) > self.CART_LIMIT)
            | (jnp.abs(pole) > jnp.pi / 2)
        )
        return state.replace(
            data=data,
            obs=env._get_obs(data, state.info),
            reward=reward,
            done=done.astype(jnp.float32),
            metrics=metrics,
        )


def load(task: str) -> Task:
    """Playground's task `task` (or `<task>:vision`, `VisionTask`) with MJX's JAX physics;
    ChoiceError naming every task for an unknown one, EnvUnavailable for one that does not load
    here."""
    registry = _registry()
    base, colon, configuration = task.partition(":")
    if base not in registry.ALL_ENVS:
        raise ChoiceError("Playground env", base, registry.ALL_ENVS)
    if colon and configuration != VISION:
        raise ChoiceError(f"configuration of {base}", configuration, [VISION])
    if colon and base not in VISION_TASKS:
        raise ChoiceError("Playground task with a vision configuration", base, VISION_TASKS)
    _mend_mujoco_version_check()
    try:
        config = registry.get_default_config(base)
        env = registry.load(base, config_overrides={"impl": "jax"})
    except Exception as e:  # noqa: BLE001  Playground's own failure (a model it must download, ...), in one line
        raise EnvUnavailable(
            f"playground:{base} does not load: {type(e).__name__}: "
            f"{str(e).splitlines()[0][:200] if str(e) else ''}"
        ) from None
    length = int(config.episode_length)
    if colon:
        env, length = VisionTask(env), VisionTask.EPISODE_LENGTH
    return Task(
        f"{SOURCE}:{task}",
        env,
        env.mj_model,
        "data",
        length,
        int(config.get("action_repeat", 1)),
        DEFAULTS.get(task, FALLBACK).camera,
    )


def training(task: str) -> dict[str, Any]:
    """The task's training defaults (`TRAINING` of a native env: RunConfig layers)."""
    row = DEFAULTS.get(task, FALLBACK)
    return dict(hint=row.hint, ppo=dict(row.ppo))


# -- the natural hints of the table's tasks ----------------------------------------------------


def register_task_hints(task: Task) -> None:
    """The hints that `DEFAULTS` names for `task` (none for a task outside it)."""
    model, name = task.mj_model, task.name
    short = name.split(":")[1]  # the Playground task (`<task>:vision` too)
    if short in CARTPOLES:
        hinge = int(model.jnt_qposadr[model.joint("hinge_1").id])

        @register_hint(name, "pole_angle", dim=1, unit="rad")
        def pole_angle(state: AdaptedState, params) -> jax.Array:
            """The pole's angle from upright, in (-pi, pi]."""
            angle = state.data.qpos[hinge]
            return jnp.arctan2(jnp.sin(angle), jnp.cos(angle))

        @register_hint(name, "pole_angular_velocity", dim=1, unit="rad/s")
        def pole_angular_velocity(state: AdaptedState, params) -> jax.Array:
            """The pole's angular velocity."""
            return state.data.qvel[int(model.jnt_dofadr[model.joint("hinge_1").id])]
    elif short in ("CheetahRun", "WalkerWalk"):
        speed = int(model.sensor_adr[model.sensor("torso_subtreelinvel").id])
        torso = model.body("torso").id

        @register_hint(name, "torso_velocity", dim=1, unit="m/s")
        def torso_velocity(state: AdaptedState, params) -> jax.Array:
            """The torso subtree's forward (x) velocity, as the task's reward reads it."""
            return state.data.sensordata[speed]

        @register_hint(name, "torso_height_velocity", dim=2, unit="m, m/s")
        def torso_height_velocity(state: AdaptedState, params) -> jax.Array:
            """The torso's height and its subtree's forward velocity."""
            return jnp.stack([state.data.xpos[torso, 2], state.data.sensordata[speed]])
    elif short == "ReacherEasy":
        finger, target = model.geom("finger").id, model.geom("target").id

        @register_hint(name, "fingertip_to_target", dim=2, unit="m")
        def fingertip_to_target(state: AdaptedState, params) -> jax.Array:
            """The target's position minus the fingertip's, in the arm's plane (x, y)."""
            return state.data.geom_xpos[target, :2] - state.data.geom_xpos[finger, :2]
