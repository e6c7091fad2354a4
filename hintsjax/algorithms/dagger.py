"""DAgger (Ross, Gordon and Bagnell 2011) as one jittable, seed-vmappable `train(key)`.

Round i rolls out ppo.batch_size steps (ppo.num_envs envs); at every step each env acts as the
expert with probability beta_i = dagger.beta_decay ** i and as the student (its mean action)
otherwise. Every visited state is labelled with the expert's action (its mean) and written into
the aggregated dataset, a fixed-size ring buffer; then the student takes dagger.grad_steps Adam
steps on the squared error between its mean action and the label, over minibatches of
ppo.minibatch_size drawn uniformly from the whole dataset.

The student is the spine's ActorCritic on the state, so evaluation and checkpoints treat it like
any agent; only its actor is trained (the critic and the log std keep their initial values, and
evaluation uses the mean action).
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
import optax
from flax import struct

from hintsjax import envs
from hintsjax.models import normalization
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms import experts
from hintsjax.algorithms.ppo import (
    Hyper,
    RunnerState,
    batch_step,
    make_network,
    start_runner,
)
from hintsjax.algorithms.trainer import Trainer, episode_metrics


@struct.dataclass
class Dataset:
    """The aggregated (state, expert action) pairs: a ring buffer of fixed capacity C."""

    state: jax.Array  # [C, n]
    action: jax.Array  # [C, A]
    size: jax.Array  # rows filled so far (at most C)
    head: jax.Array  # the next row to write

    @classmethod
    def empty(cls, capacity: int, state_size: int, action_size: int) -> "Dataset":
        zero = jnp.zeros((), jnp.int32)
        return cls(
            jnp.zeros((capacity, state_size)), jnp.zeros((capacity, action_size)), zero, zero
        )

    def add(self, state: jax.Array, action: jax.Array) -> "Dataset":
        """Append M <= C rows, overwriting the oldest once the buffer is full."""
        capacity, m = self.state.shape[0], state.shape[0]
        rows = (self.head + jnp.arange(m)) % capacity
        return Dataset(
            self.state.at[rows].set(state),
            self.action.at[rows].set(action),
            jnp.minimum(self.size + m, capacity),
            (self.head + m) % capacity,
        )

    def sample(self, key: jax.Array, n: int) -> tuple[jax.Array, jax.Array]:
        """n rows drawn uniformly, with replacement, from the filled part."""
        rows = jax.random.randint(key, (n,), 0, jnp.maximum(self.size, 1))
        return self.state[rows], self.action[rows]


@struct.dataclass
class DaggerState:
    """Everything a DAgger run carries between rounds; a checkpoint saves all of it."""

    runner: RunnerState  # the student's params and optimiser state, the envs, the key, rounds done
    data: Dataset

    @property
    def params(self) -> Any:
        """The student's ActorCritic parameters (what evaluation uses)."""
        return self.runner.params

    @property
    def update(self) -> jax.Array:
        return self.runner.update


def imitation_loss(predicted: jax.Array, label: jax.Array) -> jax.Array:
    """Mean over rows of the squared distance between the student's and the expert's actions."""
    return jnp.mean(jnp.sum((predicted - label) ** 2, axis=-1))


def make_trainer(cfg: RunConfig, expert: Any = None) -> Trainer:
    """DAgger's trainer; `expert` (anything with `mean(state)`) defaults to the env's packaged
    one."""
    ppo, dagger = cfg.ppo, cfg.dagger
    env = envs.AutoReset(cfg.make_env())
    env_params = cfg.task_params(cfg.variant)
    expert = experts.load(cfg.env, cfg.expert) if expert is None else expert
    experts.check_state_size(expert, cfg, env.state_size)
    network = make_network(cfg, env)
    optimizer = optax.chain(
        optax.clip_by_global_norm(ppo.max_grad_norm), optax.adam(dagger.lr, eps=1e-5)
    )
    T, N = ppo.rollout_length, ppo.num_envs
    step_envs = batch_step(env, cfg)

    def init(key: jax.Array) -> DaggerState:
        runner = start_runner(key, env, env_params, network, N, optimizer.init, Hyper.of(cfg))
        return DaggerState(
            runner, Dataset.empty(dagger.buffer_size, env.state_size, env.action_size)
        )

    def student(params: Any, obs: dict[str, jax.Array]) -> jax.Array:
        return network.apply(params, obs)[0]

    def update(state: DaggerState) -> tuple[DaggerState, dict[str, jax.Array]]:
        runner = state.runner
        key, k_roll, k_fit = jax.random.split(runner.key, 3)
        beta = jnp.power(dagger.beta_decay, state.update.astype(jnp.float32))

        def step(carry, key):
            env_state, obs = carry
            k_mix, k_env = jax.random.split(key)
            label = expert.mean(obs["state"])
            by_expert = jax.random.uniform(k_mix, (N, 1)) < beta
            action = jnp.where(by_expert, label, student(state.params, obs))
            ts = step_envs(jax.random.split(k_env, N), env_state, action, env_params)
            visited = (
                obs["state"],
                label,
                ts.terminated | ts.truncated,
                ts.info["episode_return"],
                by_expert[:, 0],
            )
            return (ts.state, ts.obs), visited

        (env_state, obs), (states, labels, done, returns, by_expert) = jax.lax.scan(
            step, (runner.env_state, runner.obs), jax.random.split(k_roll, T)
        )
        data = state.data.add(states.reshape(T * N, -1), labels.reshape(T * N, -1))

        def fit(carry, key):
            params, opt_state = carry
            batch_state, batch_label = data.sample(key, ppo.minibatch_size)
            loss, grads = jax.value_and_grad(
                lambda p: imitation_loss(student(p, {"state": batch_state}), batch_label)
            )(params)
            updates, opt_state = optimizer.update(grads, opt_state, params)
            return (optax.apply_updates(params, updates), opt_state), loss

        (params, opt_state), losses = jax.lax.scan(
            fit, (runner.params, runner.opt_state), jax.random.split(k_fit, dagger.grad_steps)
        )
        params = normalization.update(params, {"state": states})  # with ppo.normalize_state
        metrics = {
            **episode_metrics(done, returns),
            "imitation_loss": losses.mean(),
            "beta": beta,
            "expert_steps": by_expert.mean(),
            "dataset_size": data.size,
            "env_steps": (state.update + 1) * ppo.batch_size,
        }
        runner = RunnerState(
            params, opt_state, env_state, obs, key, runner.update + 1, runner.hyper
        )
        return DaggerState(runner, data), metrics

    return Trainer(cfg, env, network, init, update)
