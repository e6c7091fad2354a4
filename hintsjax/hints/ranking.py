"""Which hint is worth giving: cheap utility scores of candidate hints, before paying for training.

    python -m hintsjax.rank env=pendulum                                # every registered hint
    python -m hintsjax.rank env=acrobot hints=joint,composite,angular_velocity_1+goal_distance

Two scores, each one compiled call over every candidate and seed (the paper's Section 6 asks for
such a metric): `information`, how much the hint adds to what one picture shows about the return
to come (a probe's held-out R^2 with the hint minus without it), and `probe`, the area under the
learning curve of every candidate trained as HINTS-<scheme> for `probe_fraction` of the env's
budget, all in one group. How each is computed: docs/results.md, "Which hint is worth giving";
how far each agrees with the full tables: experiments/results/hint_ranking.md. The command
(hintsjax/rank.py) writes config.yaml, scores.json, ranking.csv and ranking.png into a folder.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
from flax import struct

from hintsjax import envs
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.system.checks import require_positive, require_range
from hintsjax.system.errors import UsageError
from hintsjax.models.conditioning import SCHEMES
from hintsjax.models.networks import Encoder, MLP, scale_pixels
from hintsjax.settings.layers import run_config
from hintsjax.algorithms import experts
from hintsjax.algorithms.group import make_group, make_group_trainer
from hintsjax.hints import rollouts

SCORES = {
    "information": "the return's R^2 gained by the hint over one picture",
    "probe": "area under a short training run's learning curve",
}
POLICIES = {
    "auto": (
        "the packaged expert in half the envs where the env has one, N(0, 1) actions in the rest"
    ),
    "random": "N(0, 1) actions",
}


@dataclass(frozen=True)
class RankConfig:
    """What `python -m hintsjax.rank` scores: `hints` (comma-separated; each a registered hint, a
    composite or names joined by '+'; None: every registered hint of `env`) by `scores`."""

    env: str = "pendulum"
    hints: str | None = None
    scheme: str = "fc"
    scores: str = "information,probe"
    seeds: int = 5
    seed: int = 0
    # of the env's HINTS budget (ENV_DEFAULTS), rounded to whole updates
    probe_fraction: float = 0.1
    info_envs: int = 64
    info_steps: int = 250
    info_held_out_envs: int = 16
    info_gamma: float = 0.9
    info_epochs: int = 5
    info_minibatch_size: int = 256
    info_lr: float = 3e-4
    # the information rollouts' actions: auto (the packaged expert in half the envs where there is
    # one), random
    policy: str = "auto"
    out_dir: str = "runs"
    name: str | None = None  # folder name (default: rank-<env>-<timestamp>)

    @property
    def candidates(self) -> list[str]:
        if self.hints is None:
            return [h for h in envs.hint_names(self.env) if h != envs.NO_HINT]
        return [h.strip() for h in self.hints.split(",")]

    @property
    def score_names(self) -> list[str]:
        return [s.strip() for s in self.scores.split(",")]

    def validate(self) -> "RankConfig":
        try:
            choose("env", self.env, envs.REGISTRY)
            choose("scheme", self.scheme, SCHEMES)
            for name in self.score_names:
                choose("score", name, SCORES)
            choose("policy", self.policy, POLICIES)
            if not self.candidates or "" in self.candidates:
                raise UsageError(
                    f"hints is empty: give a comma-separated list of {self.env}'s hints "
                    f"({', '.join(envs.hint_names(self.env))})"
                )
            for hint in self.candidates:
                if envs.make_hint(self.env, hint).dim == 0:
                    raise UsageError(
                        f"hint '{hint}' is empty: give hints of {self.env} "
                        f"({', '.join(envs.hint_names(self.env))})"
                    )
        except ChoiceError as e:
            raise UsageError(str(e)) from None
        if len(set(self.candidates)) < len(self.candidates):
            raise UsageError(f"hints lists a hint twice: {self.hints}")
        require_positive(
            self,
            (
                "seeds",
                "info_envs",
                "info_steps",
                "info_held_out_envs",
                "info_epochs",
                "info_minibatch_size",
                "info_lr",
            ),
        )
        require_range(self, {"probe_fraction": (0.0, 1.0), "info_gamma": (0.0, 1.0)})
        if self.probe_fraction == 0:
            raise UsageError("probe_fraction must be above 0")
        if self.info_minibatch_size > self.info_held_out_envs * self.info_steps:
            raise UsageError(
                f"info_minibatch_size ({self.info_minibatch_size}) exceeds the held-out samples "
                f"(info_held_out_envs x info_steps = {self.info_held_out_envs * self.info_steps})"
            )
        return self


# -- the information score -------------------------------------------------------------------------


class ReturnProbe(nn.Module):
    """(picture, hint, action) -> the return to come: the agent's encoder on the picture, the hint
    and the action joined to it, one hidden layer."""

    @nn.compact
    def __call__(self, pixels: jax.Array, hint: jax.Array, action: jax.Array) -> jax.Array:
        z = jnp.concatenate([Encoder()(scale_pixels(pixels)), hint, action], axis=-1)
        return MLP((256, 1))(z)[..., 0]


@struct.dataclass
class Samples:
    pixels: jax.Array  # uint8[M, S, S, 3]
    hint: jax.Array  # [M, U]: every candidate's parts
    action: jax.Array  # [M, A]
    ret: jax.Array  # [M]: discounted return that followed


def discounted_returns(reward: jax.Array, done: jax.Array, gamma: float) -> jax.Array:
    """[T, N] rewards and episode ends -> the discounted return from each step to its episode's
    end (or to the end of the data)."""

    def back(acc, x):
        r, d = x
        acc = r + gamma * (1.0 - d) * acc
        return acc, acc

    return jax.lax.scan(
        back, jnp.zeros_like(reward[0]), (reward, done.astype(jnp.float32)), reverse=True
    )[1]


def make_information(cfg: RankConfig, policy: Any = None) -> Callable[[jax.Array], jax.Array]:
    """`information(key) -> [K]`: each candidate's held-out R^2 of the return with its hint minus
    that with the hint zeroed. `policy` (an object with `mean(state)` and `log_std`, the packaged
    expert by default where cfg.policy is auto and the env has one) acts in half the envs."""
    candidates = cfg.candidates
    union, takes = envs.hints.side_by_side(cfg.env, candidates)
    width = max(len(t) for t in takes)
    # the last: no hint
    take = jnp.asarray([list(t) + [0] * (width - len(t)) for t in takes + [()]], jnp.int32)
    keep = jnp.asarray([[i < len(t) for i in range(width)] for t in takes + [()]])
    if policy is None and cfg.policy == "auto":
        policy = experts.load(cfg.env) if cfg.env in experts.packaged() else None
    env = envs.AutoReset(envs.make(cfg.env, union, rollouts.observed(policy)))
    params = envs.make_params(cfg.env)
    probe, optimizer, B = ReturnProbe(), optax.adam(cfg.info_lr), cfg.info_minibatch_size

    def record(state, obs, action, ts):
        return obs["pixels"], obs["hint"], action, ts.reward, ts.terminated | ts.truncated

    def collect(key: jax.Array, n: int) -> Samples:
        pixels, hint, action, reward, done = rollouts.rollout(
            env, params, key, n, cfg.info_steps, record, policy, driven=n // 2
        )
        ret = discounted_returns(reward, done, cfg.info_gamma)
        flat = lambda x: x.reshape((-1,) + x.shape[2:])  # noqa: E731
        return Samples(flat(pixels), flat(hint), flat(action), flat(ret))

    def r2(net, data: Samples, pick, mean, std) -> jax.Array:
        count = data.ret.shape[0] // B * B
        idx = jnp.arange(count).reshape(-1, B)
        pred = jax.lax.map(
            lambda i: probe.apply(net, data.pixels[i], pick(data.hint[i]), data.action[i]), idx
        ).reshape(-1)
        y = (data.ret[:count] - mean) / std
        return 1.0 - jnp.sum((pred - y) ** 2) / jnp.maximum(jnp.sum((y - y.mean()) ** 2), 1e-12)

    def fit(key: jax.Array, data: Samples, held: Samples, take_k, keep_k) -> jax.Array:
        pick = lambda h: jnp.where(keep_k, h[..., take_k], 0.0)  # noqa: E731
        mean, std = data.ret.mean(), jnp.maximum(data.ret.std(), 1e-6)
        m = data.ret.shape[0]
        k_init, k_epochs = jax.random.split(key)
        net = probe.init(k_init, data.pixels[:1], pick(data.hint[:1]), data.action[:1])

        def loss_fn(net, i):
            y = (data.ret[i] - mean) / std
            return jnp.mean(
                (probe.apply(net, data.pixels[i], pick(data.hint[i]), data.action[i]) - y) ** 2
            )

        def minibatch(carry, i):
            net, opt_state = carry
            grads = jax.grad(loss_fn)(net, i)
            updates, opt_state = optimizer.update(grads, opt_state, net)
            return (optax.apply_updates(net, updates), opt_state), None

        def epoch(carry, key):
            order = jax.random.permutation(key, m)[: m // B * B].reshape(-1, B)
            return jax.lax.scan(minibatch, carry, order)[0], None

        (net, _), _ = jax.lax.scan(
            epoch, (net, optimizer.init(net)), jax.random.split(k_epochs, cfg.info_epochs)
        )
        return r2(net, held, pick, mean, std)

    def information(key: jax.Array) -> jax.Array:
        k_data, k_held, k_fit = jax.random.split(key, 3)
        data, held = collect(k_data, cfg.info_envs), collect(k_held, cfg.info_held_out_envs)
        # same seed, data and init for all
        scores = jax.vmap(fit, in_axes=(None, None, None, 0, 0))(k_fit, data, held, take, keep)
        return scores[:-1] - scores[-1]

    return information


# -- the short training probe ----------------------------------------------------------------------


def probe_configs(cfg: RankConfig) -> list:
    """The HINTS runs of the probe: every candidate at probe_fraction of the env's budget."""
    base = run_config(
        {"env": cfg.env, "agent": "hints", "scheme": cfg.scheme, "hint": cfg.candidates[0]}
    )
    updates = max(1, round(cfg.probe_fraction * base.ppo.num_updates))
    ppo = {"total_env_steps": updates * base.ppo.batch_size}
    return [
        run_config(
            {
                "env": cfg.env,
                "agent": "hints",
                "scheme": cfg.scheme,
                "hint": h,
                "seeds": cfg.seeds,
                "seed": cfg.seed,
                "ppo": ppo,
            }
        )
        for h in cfg.candidates
    ]


def probe_scores(cfg: RankConfig) -> tuple[np.ndarray, str]:
    """([S, K] each seed's and candidate's area under its short run's learning curve, its
    measure)."""
    cfgs = probe_configs(cfg)
    trainer = make_group_trainer(make_group(cfgs))
    _, metrics = jax.jit(jax.vmap(trainer.train))(cfgs[0].seed_keys())
    return learning_curve_area({k: np.asarray(v) for k, v in metrics.items()})


def learning_curve_area(metrics: dict[str, np.ndarray]) -> tuple[np.ndarray, str]:
    """From a group's metrics ([S, U, K] per name), each run's area under its learning curve: the
    mean training return over the updates ("episode_return"), or, where some run saw no episode
    end (episodes longer than the probe: halfcheetah's 1000 steps against 784 steps per env at 10 %
    of its budget), every run's mean reward per step ("step_reward": a fixed-length episode's return
    over its length); ([S, K], the measure's name)."""
    returns = metrics["episode_return"]  # NaN where no episode ended in an update
    if not np.isnan(returns).all(axis=1).any():
        return np.nanmean(returns, axis=1), "episode_return"
    return metrics["step_reward"].mean(axis=1), "step_reward"


# -- the command -----------------------------------------------------------------------------------


def rank_hints(cfg: RankConfig) -> dict[str, Any]:
    """Every score of every candidate and seed, and the seconds each took (compile included)."""
    keys = jnp.stack([jax.random.key(cfg.seed + i) for i in range(cfg.seeds)])
    out: dict[str, Any] = {"candidates": cfg.candidates, "scores": {}, "seconds": {}}
    for name in cfg.score_names:
        start = time.perf_counter()
        if name == "information":
            values = np.asarray(jax.jit(jax.vmap(make_information(cfg)))(keys))
        else:
            values, out["probe_measure"] = probe_scores(cfg)
        out["scores"][name] = values.tolist()  # [S, K]
        out["seconds"][name] = round(time.perf_counter() - start, 2)
    if "probe" in cfg.score_names:
        out["probe_env_steps_per_run"] = probe_configs(cfg)[0].ppo.total_env_steps
    return out


def ranking(values: np.ndarray) -> list[int]:
    """Rank (1 = best) of each candidate by its mean over seeds ([S, K] -> [K])."""
    order = np.argsort(-np.asarray(values).mean(axis=0), kind="stable")
    ranks = np.empty(len(order), int)
    ranks[order] = np.arange(1, len(order) + 1)
    return ranks.tolist()
