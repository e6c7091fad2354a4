"""Humanoid on MJX: Gymnasium `Humanoid-v5` (its `humanoid.xml`, frame skip 5, reward, health
and observation).

Two overrides of Gymnasium's file (`Humanoid.options`): Newton with at most 4 iterations and 8
line-search steps (the file's PGS is not in MJX), and semi-implicit Euler instead of its RK4, for
the GPU budget. Otherwise the file is unchanged (dt 0.003, frame skip 5; self-collisions on). Why,
and what each costs and leaves of the distance from Gymnasium: docs/environments.md, "Humanoid's
overrides".

Reward (v5): 1.25 x velocity of the centre of mass over the step + 5 while healthy
- 0.1 |a|^2 - min(5e-7 |cfrc_ext|^2, 10); healthy while 1 < torso height < 2; unhealthy
terminates. Observation (348): qpos[2:], qvel, cinert[1:], cvel[1:], qfrc_actuator[6:],
cfrc_ext[1:].
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import mujoco

from hintsjax.envs.hints import register_hint
from hintsjax.envs.locomotion import (
    LocomotionEnv,
    LocomotionParams,
    LocomotionState,
    forward_velocity,
    torso_height_above_target,
)
from hintsjax.envs.physics import Readout

NAME = "humanoid"
CONTACT_COST_MAX = 10.0

VARIANTS = {
    "standard": LocomotionParams(
        forward_reward_weight=1.25,
        ctrl_cost_weight=0.1,
        contact_cost_weight=5e-7,
        healthy_reward=5.0,
        healthy_z_low=1.0,
        healthy_z_high=2.0,
        reset_noise_scale=1e-2,
        target_height=1.4,
    )
}


class Humanoid(LocomotionEnv):
    name = NAME
    asset = "humanoid.xml"
    options = dict(
        solver=mujoco.mjtSolver.mjSOL_NEWTON,
        iterations=4,
        ls_iterations=8,
        integrator=mujoco.mjtIntegrator.mjINT_EULER,
    )  # module docstring
    variants = VARIANTS
    action_size = 17
    camera = dict(distance=3.0, elevation_deg=-15.0, azimuth_deg=90.0)
    camera_height = 1.0
    uniform_velocity_noise = True

    def position(self, data: Readout) -> jax.Array:
        return self.mass_centre(data)[:2]

    def outcome(self, data, velocity, ctrl, params):
        z = data.qpos[2]
        healthy = (z > params.healthy_z_low) & (z < params.healthy_z_high)
        ctrl_cost = params.ctrl_cost_weight * jnp.sum(ctrl**2)
        contact_cost = jnp.minimum(
            params.contact_cost_weight * jnp.sum(data.cfrc_ext**2), CONTACT_COST_MAX
        )
        reward = (
            params.forward_reward_weight * velocity[0]
            + params.healthy_reward * healthy
            - ctrl_cost
            - contact_cost
        )
        return reward, ~healthy

    def observe_data(self, data: Readout) -> jax.Array:
        return jnp.concatenate(
            [
                data.qpos[2:],
                data.qvel,
                data.cinert[1:].ravel(),
                data.cvel[1:].ravel(),
                data.qfrc_actuator[6:],
                data.cfrc_ext[1:].ravel(),
            ]
        )


# -- hints (SPEC section 3) ---------------------------------------------------------------------


register_hint(NAME, "velocity", dim=1, unit="m/s")(forward_velocity)
register_hint(NAME, "goal_height", dim=1, unit="m")(torso_height_above_target)


@register_hint(NAME, "state", dim=348, unit="v5 observation")
def full_state(state: LocomotionState, params) -> jax.Array:
    """The full state observation."""
    return state.obs


# Training defaults, RunConfig layers over the dataclasses' (hintsjax/settings/env_defaults.py): the
# hint, deploy variants and PPO settings of every agent; `learners`, the layer of every agent but
# the converged references; `agents`, an agent's own layer (the references' budgets and settings).
# Humanoid's learners take the ant's KL early stop and its 256 envs per seed (rollouts of 4
# steps: each update waits on 4 latency-bound MJX steps instead of 8). Its references follow
# the ant's: the expert is PPO on the state for 20 M steps (2x the learners'), 1024 envs per
# seed in batches of 8192, minibatches of 1024, 8 epochs; 50 M would take 3 h of GPU (5 seeds).
# Every humanoid agent learns from rewards x 0.1, and one that takes the state alone normalises
# it (its contact forces run to thousands; a hint, the state hint too, enters as generated);
# GAIL's discriminator reads it standardised by the demonstrations'
# statistics (gail.normalize_state) and is held smooth by an R1 penalty of 10 on the expert's
# pairs (gail.grad_penalty): without it D told the pairs apart perfectly within 200 updates, its
# reward -log(1 - D) went flat near 0 and GAIL scored 447; with it, 7334 (5 seeds x 50
# episodes; docs/throughput.md). The expert's PPO at 5 M steps, 2 seeds (evaluation 2 x 10
# episodes, in brackets the training return at the end): as listed 5617 (3897); without the
# entropy bonus 4923 (4061), its approx. KL rising to 0.7; without the bonus and the
# normaliser 513 (460); without the bonus, the normaliser and the reward scale 124 (118).
# The first 20 M run, with neither normaliser nor reward scale, was at 555 after 13.5 M
# steps, its std grown to 38 (the actions are clipped to +-0.4).
EXPERT_PPO = dict(
    total_env_steps=20_000_000, num_envs=1024, batch_size=8192, minibatch_size=1024, epochs=8
)
TRAINING = dict(
    hint="velocity",
    ppo=dict(
        total_env_steps=10_000_000,
        num_envs=256,
        encoder_lr=3e-4,
        epochs=4,
        reward_scale=0.1,
        normalize_state=True,
    ),
    learners=dict(ppo=dict(target_kl=0.05)),
    agents=dict(
        expert_ppo=dict(ppo=EXPERT_PPO),
        gail=dict(
            ppo=EXPERT_PPO, gail=dict(reward="original", normalize_state=True, grad_penalty=10.0)
        ),
        dagger=dict(ppo=dict(total_env_steps=250_000), dagger=dict(buffer_size=250_000)),
    ),
)
