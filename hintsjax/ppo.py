"""PPO as one jittable `train(key)`: rollout, GAE, clipped-surrogate loss and updates.

`make_trainer(cfg)` returns PPO's `Trainer` (hintsjax.trainer); `make_ppo(cfg)` its pieces
(init, rollout, learn), which GAIL reuses with the discriminator's reward.

Episodes carry `terminated` and `truncated` separately: GAE bootstraps a truncated episode from
the value of the state it was cut off in (the env's `final_obs`) and a terminated one from 0.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

import jax
import jax.numpy as jnp
import optax
from flax import struct

from hintsjax import envs, normalization
from hintsjax.config import PPOConfig, RunConfig
from hintsjax.networks import ActorCritic, lr_labels
from hintsjax.trainer import Trainer, episode_metrics


@struct.dataclass
class Transition:
    """One rollout step of every env; arrays are [T, N, ...] once stacked by the scan."""

    obs: dict[str, jax.Array]
    action: jax.Array
    log_prob: jax.Array
    value: jax.Array
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    final_value: jax.Array  # value of the pre-reset observation; used where truncated
    episode_return: jax.Array  # return of the episode that ended here (valid where done)


@struct.dataclass
class RunnerState:
    """Everything a run carries between updates; a checkpoint saves all of it."""

    params: Any
    opt_state: Any
    env_state: Any  # AutoReset's EpisodeState, batched [N]
    obs: dict[str, jax.Array]  # current observation, batched [N]
    key: jax.Array
    update: jax.Array  # updates done so far


@struct.dataclass
class Batch:
    """Flattened training samples [M, ...] with their advantage and value target."""

    obs: dict[str, jax.Array]
    action: jax.Array
    log_prob: jax.Array
    advantage: jax.Array
    target: jax.Array


# -- the pieces with hand-checkable arithmetic ----------------------------------------------------


def gaussian_log_prob(action: jax.Array, mean: jax.Array, log_std: jax.Array) -> jax.Array:
    """Log density of a diagonal Gaussian, summed over the last axis: [..., A] -> [...]."""
    z = (action - mean) * jnp.exp(-log_std)
    return jnp.sum(-0.5 * z**2 - log_std - 0.5 * jnp.log(2 * jnp.pi), axis=-1)


def gaussian_entropy(log_std: jax.Array) -> jax.Array:
    """Entropy of a diagonal Gaussian: [A] -> []."""
    return jnp.sum(log_std + 0.5 * (1.0 + jnp.log(2 * jnp.pi)), axis=-1)


def gae(
    reward: jax.Array,
    value: jax.Array,
    terminated: jax.Array,
    truncated: jax.Array,
    final_value: jax.Array,
    last_value: jax.Array,
    gamma: float,
    lam: float,
) -> tuple[jax.Array, jax.Array]:
    """Generalised advantage estimates and value targets, both [T, N].

    reward, value, terminated, truncated, final_value: [T, N]; last_value: [N], the value of
    the observation after the last step. The step after t is the next row unless an episode
    ended at t: then the bootstrap is final_value[t] if it was truncated and 0 if terminated,
    and no advantage flows back across the boundary.
    """
    next_value = jnp.concatenate([value[1:], last_value[None]], axis=0)
    next_value = jnp.where(truncated, final_value, next_value)
    next_value = jnp.where(terminated, 0.0, next_value)
    delta = reward + gamma * next_value - value
    carry_on = 1.0 - (terminated | truncated).astype(jnp.float32)

    def back(acc, x):
        d, c = x
        acc = d + gamma * lam * c * acc
        return acc, acc

    _, advantage = jax.lax.scan(back, jnp.zeros_like(last_value), (delta, carry_on), reverse=True)
    return advantage, advantage + value


def clipped_surrogate_loss(
    log_prob: jax.Array,
    old_log_prob: jax.Array,
    advantage: jax.Array,
    value: jax.Array,
    target: jax.Array,
    entropy: jax.Array,
    clip_eps: float,
    vf_coef: float,
    ent_coef: float,
) -> tuple[jax.Array, dict[str, jax.Array]]:
    """PPO's loss (paper eq. 5, with the entropy bonus subtracted so it is maximised).

    log_prob, old_log_prob, advantage, value, target: [M]; entropy: []. Advantages are used
    as given (normalise before calling). Returns the scalar loss and its parts.
    """
    log_ratio = log_prob - old_log_prob
    ratio = jnp.exp(log_ratio)
    clipped = jnp.clip(ratio, 1.0 - clip_eps, 1.0 + clip_eps)
    policy_loss = -jnp.mean(jnp.minimum(ratio * advantage, clipped * advantage))
    value_loss = jnp.mean((value - target) ** 2)
    loss = policy_loss + vf_coef * value_loss - ent_coef * entropy
    parts = {
        "policy_loss": policy_loss,
        "value_loss": value_loss,
        "entropy": entropy,
        "approx_kl": jnp.mean((ratio - 1.0) - log_ratio),  # not ln(ratio): inf, not NaN, on overflow
        "clip_fraction": jnp.mean((jnp.abs(ratio - 1.0) > clip_eps).astype(jnp.float32)),
    }
    return loss, parts


# -- the trainer ---------------------------------------------------------------------------------


def make_network(cfg: RunConfig, env: envs.Env) -> ActorCritic:
    return ActorCritic(cfg.agent_spec, cfg.scheme, env.action_size, cfg.ppo.hint_width, cfg.ppo.hidden,
                       cfg.ppo.normalize_state)


def make_optimizer(ppo: PPOConfig, params: Any) -> optax.GradientTransformation:
    """Adam with the paper's per-part learning rates, after global-norm gradient clipping (the
    normaliser's statistics, if any, are not trained)."""
    rates = {"encoder": ppo.encoder_lr, "actor": ppo.actor_lr, "critic": ppo.critic_lr}
    groups = {g: optax.adam(lr, eps=1e-5) for g, lr in rates.items()}
    if normalization.COLLECTION in params:  # only then: older checkpoints keep their optimiser state's shape
        groups["frozen"] = optax.set_to_zero()
    return optax.chain(optax.clip_by_global_norm(ppo.max_grad_norm), optax.multi_transform(groups, lr_labels(params)))


def observe_with_noise(obs: dict[str, jax.Array], key: jax.Array, noise: float) -> dict[str, jax.Array]:
    """The agent's view of obs: the state plus N(0, noise^2) for PPO-x+N(0,1)."""
    if noise <= 0.0 or "state" not in obs:
        return obs
    return {**obs, "state": obs["state"] + noise * jax.random.normal(key, obs["state"].shape)}


STARTS_TAG = 0x57A7  # folded into a rollout's key for its per-rollout starts (leaves the step keys as they were)


def start_runner(
    key: jax.Array, env: Any, env_params: Any, network: ActorCritic, num_envs: int, init_opt: Callable[[Any], Any]
) -> RunnerState:
    """A run's start: `num_envs` fresh episodes, fresh network params and `init_opt(params)`."""
    k_net, k_env, k_run = jax.random.split(key, 3)
    ts = jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(k_env, num_envs), env_params)
    params = network.init(k_net, jax.tree.map(lambda x: x[:1], ts.obs))
    return RunnerState(params, init_opt(params), ts.state, ts.obs, k_run, jnp.zeros((), jnp.int32))


@dataclass(frozen=True)
class PPO:
    """PPO's pure pieces for one configuration; `make_trainer` joins them into PPO's update, and
    algorithms that learn from another reward (GAIL) join them around their own."""

    env: Any  # AutoReset(Env)
    env_params: Any
    network: ActorCritic
    init: Callable[[jax.Array], RunnerState]
    # (state, key) -> (state after T steps of N envs, [T, N] transitions, [N] value after them)
    rollout: Callable[[RunnerState, jax.Array], tuple[RunnerState, Transition, jax.Array]]
    # (state, transitions, last value, [T, N] reward to learn from, key) -> (state one update on, metrics)
    learn: Callable[[RunnerState, Transition, jax.Array, jax.Array, jax.Array], tuple[RunnerState, dict[str, jax.Array]]]


def make_ppo(cfg: RunConfig) -> PPO:
    """PPO's pieces for a validated RunConfig."""
    ppo = cfg.ppo
    env = envs.AutoReset(cfg.make_env())
    env_params = envs.make_params(cfg.env, cfg.variant)
    network = make_network(cfg, env)
    noise = cfg.agent_spec.state_noise
    T, N = ppo.rollout_length, ppo.num_envs

    def init(key: jax.Array) -> RunnerState:
        return start_runner(key, env, env_params, network, N, lambda params: make_optimizer(ppo, params).init(params))

    def rollout(state: RunnerState, key: jax.Array) -> tuple[RunnerState, Transition, jax.Array]:
        starts = None
        if ppo.starts_per_rollout:  # one next start per env for the whole rollout (its own key)
            k_starts = jax.random.fold_in(key, STARTS_TAG)
            starts = jax.vmap(env.fresh_start, in_axes=(0, None))(jax.random.split(k_starts, N), env_params)

        def step(carry, key):
            env_state, obs = carry
            k_noise, k_act, k_env, k_final = jax.random.split(key, 4)
            seen = observe_with_noise(obs, k_noise, noise)
            mean, log_std, value = network.apply(state.params, seen)
            action = mean + jnp.exp(log_std) * jax.random.normal(k_act, mean.shape)
            ts = jax.vmap(env.step, in_axes=(0, 0, 0, None, 0))(jax.random.split(k_env, N), env_state, action, env_params, starts)
            final_value = network.apply(state.params, observe_with_noise(ts.final_obs, k_final, noise))[2]
            transition = Transition(
                seen,
                action,
                gaussian_log_prob(action, mean, log_std),
                value,
                ts.reward,
                ts.terminated,
                ts.truncated,
                final_value,
                ts.info["episode_return"],
            )
            return (ts.state, ts.obs), transition

        k_steps, k_last = jax.random.split(key)
        (env_state, obs), traj = jax.lax.scan(step, (state.env_state, state.obs), jax.random.split(k_steps, T))
        last_value = network.apply(state.params, observe_with_noise(obs, k_last, noise))[2]
        return state.replace(env_state=env_state, obs=obs), traj, last_value

    def loss_fn(params, batch: Batch):
        mean, log_std, value = network.apply(params, batch.obs)
        advantage = (batch.advantage - batch.advantage.mean()) / (batch.advantage.std() + 1e-8)
        return clipped_surrogate_loss(
            gaussian_log_prob(batch.action, mean, log_std),
            batch.log_prob,
            advantage,
            value,
            batch.target,
            gaussian_entropy(log_std),
            ppo.clip_eps,
            ppo.vf_coef,
            ppo.ent_coef,
        )

    def learn(state: RunnerState, traj: Transition, last_value: jax.Array, reward: jax.Array, key: jax.Array):
        advantage, target = gae(
            reward,
            traj.value,
            traj.terminated,
            traj.truncated,
            traj.final_value,
            last_value,
            ppo.gamma,
            ppo.gae_lambda,
        )
        flat = lambda x: x.reshape((T * N,) + x.shape[2:])  # noqa: E731
        batch = jax.tree.map(flat, Batch(traj.obs, traj.action, traj.log_prob, advantage, target))
        optimizer = make_optimizer(ppo, state.params)

        def minibatch_step(carry, mb: Batch):
            params, opt_state, stopped = carry
            (_, parts), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, mb)
            updates, new_opt_state = optimizer.update(grads, opt_state, params)
            new = (optax.apply_updates(params, updates), new_opt_state)
            if ppo.target_kl is not None:  # KL early stop: no step from here to the update's end
                stopped = stopped | ~(parts["approx_kl"] <= 1.5 * ppo.target_kl)  # NaN stops too
                new = jax.tree.map(lambda old, step: jnp.where(stopped, old, step), (params, opt_state), new)
                parts = {**parts, "kl_stopped": stopped.astype(jnp.float32)}
            return (*new, stopped), parts

        def epoch(carry, key):
            order = jax.random.permutation(key, T * N)
            shaped = lambda x: x[order].reshape((ppo.num_minibatches, ppo.minibatch_size) + x.shape[1:])  # noqa: E731
            return jax.lax.scan(minibatch_step, carry, jax.tree.map(shaped, batch))

        (params, opt_state, _), parts = jax.lax.scan(
            epoch, (state.params, state.opt_state, jnp.zeros((), bool)), jax.random.split(key, ppo.epochs)
        )
        params = normalization.update(params, traj.obs)  # after learning: the next rollout's statistics
        metrics = {
            **jax.tree.map(jnp.mean, parts),
            **episode_metrics(traj.terminated | traj.truncated, traj.episode_return),
            "env_steps": (state.update + 1) * ppo.batch_size,
        }
        return state.replace(params=params, opt_state=opt_state, update=state.update + 1), metrics

    return PPO(env, env_params, network, init, rollout, learn)


def make_trainer(cfg: RunConfig) -> Trainer:
    """PPO's trainer: each update rolls out, then learns from the env's (scaled) reward."""
    parts = make_ppo(cfg)

    def update(state: RunnerState) -> tuple[RunnerState, dict[str, jax.Array]]:
        key, k_roll, k_epochs = jax.random.split(state.key, 3)
        state, traj, last_value = parts.rollout(state, k_roll)
        state, metrics = parts.learn(state, traj, last_value, cfg.ppo.reward_scale * traj.reward, k_epochs)
        return state.replace(key=key), metrics

    return Trainer(cfg, parts.env, parts.network, parts.init, update)
