"""PPO as one jittable `train(key)`: rollout, GAE, clipped-surrogate loss and updates.

`make_trainer(cfg)` returns PPO's `Trainer` (hintsjax.algorithms.trainer); `make_ppo(cfg)` its
pieces (init, rollout, learn), which GAIL reuses with the discriminator's reward. The arithmetic
they join (the Gaussian policy, GAE, the loss) is in hintsjax.algorithms.ppo_math.

Episodes carry `terminated` and `truncated` separately: GAE bootstraps a truncated episode from
the value of the state it was cut off in (the env's `final_obs`) and a terminated one from 0.
The privileged-signal baselines ride on the same pieces: the hint dropped in the training view
(`observe`), its prediction's loss (`hint_error`) and what deployment sees (`deploy_view`).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from hintsjax import envs
from hintsjax.models import normalization
from hintsjax.models.agents import AgentSpec
from hintsjax.models.networks import ActorCritic, lr_labels
from hintsjax.settings import fields
from hintsjax.settings.algorithm_settings import PPOConfig
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms.ppo_math import (
    Batch,
    Transition,
    clipped_surrogate_loss,
    gae,
    gaussian_entropy,
    gaussian_log_prob,
    gaussian_sample,
    squashed_entropy,
)
from hintsjax.algorithms import kl_rate
from hintsjax.algorithms.trainer import Trainer, episode_metrics, program_identity


# the PPO settings that are Hyper leaves (`traced=True` on the field)
TRACED = fields.names(PPOConfig, traced=True)


@jax.tree_util.register_pytree_with_keys_class
class Hyper:
    """A configuration's numbers, as arrays in its runner state rather than constants in the
    trace: configurations that differ only in these (and in their hint) train in one compiled
    program, vmapped over a group of them (hintsjax.algorithms.group), as rejax vmaps over its
    configs.

    Its leaves, read as attributes (`hyper.clip_eps`): every PPO setting declared `traced` (TRACED;
    an optional one is NaN where unset), the agent's `state_noise` (the std of N(0, s^2) on the
    state it sees in training rollouts), and `hint_take` (int32[W]) and `hint_keep` (bool[W]), which
    pick the agent's hint out of the env's: an env built for a group computes every member's hint
    parts side by side, and a member sees those at `hint_take` where `hint_keep`, 0 elsewhere (its
    width padded to the group's). Trained alone, a configuration takes its own hint's positions in
    order, all kept.
    """

    __slots__ = ("_leaves",)

    def __init__(self, leaves: dict[str, Any]):
        object.__setattr__(self, "_leaves", dict(leaves))

    def __getattr__(self, name: str) -> Any:
        try:
            return object.__getattribute__(self, "_leaves")[name]
        except KeyError:
            raise AttributeError(
                f"Hyper has no {name!r}; its leaves: {', '.join(self._leaves)}"
            ) from None

    def __repr__(self) -> str:
        return f"Hyper({', '.join(f'{k}={v!r}' for k, v in self._leaves.items())})"

    def tree_flatten_with_keys(self):
        """Leaves keyed by name, as a dataclass's fields are (checkpoints store them by these
        names)."""
        return [(jax.tree_util.GetAttrKey(k), v) for k, v in self._leaves.items()], tuple(
            self._leaves
        )

    @classmethod
    def tree_unflatten(cls, names: tuple[str, ...], leaves: Any) -> "Hyper":
        return cls(dict(zip(names, leaves)))

    @classmethod
    def of(cls, cfg: RunConfig, hint_take: Any = None, width: int | None = None) -> "Hyper":
        """`cfg`'s numbers; its hint at positions `hint_take` of the env's (default: the first d),
        padded to `width` (default: d, its own hint's width)."""
        d = hint_width(cfg)
        take = list(range(d)) if hint_take is None else list(hint_take)
        # never empty: orbax stores no zero-size array
        width = max(d if width is None else width, 1)
        f32 = lambda x: np.asarray(np.nan if x is None else x, np.float32)  # noqa: E731  (numpy: constants, also inside a trace)
        return cls(
            {
                **{name: f32(getattr(cfg.ppo, name)) for name in TRACED},
                "state_noise": f32(cfg.agent_spec.state_noise),
                "hint_take": np.asarray(take + [0] * (width - d), np.int32),
                "hint_keep": np.arange(width) < d,
            }
        )


def hint_width(cfg: RunConfig) -> int:
    """The width of the hint `cfg`'s agent sees (0 without one)."""
    return envs.make_hint(cfg.env, cfg.effective_hint).dim


@struct.dataclass
class RunnerState:
    """Everything a run carries between updates; a checkpoint saves all of it."""

    params: Any
    opt_state: Any
    env_state: Any  # AutoReset's EpisodeState, batched [N]
    obs: dict[str, jax.Array]  # current observation, batched [N]
    key: jax.Array
    update: jax.Array  # updates done so far
    hyper: Hyper


# The network's fields that are PPO settings of the same name (ppo.hidden, ppo.action_head, ...): a
# setting the network reads is a field on each side, and nothing between them names it.
NETWORK_SETTINGS = tuple(
    f.name for f in dataclasses.fields(ActorCritic) if f.name in fields.names(PPOConfig)
)


def make_network(cfg: RunConfig, env: envs.Env) -> ActorCritic:
    """The policy's ActorCritic for `cfg`'s agent and `env`'s actions, with its PPO settings."""
    return ActorCritic(
        cfg.agent_spec,
        cfg.scheme,
        env.action_size,
        **{name: getattr(cfg.ppo, name) for name in NETWORK_SETTINGS},
    )


def make_optimizer(hyper: Hyper, params: Any, ppo: PPOConfig) -> optax.GradientTransformation:
    """Adam with the paper's per-part learning rates, after gradient clipping to max_grad_norm (the
    normaliser's statistics, if any, are not trained). The rates may be traced arrays; the static
    choices come from `ppo`: `grad_clip` "global" clips the norm of all parts' gradients together,
    so a large critic loss shrinks the actor's step too, "per_part" clips each part's (encoder,
    actor, critic, and the critic's own encoder where it has one) alone; `adam_eps` is Adam's
    epsilon; `kl_adaptive_lr` scales every rate by the KL of the steps
    (hintsjax/algorithms/kl_rate.py), its scale kept in the optimiser's state."""
    rates = {"encoder": hyper.encoder_lr, "actor": hyper.actor_lr, "critic": hyper.critic_lr}
    per_part = ppo.grad_clip == "per_part"
    labels = lr_labels(params)
    # A critic's own encoder (ppo.critic_encoder=own) is a part of its own only where parts are
    # clipped apart; else it steps with the encoders' group (the same Adam, element by element),
    # and every other run's optimiser state keeps the shape its checkpoints were saved with.
    if "critic_encoder" in jax.tree.leaves(labels):
        if per_part:
            rates["critic_encoder"] = hyper.encoder_lr
        else:
            labels = jax.tree.map(lambda g: "encoder" if g == "critic_encoder" else g, labels)

    def part(lr):
        adam = optax.adam(lr, eps=ppo.adam_eps)
        return (
            optax.chain(optax.clip_by_global_norm(hyper.max_grad_norm), adam) if per_part else adam
        )

    groups = {g: part(lr) for g, lr in rates.items()}
    # only then: older checkpoints keep their optimiser state's shape
    if normalization.COLLECTION in params:
        groups["frozen"] = optax.set_to_zero()
    parts = optax.multi_transform(groups, labels)
    optimizer = (
        parts if per_part else optax.chain(optax.clip_by_global_norm(hyper.max_grad_norm), parts)
    )
    return optax.chain(optimizer, kl_rate.scale_by_kl_rate()) if ppo.kl_adaptive_lr else optimizer


def pick_hint(obs: dict[str, jax.Array], hyper: Hyper) -> dict[str, jax.Array]:
    """obs with the configuration's hint picked out of the env's (`Hyper.hint_take`), padding 0."""
    if "hint" not in obs:
        return obs
    return {**obs, "hint": jnp.where(hyper.hint_keep, obs["hint"][..., hyper.hint_take], 0.0)}


# folded into a step's noise key for its hint dropout (leaves the noise as it was)
DROP_TAG = 0xD809


def observe(
    obs: dict[str, jax.Array], key: jax.Array, hyper: Hyper, drop: float | None = None
) -> dict[str, jax.Array]:
    """The agent's view of obs ([N, ...]) in training: its hint, each env's replaced by zeros with
    probability `drop` (an agent that drops its hint; None: kept), and the state plus N(0, s^2) (s
    is 0 but for PPO-x+N(0,1); adding 0 x noise leaves the state as it was)."""
    obs = pick_hint(obs, hyper)
    if drop is not None:
        kept = jax.random.uniform(jax.random.fold_in(key, DROP_TAG), obs["hint"].shape[:-1]) >= drop
        obs = {**obs, "hint": jnp.where(kept[..., None], obs["hint"], 0.0)}
    if "state" not in obs:
        return obs
    return {
        **obs,
        "state": obs["state"] + hyper.state_noise * jax.random.normal(key, obs["state"].shape),
    }


def deploy_view(obs: dict[str, jax.Array], spec: AgentSpec) -> dict[str, jax.Array]:
    """obs as the agent sees it at deployment: its privileged inputs (`spec.privileged`) are
    zeros."""
    return {**obs, **{k: jnp.zeros_like(obs[k]) for k in spec.privileged if k in obs}}


def hint_error(prediction: jax.Array, hint: jax.Array, keep: jax.Array) -> jax.Array:
    """The mean squared error of a hint's prediction over its kept positions: prediction, hint
    [M, W], keep bool[W] (a group's padding is no part of a member's hint, so its loss is as
    alone)."""
    squared = jnp.where(keep, (prediction - hint) ** 2, 0.0)
    return squared.sum() / (prediction.shape[0] * jnp.maximum(keep.sum(), 1))


# What a step needs of a few envs only (a truncated episode's final value, an ended one's fresh
# start) is computed this many at a time (`envs.rows_where`): a step pays a fraction of a pass
# for its few truncations and ends, not a whole one.
ROW_CHUNKS = 8
# The physics whose rollouts draw the ended envs' starts alone (`AutoReset.step_ended`); under
# MJX-Warp a chunk is another batch shape for its kernels: it steps as every env's start does on a
# CPU (tests/envs/test_physics.py, slow tier), but its speed on a GPU is not yet measured
# (experiments/gpu_queue.sh), so Warp's rollouts draw every env's start each step.
ENDED_STARTS_PHYSICS = frozenset({envs.JAX})


def row_chunk(n: int) -> int:
    """The rows `envs.rows_where` takes at a time of a batch of n: an eighth, or all of them where
    n is no multiple of 8."""
    return n // ROW_CHUNKS if n % ROW_CHUNKS == 0 else n


def batch_step(
    env: envs.AutoReset, cfg: RunConfig, ended_starts: bool | None = None
) -> Callable[..., envs.Timestep]:
    """(keys, states, actions, params) -> `env.step` of cfg's `ppo.num_envs` envs at once: drawing
    the ended envs' starts alone (`AutoReset.step_ended`) where `ended_starts` says (None: where
    cfg's physics is in ENDED_STARTS_PHYSICS), else every env's (vmapped `step`)."""
    if ended_starts is None:
        ended_starts = envs.resolve_physics(cfg.env, cfg.physics) in ENDED_STARTS_PHYSICS
    if not ended_starts:
        return jax.vmap(env.step, in_axes=(0, 0, 0, None))
    chunk = row_chunk(cfg.ppo.num_envs)
    return lambda keys, state, action, params: env.step_ended(keys, state, action, params, chunk)


# folded into a rollout's key for its per-rollout starts (leaves the step keys as they were)
STARTS_TAG = 0x57A7
RESET_TAG = 0x5E7A  # folded into a rollout's key for its fresh episodes (ppo.reset_every_update)


def start_envs(
    key: jax.Array, env: Any, env_params: Any, num_envs: int
) -> tuple[jax.Array, jax.Array, envs.Timestep]:
    """A run's start from its seed key: (network key, run key, `num_envs` fresh episodes)."""
    k_net, k_env, k_run = jax.random.split(key, 3)
    return k_net, k_run, envs.fresh_episodes(k_env, env, env_params, num_envs)


def start_params(
    k_net: jax.Array, network: ActorCritic, obs: dict[str, jax.Array], hyper: Hyper, width: int
) -> Any:
    """Fresh network params for observations like `obs` ([N, ...]) at hint width `width` (the
    configuration's own: its first `width` picked hint positions)."""
    seen = pick_hint(jax.tree.map(lambda x: x[:1], obs), hyper)
    if "hint" in seen:
        seen = {**seen, "hint": seen["hint"][..., :width]}
    return network.init(k_net, seen)


def start_runner(
    key: jax.Array,
    env: Any,
    env_params: Any,
    network: ActorCritic,
    num_envs: int,
    init_opt: Callable[[Any], Any],
    hyper: Hyper,
) -> RunnerState:
    """A run's start: `num_envs` fresh episodes, fresh network params and `init_opt(params)`."""
    k_net, k_run, ts = start_envs(key, env, env_params, num_envs)
    # a concrete Hyper (Hyper.of's)
    params = start_params(k_net, network, ts.obs, hyper, int(np.sum(hyper.hint_keep)))
    return RunnerState(
        params, init_opt(params), ts.state, ts.obs, k_run, jnp.zeros((), jnp.int32), hyper
    )


class StepCarry(NamedTuple):
    """What one minibatch step hands the next, through an update's epochs."""

    params: Any
    opt_state: Any
    stopped: jax.Array  # bool: the KL early stop has ended this update's steps
    stepped: jax.Array  # bool: a step came before this one in this update (its KL is informative)


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
    # (state, transitions, last value, [T, N] reward to learn from, key) -> (state one update on,
    # metrics)
    learn: Callable[
        [RunnerState, Transition, jax.Array, jax.Array, jax.Array],
        tuple[RunnerState, dict[str, jax.Array]],
    ]


def make_ppo(cfg: RunConfig, hint: str | None = None, ended_starts: bool | None = None) -> PPO:
    """PPO's pieces for a validated RunConfig. Every number a table varies is read from the
    state's `Hyper`, so the pieces serve any configuration of the same shapes; `hint` is the
    env's hint (default: cfg's; a group's env computes every member's, see
    hintsjax.algorithms.group); `ended_starts` whether the rollout draws the ended envs' starts
    alone (None: where the physics is in ENDED_STARTS_PHYSICS; a bench compares both)."""
    ppo, spec = cfg.ppo, cfg.agent_spec
    env = envs.AutoReset(cfg.make_env(hint=hint))
    env_params = cfg.task_params(cfg.variant)
    network = make_network(cfg, env)
    T, N = ppo.rollout_length, ppo.num_envs
    drop = ppo.hint_dropout if spec.drops_hint else None
    chunk = row_chunk(N)
    step_envs = batch_step(env, cfg, ended_starts)

    def init(key: jax.Array) -> RunnerState:
        hyper = Hyper.of(cfg)
        return start_runner(
            key,
            env,
            env_params,
            network,
            N,
            lambda params: make_optimizer(hyper, params, ppo).init(params),
            hyper,
        )

    def rollout(state: RunnerState, key: jax.Array) -> tuple[RunnerState, Transition, jax.Array]:
        if ppo.reset_every_update:  # every env begins a fresh episode here (its own key)
            fresh = envs.fresh_episodes(jax.random.fold_in(key, RESET_TAG), env, env_params, N)
            state = state.replace(env_state=fresh.state, obs=fresh.obs)
        starts = None
        if ppo.starts_per_rollout:  # one next start per env for the whole rollout (its own key)
            k_starts = jax.random.fold_in(key, STARTS_TAG)
            starts = jax.vmap(env.fresh_start, in_axes=(0, None))(
                jax.random.split(k_starts, N), env_params
            )

        def step(carry, key):
            env_state, obs = carry
            k_noise, k_act, k_env, k_final = jax.random.split(key, 4)
            seen = observe(obs, k_noise, state.hyper, drop)
            mean, log_std, value = network.apply(state.params, seen)
            action = gaussian_sample(k_act, mean, log_std)
            k_envs = jax.random.split(k_env, N)
            if starts is None:
                ts = step_envs(k_envs, env_state, action, env_params)
            else:  # every env's next episode from the rollout's one start
                ts = jax.vmap(env.step, in_axes=(0, 0, 0, None, 0))(
                    k_envs, env_state, action, env_params, starts
                )
            # GAE reads it where an episode was truncated only (a terminated one bootstraps from 0),
            # and not at all without the bootstrap
            final_value = (
                envs.rows_where(
                    lambda rows: network.apply(state.params, rows)[2],
                    observe(ts.final_obs, k_final, state.hyper, drop),
                    ts.truncated,
                    chunk,
                )
                if ppo.bootstrap_truncated
                else jnp.zeros_like(value)
            )
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
        (env_state, obs), traj = jax.lax.scan(
            step, (state.env_state, state.obs), jax.random.split(k_steps, T)
        )
        last_value = network.apply(state.params, observe(obs, k_last, state.hyper, drop))[2]
        return state.replace(env_state=env_state, obs=obs), traj, last_value

    def loss_fn(params, batch: Batch, hyper: Hyper):
        predicts = spec.hint_use == "target"
        mean, log_std, value, *prediction = network.apply(params, batch.obs, predicts)
        advantage = (batch.advantage - batch.advantage.mean()) / (batch.advantage.std() + 1e-8)
        loss, parts = clipped_surrogate_loss(
            gaussian_log_prob(batch.action, mean, log_std),
            batch.log_prob,
            advantage,
            value,
            batch.target,
            squashed_entropy(mean, log_std).mean()
            if ppo.squashed_entropy
            else gaussian_entropy(log_std).mean(),  # a softplus std head's is [B]
            hyper.clip_eps,
            hyper.vf_coef,
            hyper.ent_coef,
        )
        if not predicts:
            return loss, parts
        error = hint_error(prediction[0], batch.obs["hint"], hyper.hint_keep)
        return loss + ppo.aux_coef * error, {**parts, "hint_loss": error}

    def learn(
        state: RunnerState,
        traj: Transition,
        last_value: jax.Array,
        reward: jax.Array,
        key: jax.Array,
    ):
        hyper = state.hyper
        if ppo.normalize_before_learning:
            state = state.replace(params=normalization.update(state.params, traj.obs))
        advantage, target = gae(
            reward,
            traj.value,
            traj.terminated,
            traj.truncated,
            traj.final_value,
            last_value,
            hyper.gamma,
            hyper.gae_lambda,
            ppo.gae_segment,
            ppo.bootstrap_truncated,
        )
        flat = lambda x: x.reshape((T * N,) + x.shape[2:])  # noqa: E731
        batch = jax.tree.map(flat, Batch(traj.obs, traj.action, traj.log_prob, advantage, target))
        optimizer = make_optimizer(hyper, state.params, ppo)

        def minibatch_step(carry: StepCarry, mb: Batch):
            params, opt_state, stopped, stepped = carry
            (_, parts), grads = jax.value_and_grad(loss_fn, has_aux=True)(params, mb, hyper)
            # this step's rate from the KL of the steps before it in this update
            if ppo.kl_adaptive_lr:
                # not the rollout policy's own KL of 0, not after a stop
                informative = stepped & ~stopped
                opt_state = jax.tree.map(
                    lambda old, new: jnp.where(informative, new, old),
                    opt_state,
                    kl_rate.adapt(opt_state, parts["approx_kl"], hyper.target_kl),
                )
                parts = {**parts, "lr_scale": kl_rate.scale_of(opt_state)}
            updates, new_opt_state = optimizer.update(grads, opt_state, params)
            new = (optax.apply_updates(params, updates), new_opt_state)
            if ppo.target_kl is not None:  # KL early stop: no step from here to the update's end
                # NaN stops too
                stopped = stopped | ~(parts["approx_kl"] <= kl_rate.STOP * hyper.target_kl)
                new = jax.tree.map(
                    lambda old, step: jnp.where(stopped, old, step), (params, opt_state), new
                )
                parts = {**parts, "kl_stopped": stopped.astype(jnp.float32)}
            return StepCarry(*new, stopped, jnp.ones((), bool)), parts

        def epoch(carry, key):
            order = jax.random.permutation(key, T * N)

            def shaped(x):
                return x[order].reshape((ppo.num_minibatches, ppo.minibatch_size) + x.shape[1:])

            return jax.lax.scan(minibatch_step, carry, jax.tree.map(shaped, batch))

        start = StepCarry(state.params, state.opt_state, jnp.zeros((), bool), jnp.zeros((), bool))
        (params, opt_state, _, _), parts = jax.lax.scan(
            epoch, start, jax.random.split(key, ppo.epochs)
        )
        if not ppo.normalize_before_learning:
            # after learning: the next rollout's statistics
            params = normalization.update(params, traj.obs)
        metrics = {
            **jax.tree.map(jnp.mean, parts),
            **episode_metrics(traj.terminated | traj.truncated, traj.episode_return),
            # the env's reward per step, unscaled: defined where no episode ends
            "step_reward": jnp.mean(traj.reward),
            "env_steps": (state.update + 1) * ppo.batch_size,
        }
        return state.replace(params=params, opt_state=opt_state, update=state.update + 1), metrics

    return PPO(env, env_params, network, init, rollout, learn)


def make_trainer(cfg: RunConfig, hint: str | None = None) -> Trainer:
    """PPO's trainer: each update rolls out, then learns from the env's (scaled) reward. `hint`:
    as make_ppo's."""
    parts = make_ppo(cfg, hint)

    def update(state: RunnerState) -> tuple[RunnerState, dict[str, jax.Array]]:
        key, k_roll, k_epochs = jax.random.split(state.key, 3)
        state, traj, last_value = parts.rollout(state, k_roll)
        state, metrics = parts.learn(
            state, traj, last_value, state.hyper.reward_scale * traj.reward, k_epochs
        )
        return state.replace(key=key), metrics

    return Trainer(cfg, parts.env, parts.network, parts.init, update, program_identity(cfg, hint))
