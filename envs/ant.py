"""Ant on MJX: Gymnasium `Ant-v5` (its `ant.xml`, frame skip 5, reward, health and observation).

Solver override (`locomotion.SOLVER`): Newton with at most 8 iterations and 16 line-search steps
instead of MuJoCo's 100 and 50 (MJX runs every iteration for every env under vmap). From the
expert's running states this steps as MuJoCo C does to 1e-4; 4 iterations, the earlier
cap, missed by 0.011. The model is otherwise Gymnasium's file unchanged (RK4, dt 0.01,
frame skip 5: 0.05 s per step). What remains is MJX's: from states with legs on the floor under
random or saturated actions, MJX (its JAX solver and MJX-Warp alike) misses MuJoCo C by up to 1.5
in a velocity (0.07 on average), whatever the iterations, because it orients the friction pyramid
of a plane contact differently. Elliptic cones, where MJX matches MuJoCo C, would be a different
model from Gymnasium's: MuJoCo C with them misses the shipped Ant-v5 by up to 2.2 (0.17 on
average) and by 2.6 from the expert's states (experiments/fidelity.py; docs/environments.md).

More of what it owns and why: docs/design.md, "Module notes", envs/ant.py.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco

from hintsjax.envs.hints import register_hint, share_hints
from hintsjax.envs.locomotion import (
    LocomotionEnv,
    LocomotionParams,
    LocomotionState,
    torso_height_above_target,
)
from hintsjax.envs.physics import Readout

NAME = "ant"
TORSO = 1  # body id of the torso, Gymnasium's `main_body`

VARIANTS = {
    "standard": LocomotionParams(
        forward_reward_weight=1.0,
        ctrl_cost_weight=0.5,
        contact_cost_weight=5e-4,
        healthy_reward=1.0,
        healthy_z_low=0.2,
        healthy_z_high=1.0,
        reset_noise_scale=0.1,
        target_height=0.75,
    )
}


def contact_forces(data: Readout) -> jax.Array:
    """float32[nbody, 6] cfrc_ext clipped to v5's contact force range [-1, 1]."""
    return jnp.clip(data.cfrc_ext, -1.0, 1.0)


class Ant(LocomotionEnv):
    name = NAME
    asset = "ant.xml"
    variants = VARIANTS
    action_size = 8
    camera = dict(distance=3.5, elevation_deg=-35.0, azimuth_deg=90.0)
    camera_height = 0.4

    def position(self, data: Readout) -> jax.Array:
        return data.xpos[TORSO, :2]

    def outcome(self, data, velocity, ctrl, params):
        z = data.qpos[2]
        finite = jnp.all(jnp.isfinite(data.qpos)) & jnp.all(jnp.isfinite(data.qvel))
        healthy = finite & (z >= params.healthy_z_low) & (z <= params.healthy_z_high)
        ctrl_cost = params.ctrl_cost_weight * jnp.sum(ctrl**2)
        contact_cost = params.contact_cost_weight * jnp.sum(contact_forces(data) ** 2)
        reward = (
            params.forward_reward_weight * velocity[0]
            + params.healthy_reward * healthy
            - ctrl_cost
            - contact_cost
        )
        return reward, ~healthy

    def observe_data(self, data: Readout) -> jax.Array:
        return jnp.concatenate([data.qpos[2:], data.qvel, contact_forces(data)[1:].ravel()])


# -- hints (SPEC section 3) ---------------------------------------------------------------------


@register_hint(NAME, "speed", dim=1, unit="m/s")
def speed(state: LocomotionState, params) -> jax.Array:
    """The torso's planar speed over the last step, |(dx, dy)| / dt."""
    return jnp.linalg.norm(state.velocity)


register_hint(NAME, "goal_height", dim=1, unit="m")(torso_height_above_target)


@register_hint(NAME, "state", dim=105, unit="v5 observation")
def full_state(state: LocomotionState, params) -> jax.Array:
    """The full state observation."""
    return state.obs


# -- ant_fast: another, cheaper task on the ant's body (not Ant-v5's dynamics) ---------------------

FAST_NAME = "ant_fast"
# The capsules from the torso to the knees: they reach the floor only once the ant lies on them.
ABOVE_KNEES = tuple(
    f"{part}_geom"
    for part in (
        "aux_1",
        "aux_2",
        "aux_3",
        "aux_4",
        "left_leg",
        "right_leg",
        "back_leg",
        "rightback_leg",
    )
)


class AntFast(Ant):
    """`ant_fast`: a different, cheaper task on the ant's body, not the ant made faster. Euler
    instead of RK4 (one forward pass per substep, not four), Newton capped at 2 iterations and 4
    line-search steps (with Euler, 2 miss Gymnasium's steps by as much as 4 do, and 1 by far
    more: tests/envs/test_locomotion.py), and floor contacts only for the torso and the four lower
    legs (9 contacts instead of 25). Reward, termination, observation and hints are the ant's, but
    not its dynamics: the ant's expert, 5726 on Ant-v5, scores 68 here and falls in 59 of 60
    episodes (experiments/results/fidelity.md). Its distance from Ant-v5 as shipped and from
    MuJoCo C with the same changes is measured by the ant_fast tests in
    tests/envs/test_locomotion.py."""

    name = FAST_NAME
    options = {
        **Ant.options,
        "integrator": mujoco.mjtIntegrator.mjINT_EULER,
        "iterations": 2,
        "ls_iterations": 4,
    }

    @classmethod
    def adapt(cls, model: mujoco.MjModel) -> mujoco.MjModel:
        for name in ABOVE_KNEES:
            model.geom_contype[model.geom(name).id] = model.geom_conaffinity[
                model.geom(name).id
            ] = 0
        return super().adapt(model)


share_hints(FAST_NAME, NAME)


# Training defaults, RunConfig layers over the dataclasses' (hintsjax/settings/env_defaults.py): the
# hint, deploy variants and PPO settings of every agent; `learners`, the layer of every agent but
# the converged references; `agents`, an agent's own layer (the references' budgets and settings).
# Ant steps 256 envs per seed (rollouts of 4 steps per 1024-transition batch): each of its
# steps is 5 RK4 substeps with 25 floor contacts, latency-bound at these sizes on a GPU, so
# half the rollout length nearly halves a 5 M-step run (a speed choice, SPEC section 5).
# At Table 5's rates (encoder 1e-3, 8 epochs) every ant hint agent's PPO blew up as the
# cheetah's had (approx. KL above 0.5 by update 115 to 360, then std runaway to saturated
# actions; experiments/results/locomotion_ppo_stability.md), so the ant and humanoid take the
# cheetah's encoder 3e-4 and 4 epochs, every agent alike.
# Even so, the ant's pixel agents blew up (approx. KL > 0.5 in 6 to 57% of updates;
# hints-fc-state scored -952 +- 2407). A KL early stop (ppo.target_kl 0.05, as in
# Stable-Baselines3) held the same run to 11% and 2318 +- 808, every seed above 1600 (the
# stability notes), so the ant's learners take it (its references, PPO on the state, were
# stable without). Still, 11 of 25 seeds of the design command had a KL storm (10 or more updates
# in a row above a KL of 0.5) and 2 of them ended lost at the joint limits: the stop cannot stop an
# update's first step. rsl_rl's adaptive rate (ppo.kl_adaptive_lr), which carries a rate cut by one
# update's KL into the next, had none in 10 seeds and kept the return (1180 [921, 1439] against
# 1060 [990, 1199]; the stability notes, "The two candidates to the end"), so the learners take it.
# Ant's expert: PPO on the state for 10 M steps (2x the hint agents', what fits one GPU lease
# beside the Table 3 rows), 1024 envs per seed in batches of 8192, minibatches of 1024, 8
# epochs. Not tuned further: it scored 5694 (5 seeds x 50 episodes).
# Ant and Humanoid episodes end when the robot falls, so their GAIL is paid Ho and Ermon's
# -log(1 - D) > 0, as idp's is: with the signed log odds, falling early would pay.
EXPERT_PPO = dict(
    total_env_steps=10_000_000, num_envs=1024, batch_size=8192, minibatch_size=1024, epochs=8
)
TRAINING = dict(
    hint="speed",
    ppo=dict(total_env_steps=5_000_000, num_envs=256, encoder_lr=3e-4, epochs=4),
    learners=dict(ppo=dict(target_kl=0.05, kl_adaptive_lr=True)),
    agents=dict(
        expert_ppo=dict(ppo=EXPERT_PPO),
        gail=dict(ppo=EXPERT_PPO, gail=dict(reward="original")),
        dagger=dict(ppo=dict(total_env_steps=250_000), dagger=dict(buffer_size=250_000)),
    ),
)
# The fast-physics ant (AntFast) trains as the ant does, with each env's next start drawn once
# per rollout (ppo.starts_per_rollout), as its throughput figure is measured.
FAST_TRAINING = {**TRAINING, "ppo": {**TRAINING["ppo"], "starts_per_rollout": True}}
