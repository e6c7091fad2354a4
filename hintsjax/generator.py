"""A learned hint generator: the hint read off the agent's own pictures instead of the simulator.

The paper's generator G reads the simulator's state, which a real robot does not have (its
Section 6). This one is a small network that maps the last `frames` pictures to the hint of any
registered hint or `a+b` composite, trained by regression on rollouts of the jitted env:

    python -m hintsjax.generator env=pendulum hint=composite seeds=5     # -> runs/generator-...
    python -m hintsjax.run env=pendulum hint=composite hint_source=runs/generator-...

`hint_source` (training) and `eval_hint_source` (deploy; `python -m hintsjax.evaluate
--hint-source`) then make the agent see the generator's hints (its seed 0) in place of the
programmatic ones. The env that does it (`GeneratedHintEnv`) keeps the last pictures in its state
and the generator's params in its params, so it is as pure and jittable as the env it wraps.

Training is one jitted `train(key)` vmapped over seeds: rollouts (random actions N(0, 1), the
start of an untrained policy; optionally the packaged expert's in part of the envs, so the data
covers the states a good policy visits), then Adam on the mean squared error of the hint
normalised per dimension, then the held-out error and R^2 per dimension on rollouts of other
envs. The folder holds config.yaml, metrics.csv (per seed and hint dimension), generator.json and
the seed-batched params as an orbax checkpoint.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import json
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import optax
import orbax.checkpoint as ocp
import yaml
from flax import struct

from hintsjax import envs, rollouts
from hintsjax.arguments import parse_key_values
from hintsjax.checkpoint import on_this_device, require_same_arrays
from hintsjax.envs.core import Env, Step
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.errors import UsageError, command, require_positive, require_range
from hintsjax.networks import MLP, Encoder, scale_pixels
from hintsjax.runlog import fresh_folder

PROGRAMMATIC = "programmatic"  # the hint source that computes hints from the simulator's state
GENERATOR_JSON = "generator.json"
PARAMS = "generator"  # the orbax checkpoint inside a generator folder
POLICIES = {"random": "N(0, 1) actions", "expert": "the packaged expert in part of the envs"}


# -- the network ------------------------------------------------------------------------------------


class HintGenerator(nn.Module):
    """uint8[..., k, S, S, 3] (the last k pictures, oldest first) -> float32[..., width], the hint
    normalised per dimension: the agent's encoder on the pictures stacked along the channels, then
    one hidden layer."""

    width: int
    hidden: int = 256

    @nn.compact
    def __call__(self, frames: jax.Array) -> jax.Array:
        x = jnp.moveaxis(scale_pixels(frames), -4, -2)  # [..., S, S, k, 3]
        x = x.reshape(x.shape[:-2] + (-1,))  # [..., S, S, 3k]
        return MLP((self.hidden, self.width))(Encoder()(x))


@struct.dataclass
class GeneratorParams:
    """One generator's numbers: the network's params and the hint's per-dimension mean and std
    over its training data (the network predicts (hint - mean) / std)."""

    net: Any
    mean: jax.Array  # [d]
    std: jax.Array  # [d]


@dataclass(frozen=True)
class Generator:
    """A generator's structure (static): which hint of which env, from how many pictures."""

    env: str
    hint: str
    frames: int
    hidden: int = 256

    @property
    def spec(self) -> envs.Hint:
        return envs.make_hint(self.env, self.hint)

    @property
    def network(self) -> HintGenerator:
        return HintGenerator(self.spec.dim, self.hidden)

    def predict(self, params: GeneratorParams, frames: jax.Array) -> jax.Array:
        """The hint, in its own units, of pictures uint8[..., k, S, S, 3] -> float32[..., d]."""
        return params.mean + params.std * self.network.apply(params.net, frames)

    def init(self, key: jax.Array, image_size: int) -> Any:
        return self.network.init(key, jnp.zeros((1, self.frames, image_size, image_size, 3), jnp.uint8))


# -- the env that shows the agent the generator's hint ---------------------------------------------


@struct.dataclass
class FramedState:
    """The wrapped env's state and its last k pictures (oldest first; a new episode repeats its
    first picture); `t` mirrors the wrapped state's step count."""

    env_state: Any
    frames: jax.Array  # uint8[k, S, S, 3]
    t: jax.Array


@struct.dataclass
class GeneratedParams:
    """The wrapped env's params (a variant's) and the generator's."""

    task: Any
    generator: GeneratorParams


def push_frame(frames: jax.Array, frame: jax.Array) -> jax.Array:
    """The last k pictures after `frame`: [k, ...] -> [k, ...]."""
    return jnp.concatenate([frames[1:], frame[None]], axis=0)


@dataclass(frozen=True)
class GeneratedHint(envs.Hint):
    """The hint as the generator reads it off a FramedState's pictures (same name, parts and
    width as the programmatic hint it imitates, so plots and labels stay as they were)."""

    generator: Generator | None = None

    def __call__(self, state: FramedState, params: GeneratedParams) -> jax.Array:
        return self.generator.predict(params.generator, state.frames)


class GeneratedHintEnv(Env):
    """`inner`'s task with the hint read by `generator` off the last pictures: the four pieces of
    `inner`, plus the pictures carried in the state. Its params are GeneratedParams."""

    def __init__(self, inner: Env, generator: Generator, observe: tuple[str, ...]):
        self.inner = inner
        self.name, self.max_steps = inner.name, inner.max_steps
        self.action_size, self.image_size = inner.action_size, inner.image_size
        hint = inner.hint
        super().__init__(GeneratedHint(hint.env, hint.name, hint.parts, generator), observe)

    def initial_state(self, key: jax.Array, params: GeneratedParams) -> FramedState:
        state = self.inner.initial_state(key, params.task)
        frame = self.inner._render(state, params.task)
        return FramedState(state, jnp.repeat(frame[None], self.hint.generator.frames, axis=0), state.t)

    def action_range(self, params: GeneratedParams) -> tuple[jax.Array, jax.Array]:
        return self.inner.action_range(params.task)

    def transition(self, key: jax.Array, state: FramedState, action: jax.Array, params: GeneratedParams) -> Step:
        out = self.inner.transition(key, state.env_state, action, params.task)
        inner = out.state.replace(t=state.env_state.t + 1)  # as Env.step advances the wrapped env's count
        frames = push_frame(state.frames, self.inner._render(inner, params.task))
        return Step(FramedState(inner, frames, state.t), out.reward, out.terminated)

    def render(self, state: FramedState, params: GeneratedParams) -> jax.Array:
        return state.frames[-1]

    def state_obs(self, state: FramedState, params: GeneratedParams) -> jax.Array:
        return self.inner.state_obs(state.env_state, params.task)

    def metrics(self, state: FramedState, params: GeneratedParams) -> dict[str, jax.Array]:
        return self.inner.metrics(state.env_state, params.task)


# -- a generator folder -----------------------------------------------------------------------------


def describe(folder: str | Path) -> dict[str, Any]:
    """generator.json of a generator folder; UsageError if it is missing or unreadable."""
    path = Path(folder) / GENERATOR_JSON
    if not path.is_file():
        raise UsageError(f"no generator at {folder} (expected {GENERATOR_JSON}; train one with "
                         "python -m hintsjax.generator env=<env> hint=<hint>)")
    try:
        meta = json.loads(path.read_text())
        meta["frames"], meta["hidden"], meta["seeds"] = int(meta["frames"]), int(meta["hidden"]), int(meta["seeds"])
        str(meta["env"]), str(meta["hint"])
    except (ValueError, KeyError, TypeError) as e:
        raise UsageError(f"{path} is not a generator's description: {type(e).__name__}") from None
    return meta


def check_matches(folder: str | Path, env: str, hint: str) -> dict[str, Any]:
    """generator.json of `folder`, after checking that it generates `env`'s `hint` (the same
    registered parts in the same order) and that its checkpoint loads; UsageError naming what
    it generates, or what is wrong with it, otherwise."""
    meta = describe(folder)
    parts = lambda e, h: [p.name for p in envs.make_hint(e, h).parts]  # noqa: E731
    if meta["env"] != env or parts(meta["env"], meta["hint"]) != parts(env, hint):
        raise UsageError(f"the generator at {folder} generates {meta['env']}/{meta['hint']}, not {env}/{hint}")
    load(folder)
    return meta


def _as_dict(params: GeneratorParams) -> dict[str, Any]:
    """What the checkpoint stores: a plain dict (orbax restores it into any tree of that form)."""
    return {"net": params.net, "mean": params.mean, "std": params.std}


@functools.lru_cache(maxsize=16)
def _load(folder: str, mtime: float) -> tuple[Generator, GeneratorParams]:
    meta = describe(folder)
    generator = Generator(meta["env"], meta["hint"], meta["frames"], meta["hidden"])
    image_size = envs.make(meta["env"]).image_size
    abstract = jax.eval_shape(jax.vmap(lambda k: _fresh_params(generator, k, image_size)),
                              jax.random.split(jax.random.key(0), meta["seeds"]))
    abstract = on_this_device(abstract)
    try:
        with ocp.StandardCheckpointer() as loader:
            path = (Path(folder) / PARAMS).absolute()
            require_same_arrays(loader.metadata(path).item_metadata, abstract, f"{GENERATOR_JSON} gives")
            params = GeneratorParams(**loader.restore(path, _as_dict(abstract)))
    except Exception as e:  # orbax raises many types for unreadable or mismatched files
        reason = str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__
        raise UsageError(f"the generator checkpoint in {folder} is corrupt or does not match {GENERATOR_JSON}: {reason}") from None
    return generator, params


def load(folder: str | Path, seed: int = 0) -> tuple[Generator, GeneratorParams]:
    """The generator in `folder` and its seed `seed`'s params; UsageError if missing or corrupt."""
    meta = describe(folder)
    if not 0 <= seed < meta["seeds"]:
        raise UsageError(f"the generator at {folder} has seeds 0..{meta['seeds'] - 1}, not {seed}")
    resolved = Path(folder).resolve()
    generator, params = _load(str(resolved), (resolved / GENERATOR_JSON).stat().st_mtime)
    return generator, jax.tree.map(lambda x: x[seed], params)


def hinted_env(env: str, hint: str, observe: tuple[str, ...], source: str, **physics: Any) -> Env:
    """`env` with `hint` from `source`: the programmatic hint, or a generator folder's; `physics`
    (physics, warp_capacity) as `envs.make` takes them."""
    if source == PROGRAMMATIC or "hint" not in observe:
        return envs.make(env, hint, observe, **physics)
    generator, _ = load(source)
    return GeneratedHintEnv(envs.make(env, hint, ("pixels",), **physics), generator, observe)


def hinted_params(env: str, task_params: Any, observe: tuple[str, ...], source: str) -> Any:
    """The params of `hinted_env(env, ..., observe, source)` for a variant's `task_params`."""
    if source == PROGRAMMATIC or "hint" not in observe:
        return task_params
    return GeneratedParams(task_params, load(source)[1])


# -- training ---------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GeneratorConfig:
    """What `python -m hintsjax.generator` trains: a generator of `env`'s `hint` from the last
    `frames` pictures, on `num_envs` x `steps` rollout steps (held out: `held_out_envs` x `steps`)."""

    env: str = "pendulum"
    hint: str = "composite"
    variant: str | None = None  # the env variant the rollouts run in (None: its default)
    frames: int = 2  # 2 measured best: experiments/results/learned_hints.md, "How many pictures"
    seeds: int = 1
    seed: int = 0  # seed i is PRNGKey(seed + i)
    num_envs: int = 64
    steps: int = 500
    held_out_envs: int = 16
    policy: str = "random"  # who acts in the rollouts: random (N(0, 1) actions) or expert (in part of the envs)
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
            raise UsageError(f"hint '{self.hint}' is empty: give a registered hint of {self.env} "
                             f"({', '.join(envs.hint_names(self.env))})")
        require_positive(self, ("frames", "seeds", "num_envs", "steps", "held_out_envs", "epochs", "minibatch_size",
                                "lr", "hidden"))
        require_range(self, {"expert_fraction": (0.0, 1.0)})
        if self.minibatch_size > self.num_envs * self.steps:
            raise UsageError(f"minibatch_size ({self.minibatch_size}) exceeds the {self.num_envs * self.steps} "
                             "training samples (num_envs x steps)")
        if self.policy == "expert":
            from hintsjax import expert

            expert.describe(self.env)
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
        from hintsjax import expert

        policy = expert.load(cfg.env)
    env = envs.AutoReset(envs.make(cfg.env, cfg.hint, rollouts.observed(policy)))
    params = envs.make_params(cfg.env, cfg.variant)

    def record(state, obs, action, ts) -> Rollouts:
        return Rollouts(obs["pixels"], state.episode_length, obs["hint"])

    def collect(key: jax.Array, num_envs: int) -> Rollouts:
        return rollouts.rollout(env, params, key, num_envs, cfg.steps, record, policy,
                                driven=round(cfg.expert_fraction * num_envs))

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


def _fresh_params(generator: Generator, key: jax.Array, image_size: int) -> GeneratorParams:
    d = generator.spec.dim
    return GeneratorParams(generator.init(key, image_size), jnp.zeros(d), jnp.ones(d))


def make_train(cfg: GeneratorConfig) -> Callable[[jax.Array], tuple[GeneratorParams, GeneratorMetrics]]:
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
            loss, grads = jax.value_and_grad(loss_fn)(net, *targets(data, idx // N, idx % N, mean, std))
            updates, opt_state = optimizer.update(grads, opt_state, net)
            return (optax.apply_updates(net, updates), opt_state), loss

        def epoch(carry, key):
            order = jax.random.permutation(key, samples)[: per_epoch * B].reshape(per_epoch, B)
            carry, losses = jax.lax.scan(minibatch, carry, order)
            return carry, losses.mean()

        (net, _), loss = jax.lax.scan(epoch, (net, optimizer.init(net)), jax.random.split(k_epochs, cfg.epochs))
        train_mse, train_r2 = errors(net, data, N, mean, std)
        heldout_mse, heldout_r2 = errors(net, held, cfg.held_out_envs, mean, std)
        return GeneratorParams(net, mean, std), GeneratorMetrics(loss, train_mse, heldout_mse, train_r2, heldout_r2)

    return train


def dimension_names(hint: envs.Hint) -> list[str]:
    """One name per hint dimension: the part's name, with [i] for parts wider than one."""
    return [p.name if p.dim == 1 else f"{p.name}[{i}]" for p in hint.parts for i in range(p.dim)]


def write_folder(folder: Path, cfg: GeneratorConfig, params: GeneratorParams, metrics: GeneratorMetrics,
                 seconds: dict[str, float]) -> dict[str, Any]:
    """Write a trained generator's folder; generator.json last (a folder without it is incomplete)."""
    names = dimension_names(cfg.generator.spec)
    m = jax.tree.map(np.asarray, metrics)
    with (folder / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["seed", "dimension", "train_mse", "heldout_mse", "train_r2", "heldout_r2", "final_loss"])
        for s in range(cfg.seeds):
            for i, name in enumerate(names):
                writer.writerow([s, name, *(f"{float(getattr(m, a)[s, i]):.6g}" for a in
                                            ("train_mse", "heldout_mse", "train_r2", "heldout_r2")), f"{m.loss[s, -1]:.6g}"])
    with ocp.StandardCheckpointer() as saver:
        saver.save((folder / PARAMS).absolute(), _as_dict(params), force=True)
    meta = {
        "env": cfg.env, "hint": cfg.hint, "frames": cfg.frames, "hidden": cfg.hidden, "seeds": cfg.seeds,
        "dimensions": names,
        "heldout_r2_mean": m.heldout_r2.mean(axis=0).tolist(), "heldout_r2_min": m.heldout_r2.min(axis=0).tolist(),
        "train_r2_mean": m.train_r2.mean(axis=0).tolist(),
        "env_steps": (cfg.num_envs + cfg.held_out_envs) * cfg.steps, "seconds": seconds,
        "device": jax.devices()[0].device_kind, "config": dataclasses.asdict(cfg),
    }
    (folder / GENERATOR_JSON).write_text(json.dumps(meta, indent=1))
    return meta


def train_folder(cfg: GeneratorConfig) -> tuple[Path, dict[str, Any]]:
    """Train cfg's seeds in one jitted call and write their folder; (folder, generator.json)."""
    name = cfg.name or f"generator-{cfg.env}-{cfg.hint}-{time.strftime('%Y%m%d-%H%M%S')}"
    folder = fresh_folder(Path(cfg.out_dir) / name)
    (folder / "config.yaml").write_text(yaml.safe_dump(dataclasses.asdict(cfg), sort_keys=False))
    keys = jnp.stack([jax.random.key(cfg.seed + i) for i in range(cfg.seeds)])
    start = time.perf_counter()
    train = jax.jit(jax.vmap(make_train(cfg))).lower(keys).compile()
    compiled = time.perf_counter()
    params, metrics = jax.block_until_ready(train(keys))
    done = time.perf_counter()
    seconds = {"compile": round(compiled - start, 2), "train": round(done - compiled, 2)}
    return folder, write_folder(folder, cfg, params, metrics, seconds)


def parse(argv: list[str]) -> GeneratorConfig:
    """GeneratorConfig from `key=value` arguments; UsageError naming the valid keys."""
    return parse_key_values(GeneratorConfig, argv).validate()


@command
def main(argv: list[str] | None = None) -> int:
    cfg = parse(sys.argv[1:] if argv is None else argv)
    print(f"generator of {cfg.env}/{cfg.hint} from {cfg.frames} pictures: {cfg.seeds} seed(s), "
          f"{cfg.num_envs} x {cfg.steps} steps of {cfg.policy} rollouts, {cfg.epochs} epochs", flush=True)
    folder, meta = train_folder(cfg)
    r2 = ", ".join(f"{n} {v:.3f}" for n, v in zip(meta["dimensions"], meta["heldout_r2_mean"]))
    print(f"held-out R^2 (mean over seeds): {r2}; compile {meta['seconds']['compile']:.0f} s, "
          f"train {meta['seconds']['train']:.0f} s -> {folder}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
