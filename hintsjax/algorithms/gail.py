"""GAIL (Ho and Ermon 2016) as one jittable, seed-vmappable `train(key)`.

At the start of a run the expert plays gail.demonstrations episodes (actions drawn from its
Gaussian), kept as (state, action) pairs with a mask for the steps before each episode ended.
Each update then rolls out the spine's PPO policy, trains the discriminator D(s, a) for
gail.disc_steps minibatch steps to tell expert pairs (label 1) from the rollout's (label 0), and
lets PPO learn from the discriminator's reward on the rollout instead of the env's:
`logit` gives log D - log(1 - D) (the default), `original` Ho and Ermon's -log(1 - D). The env's
own return is still what the run logs and what evaluation reports.

With gail.normalize_state, D reads the state standardised by the demonstrations' own mean and
variance (fixed for the run, clipped as ppo.normalize_state's are): without it, a few large
dimensions (the humanoid's contact forces, in the thousands) would dominate D's input.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct

from hintsjax import envs
from hintsjax.models.networks import MLP
from hintsjax.models.normalization import normalize
from hintsjax.settings.algorithm_settings import GailConfig
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms import experts
from hintsjax.algorithms.ppo import RunnerState, make_ppo
from hintsjax.algorithms.trainer import Trainer


@struct.dataclass
class Demonstrations:
    """The expert's (state, action) pairs, [D * L, ...], with `valid` false after an episode
    ended."""

    state: jax.Array
    action: jax.Array
    valid: jax.Array
    episode_return: jax.Array  # [D]
    state_mean: jax.Array  # [n], over the valid pairs
    state_var: jax.Array  # [n]

    def sample(self, key: jax.Array, n: int) -> tuple[jax.Array, jax.Array]:
        """n valid pairs drawn uniformly with replacement."""
        rows = jax.random.choice(key, self.valid.shape[0], (n,), p=self.valid / self.valid.sum())
        return self.state[rows], self.action[rows]


@struct.dataclass
class GailState:
    """PPO's runner state plus the discriminator and the demonstrations; a checkpoint saves all."""

    ppo: RunnerState
    disc_params: Any
    disc_opt_state: Any
    demos: Demonstrations

    @property
    def params(self) -> Any:
        """The policy's ActorCritic parameters (what evaluation uses)."""
        return self.ppo.params

    @property
    def update(self) -> jax.Array:
        return self.ppo.update


def demonstrate(
    env: Any, env_params: Any, expert: Any, key: jax.Array, episodes: int
) -> Demonstrations:
    """Roll the expert out for `episodes` whole episodes of a plain (not auto-resetting) env."""
    k_reset, k_run = jax.random.split(key)
    ts = envs.fresh_episodes(k_reset, env, env_params, episodes)

    def step(carry, key):
        env_state, obs, alive, ret = carry
        k_act, k_env = jax.random.split(key)
        action = expert.sample(k_act, obs["state"])
        ts = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
            jax.random.split(k_env, episodes), env_state, action, env_params
        )
        pair = (
            jnp.where(alive[:, None], obs["state"], 0.0),
            jnp.where(alive[:, None], action, 0.0),
            alive,
        )
        ret = ret + jnp.where(alive, ts.reward, 0.0)
        return (ts.state, ts.obs, alive & ~(ts.terminated | ts.truncated), ret), pair

    init = (ts.state, ts.obs, jnp.ones(episodes, bool), jnp.zeros(episodes))
    (_, _, _, ret), (state, action, valid) = jax.lax.scan(
        step, init, jax.random.split(k_run, env.max_steps)
    )
    flat = lambda x: x.reshape((-1,) + x.shape[2:])  # noqa: E731
    state, valid = flat(state), flat(valid)
    weight = valid[:, None] / valid.sum()
    mean = jnp.sum(weight * state, axis=0)
    var = jnp.sum(weight * (state - mean) ** 2, axis=0)
    return Demonstrations(state, flat(action), valid, ret, mean, var)


def make_discriminator(gail: GailConfig) -> MLP:
    """D's logit on concat(state, action): [B, n + A] -> [B, 1]."""
    return MLP((*gail.disc_hidden, 1))


def discriminator_loss(
    disc: MLP, params: Any, expert: jax.Array, policy: jax.Array, grad_penalty: float = 0.0
) -> tuple[jax.Array, dict]:
    """Binary cross-entropy with expert pairs labelled 1 and the policy's 0; inputs [B, n + A].

    With `grad_penalty` > 0 it adds grad_penalty * E_expert |d logit / d input|^2, the
    zero-centred R1 penalty of Mescheder et al. (2018): D cannot grow steep around the expert's
    pairs, so it keeps paying a policy that comes near them instead of separating the two sets
    perfectly (the humanoid's GAIL, whose reward went to 0 within 200 updates)."""
    logit_e, logit_p = disc.apply(params, expert)[..., 0], disc.apply(params, policy)[..., 0]
    loss = -jnp.mean(jax.nn.log_sigmoid(logit_e)) - jnp.mean(jax.nn.log_sigmoid(-logit_p))
    stats = {
        "disc_loss": loss,
        "disc_expert_acc": jnp.mean(logit_e > 0),
        "disc_policy_acc": jnp.mean(logit_p < 0),
    }
    if grad_penalty:
        slope = jax.vmap(jax.grad(lambda x: disc.apply(params, x[None])[0, 0]))(expert)
        penalty = jnp.mean(jnp.sum(slope**2, axis=-1))
        loss, stats = loss + grad_penalty * penalty, {**stats, "disc_grad_penalty": penalty}
    return loss, stats


def gail_reward(logit: jax.Array, kind: str) -> jax.Array:
    """The policy's reward from D's logit x (D = sigmoid(x), the probability of 'expert')."""
    if kind == "logit":
        return logit  # log D - log(1 - D)
    return jax.nn.softplus(logit)  # "original": -log(1 - D)


def pairs(state: jax.Array, action: jax.Array) -> jax.Array:
    return jnp.concatenate([state, action], axis=-1)


def make_trainer(cfg: RunConfig, expert: Any = None) -> Trainer:
    """GAIL's trainer; `expert` (anything with `sample(key, state)`) defaults to the env's packaged
    one."""
    ppo, gail = cfg.ppo, cfg.gail
    parts = make_ppo(cfg)
    expert = experts.load(cfg.env, cfg.expert) if expert is None else expert
    experts.check_state_size(expert, cfg, parts.env.state_size)
    disc = make_discriminator(gail)
    disc_opt = optax.chain(
        optax.clip_by_global_norm(ppo.max_grad_norm), optax.adam(gail.disc_lr, eps=1e-5)
    )

    def disc_input(demos: Demonstrations, state: jax.Array, action: jax.Array) -> jax.Array:
        if gail.normalize_state:
            state = normalize(demos.state_mean, demos.state_var, state)
        return pairs(state, action)

    def init(key: jax.Array) -> GailState:
        k_ppo, k_demo, k_disc = jax.random.split(key, 3)
        runner = parts.init(k_ppo)
        demos = demonstrate(parts.env.env, parts.env_params, expert, k_demo, gail.demonstrations)
        disc_params = disc.init(k_disc, disc_input(demos, demos.state[:1], demos.action[:1]))
        return GailState(runner, disc_params, disc_opt.init(disc_params), demos)

    def update(state: GailState) -> tuple[GailState, dict[str, jax.Array]]:
        key, k_roll, k_disc, k_epochs = jax.random.split(state.ppo.key, 4)
        runner, traj, last_value = parts.rollout(state.ppo, k_roll)
        policy_pairs = disc_input(state.demos, traj.obs["state"], traj.action)  # [T, N, n + A]
        flat_policy = policy_pairs.reshape(-1, policy_pairs.shape[-1])

        def disc_step(carry, key):
            params, opt_state = carry
            k_e, k_p = jax.random.split(key)
            expert_batch = disc_input(state.demos, *state.demos.sample(k_e, ppo.minibatch_size))
            policy_batch = flat_policy[
                jax.random.randint(k_p, (ppo.minibatch_size,), 0, flat_policy.shape[0])
            ]
            grads, stats = jax.grad(
                lambda p: discriminator_loss(
                    disc, p, expert_batch, policy_batch, gail.grad_penalty
                ),
                has_aux=True,
            )(params)
            updates, opt_state = disc_opt.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), stats

        (disc_params, disc_opt_state), disc_stats = jax.lax.scan(
            disc_step,
            (state.disc_params, state.disc_opt_state),
            jax.random.split(k_disc, gail.disc_steps),
        )
        reward = gail_reward(disc.apply(disc_params, policy_pairs)[..., 0], gail.reward)
        runner, metrics = parts.learn(runner, traj, last_value, reward, k_epochs)
        metrics = {
            **metrics,
            **jax.tree.map(jnp.mean, disc_stats),
            "gail_reward": reward.mean(),
            "demo_return": state.demos.episode_return.mean(),
        }
        new = GailState(runner.replace(key=key), disc_params, disc_opt_state, state.demos)
        return new, metrics

    return Trainer(cfg, parts.env, parts.network, init, update)
