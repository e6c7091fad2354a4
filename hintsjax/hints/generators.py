"""A learned hint generator: the hint read off the agent's own pictures instead of the simulator.

The paper's generator G reads the simulator's state, which a real robot does not have (its
Section 6). This one is a small network that maps the last `frames` pictures to the hint of any
registered hint or `a+b` composite, trained by regression on rollouts of the jitted env:

    python -m hintsjax.generator env=pendulum hint=composite seeds=5     # -> runs/generator-...
    python -m hintsjax.run env=pendulum hint=composite hint_source=runs/generator-...

More of what it owns and why: docs/design.md, "Module notes", hintsjax/hints/generators.py.
"""

from __future__ import annotations

import csv
import dataclasses
import io
import json
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
import optax
import orbax.checkpoint as ocp
import yaml
from flax import struct

from hintsjax import envs
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.system import paths
from hintsjax.system.checks import require_positive, require_range
from hintsjax.system.errors import UsageError
from hintsjax.settings.hint_sources import (
    GENERATOR_JSON,
    Generator,
    GeneratorParams,
    PARAMS,
    stored,
)
from hintsjax.algorithms import experts
from hintsjax.training.runlog import fresh_folder
from hintsjax.hints import rollouts

POLICIES = {"random": "N(0, 1) actions", "expert": "the packaged expert in part of the envs"}


# -- training --------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GeneratorConfig:
    """What `python -m hintsjax.generator` trains: a generator of `env`'s `hint` from the last
    `frames` pictures, on `num_envs` x `steps` rollout steps (held out: `held_out_envs` x
    `steps`)."""

    env: str = "pendulum"
    hint: str = "composite"
    variant: str | None = None  # the env variant the rollouts run in (None: its default)
    frames: int = 2  # 2 measured best: experiments/results/learned_hints.md, "How many pictures"
    seeds: int = 1
    seed: int = 0  # seed i is PRNGKey(seed + i)
    num_envs: int = 64
    steps: int = 500
    held_out_envs: int = 16
    # who acts in the rollouts: random (N(0, 1) actions) or expert (in part of the envs)
    policy: str = "random"
    expert_fraction: float = 0.5  # with policy=expert, the share of envs the packaged expert drives
    epochs: int = 10
    minibatch_size: int = 256
    lr: float = 3e-4
    hidden: int = 256
    out_dir: str = "runs"
    name: str | None = None  # folder name (default: generator-<env>-<hint>-<timestamp>)

    @property
    def generator(self) -> Generator:
        return Generator(self.env, self.hint, self.frames, self.hidden)

    def validate(self) -> "GeneratorConfig":
        try:
            choose("env", self.env, envs.REGISTRY)
            hint = envs.make_hint(self.env, self.hint)
            envs.make_params(self.env, self.variant)
            choose("policy", self.policy, POLICIES)
        except ChoiceError as e:
            raise UsageError(str(e)) from None
        if hint.dim == 0:
            raise UsageError(
                f"hint '{self.hint}' is empty: give a registered hint of {self.env} "
                f"({', '.join(envs.hint_names(self.env))})"
            )
        require_positive(
            self,
            (
                "frames",
                "seeds",
                "num_envs",
                "steps",
                "held_out_envs",
                "epochs",
                "minibatch_size",
                "lr",
                "hidden",
            ),
        )
        require_range(self, {"expert_fraction": (0.0, 1.0)})
        if self.minibatch_size > self.num_envs * self.steps:
            raise UsageError(
                f"minibatch_size ({self.minibatch_size}) exceeds the {self.num_envs * self.steps} "
                "training samples (num_envs x steps)"
            )
        if self.policy == "expert":
            experts.describe(self.env)
        return self


@struct.dataclass
class Rollouts:
    """Rollout data, [T, N, ...]: the picture seen at each step, how many steps into its episode
    it is (to stack the pictures before it) and the true hint."""

    frames: jax.Array  # uint8[T, N, S, S, 3]
    age: jax.Array  # int32[T, N]
    hint: jax.Array  # float32[T, N, d]


def stack_frames(data: Rollouts, t: jax.Array, n: jax.Array, k: int) -> jax.Array:
    """The last k pictures (oldest first) before and at steps (t, n) [B]: uint8[B, k, S, S, 3];
    pictures before an episode's start repeat its first, as GeneratedHintEnv's state does."""
    back = jnp.minimum(jnp.arange(k - 1, -1, -1)[None, :], data.age[t, n][:, None])  # [B, k]
    return data.frames[t[:, None] - back, n[:, None]]


def make_collect(cfg: GeneratorConfig) -> Callable[[jax.Array, int], Rollouts]:
    """`collect(key, num_envs) -> Rollouts[steps, num_envs]` of rollouts of cfg's env."""
    policy = None
    if cfg.policy == "expert":
        policy = experts.load(cfg.env)
    env = envs.AutoReset(envs.make(cfg.env, cfg.hint, rollouts.observed(policy)))
    params = envs.make_params(cfg.env, cfg.variant)

    def record(state, obs, action, ts) -> Rollouts:
        return Rollouts(obs["pixels"], state.episode_length, obs["hint"])

    def collect(key: jax.Array, num_envs: int) -> Rollouts:
        return rollouts.rollout(
            env,
            params,
            key,
            num_envs,
            cfg.steps,
            record,
            policy,
            driven=round(cfg.expert_fraction * num_envs),
        )

    return collect


@struct.dataclass
class GeneratorMetrics:
    """A trained generator's errors: per epoch the training loss, per hint dimension the mean
    squared error of the normalised hint and R^2 (1 - SSE / SST), on training data and held out."""

    loss: jax.Array  # [epochs]
    train_mse: jax.Array  # [d]
    heldout_mse: jax.Array
    train_r2: jax.Array
    heldout_r2: jax.Array


def make_train(
    cfg: GeneratorConfig,
) -> Callable[[jax.Array], tuple[GeneratorParams, GeneratorMetrics]]:
    """`train(key) -> (params, metrics)`: one generator, from collecting its data to its held-out
    R^2, as one pure function (vmap it over seeds)."""
    generator, collect = cfg.generator, make_collect(cfg)
    network, k, B = generator.network, cfg.frames, cfg.minibatch_size
    N, image_size = cfg.num_envs, envs.make(cfg.env).image_size
    samples = N * cfg.steps
    per_epoch = samples // B
    optimizer = optax.adam(cfg.lr)

    def targets(data: Rollouts, t, n, mean, std):
        return stack_frames(data, t, n, k), (data.hint[t, n] - mean) / std

    def errors(net, data: Rollouts, envs_: int, mean, std) -> tuple[jax.Array, jax.Array]:
        """Per hint dimension: mean squared error (normalised) and R^2 over `data`'s samples (those
        of its whole batches of up to B)."""
        size = min(B, envs_ * cfg.steps)
        count = (envs_ * cfg.steps) // size * size
        idx = jnp.arange(count).reshape(-1, size)

        def batch(i):
            x, y = targets(data, i // envs_, i % envs_, mean, std)
            return network.apply(net, x), y

        pred, y = jax.tree.map(lambda a: a.reshape(count, -1), jax.lax.map(batch, idx))
        sse = jnp.sum((pred - y) ** 2, axis=0)
        sst = jnp.sum((y - y.mean(axis=0)) ** 2, axis=0)
        return sse / count, 1.0 - sse / jnp.maximum(sst, 1e-12)

    def train(key: jax.Array) -> tuple[GeneratorParams, GeneratorMetrics]:
        k_data, k_held, k_init, k_epochs = jax.random.split(key, 4)
        data, held = collect(k_data, N), collect(k_held, cfg.held_out_envs)
        hints = data.hint.reshape(samples, -1)
        mean, std = hints.mean(axis=0), jnp.maximum(hints.std(axis=0), 1e-6)
        net = generator.init(k_init, image_size)

        def loss_fn(net, x, y):
            return jnp.mean((network.apply(net, x) - y) ** 2)

        def minibatch(carry, idx):
            net, opt_state = carry
            loss, grads = jax.value_and_grad(loss_fn)(
                net, *targets(data, idx // N, idx % N, mean, std)
            )
            updates, opt_state = optimizer.update(grads, opt_state, net)
            return (optax.apply_updates(net, updates), opt_state), loss

        def epoch(carry, key):
            order = jax.random.permutation(key, samples)[: per_epoch * B].reshape(per_epoch, B)
            carry, losses = jax.lax.scan(minibatch, carry, order)
            return carry, losses.mean()

        (net, _), loss = jax.lax.scan(
            epoch, (net, optimizer.init(net)), jax.random.split(k_epochs, cfg.epochs)
        )
        train_mse, train_r2 = errors(net, data, N, mean, std)
        heldout_mse, heldout_r2 = errors(net, held, cfg.held_out_envs, mean, std)
        return GeneratorParams(net, mean, std), GeneratorMetrics(
            loss, train_mse, heldout_mse, train_r2, heldout_r2
        )

    return train


def dimension_names(hint: envs.Hint) -> list[str]:
    """One name per hint dimension: the part's name, with [i] for parts wider than one."""
    return [p.name if p.dim == 1 else f"{p.name}[{i}]" for p in hint.parts for i in range(p.dim)]


def write_folder(
    folder: Path,
    cfg: GeneratorConfig,
    params: GeneratorParams,
    metrics: GeneratorMetrics,
    seconds: dict[str, float],
) -> dict[str, Any]:
    """Write a trained generator's folder; generator.json last (a folder without it is
    incomplete)."""
    names = dimension_names(cfg.generator.spec)
    m = jax.tree.map(np.asarray, metrics)
    rows = io.StringIO(newline="")  # written whole once complete (paths.write_whole)
    writer = csv.writer(rows)
    writer.writerow(
        [
            "seed",
            "dimension",
            "train_mse",
            "heldout_mse",
            "train_r2",
            "heldout_r2",
            "final_loss",
        ]
    )
    for s in range(cfg.seeds):
        for i, name in enumerate(names):
            writer.writerow(
                [
                    s,
                    name,
                    *(
                        f"{float(getattr(m, a)[s, i]):.6g}"
                        for a in ("train_mse", "heldout_mse", "train_r2", "heldout_r2")
                    ),
                    f"{m.loss[s, -1]:.6g}",
                ]
            )
    paths.write_text_whole(folder / "metrics.csv", rows.getvalue())
    with ocp.StandardCheckpointer() as saver:
        saver.save((folder / PARAMS).absolute(), stored(params), force=True)
    meta = {
        "env": cfg.env,
        "hint": cfg.hint,
        "frames": cfg.frames,
        "hidden": cfg.hidden,
        "seeds": cfg.seeds,
        "dimensions": names,
        "heldout_r2_mean": m.heldout_r2.mean(axis=0).tolist(),
        "heldout_r2_min": m.heldout_r2.min(axis=0).tolist(),
        "train_r2_mean": m.train_r2.mean(axis=0).tolist(),
        "env_steps": (cfg.num_envs + cfg.held_out_envs) * cfg.steps,
        "seconds": seconds,
        "device": jax.devices()[0].device_kind,
        "config": dataclasses.asdict(cfg),
    }
    paths.write_text_whole(folder / GENERATOR_JSON, json.dumps(meta, indent=1))
    return meta


def train_folder(cfg: GeneratorConfig) -> tuple[Path, dict[str, Any]]:
    """Train cfg's seeds in one jitted call and write their folder; (folder, generator.json)."""
    name = cfg.name or f"generator-{cfg.env}-{cfg.hint}-{time.strftime('%Y%m%d-%H%M%S')}"
    folder = fresh_folder(Path(cfg.out_dir) / name)
    paths.write_text_whole(
        folder / "config.yaml", yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False)
    )
    keys = jnp.stack([jax.random.key(cfg.seed + i) for i in range(cfg.seeds)])
    start = time.perf_counter()
    train = jax.jit(jax.vmap(make_train(cfg))).lower(keys).compile()
    compiled = time.perf_counter()
    params, metrics = jax.block_until_ready(train(keys))
    done = time.perf_counter()
    seconds = {"compile": round(compiled - start, 2), "train": round(done - compiled, 2)}
    return folder, write_folder(folder, cfg, params, metrics, seconds)
