"""Where an agent's hint comes from: the simulator's state (programmatic), or a learned generator.

A generator (trained by `python -m hintsjax.generator`, hintsjax/hints/generators.py) is a small
network that reads the hint off the last `frames` pictures. Its folder holds generator.json and the
seed-batched params as an orbax checkpoint; `load` reads one seed of it. `hinted_env` and
`hinted_params` give the env an agent acts in for a hint source: the programmatic env, or
`GeneratedHintEnv`, which keeps the last pictures in its state and the generator's params in its
params, so it is as pure and jittable as the env it wraps.

This sits below the settings (hintsjax/settings/config.py builds its envs through it) and above
envs/ and the networks; it imports nothing that trains.
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import flax.linen as nn
import jax
import jax.numpy as jnp
import orbax.checkpoint as ocp
from flax import struct

from hintsjax import envs
from hintsjax.envs.core import Env, Step
from hintsjax.envs.frames import RGB, FramedState, FrameStack, framed_start, framed_step
from hintsjax.system.checkpoint import on_this_device, require_same_arrays
from hintsjax.system.errors import UsageError
from hintsjax.models.networks import Encoder, MLP, scale_pixels

PROGRAMMATIC = "programmatic"  # the hint source that computes hints from the simulator's state
GENERATOR_JSON = "generator.json"
PARAMS = "generator"  # the orbax checkpoint inside a generator folder


# -- the network -----------------------------------------------------------------------------------


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
        return self.network.init(
            key, jnp.zeros((1, self.frames, image_size, image_size, 3), jnp.uint8)
        )


# -- the env that shows the agent the generator's hint ---------------------------------------------


@struct.dataclass
class GeneratedParams:
    """The wrapped env's params (a variant's) and the generator's."""

    task: Any
    generator: GeneratorParams


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
        return framed_start(self.inner, state, params.task, self.hint.generator.frames)

    def action_range(self, params: GeneratedParams) -> tuple[jax.Array, jax.Array]:
        return self.inner.action_range(params.task)

    def transition(
        self, key: jax.Array, state: FramedState, action: jax.Array, params: GeneratedParams
    ) -> Step:
        return framed_step(self.inner, key, state, action, params.task)

    def render(self, state: FramedState, params: GeneratedParams) -> jax.Array:
        return state.frames[-1]

    def state_obs(self, state: FramedState, params: GeneratedParams) -> jax.Array:
        return self.inner.state_obs(state.env_state, params.task)

    def metrics(self, state: FramedState, params: GeneratedParams) -> dict[str, jax.Array]:
        return self.inner.metrics(state.env_state, params.task)


# -- a generator folder ----------------------------------------------------------------------------


def describe(folder: str | Path) -> dict[str, Any]:
    """generator.json of a generator folder; UsageError if it is missing or unreadable."""
    path = Path(folder) / GENERATOR_JSON
    if not path.is_file():
        raise UsageError(
            f"no generator at {folder} (expected {GENERATOR_JSON}; train one with "
            "python -m hintsjax.generator env=<env> hint=<hint>)"
        )
    try:
        meta = json.loads(path.read_text())
        meta["frames"], meta["hidden"], meta["seeds"] = (
            int(meta["frames"]),
            int(meta["hidden"]),
            int(meta["seeds"]),
        )
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
        raise UsageError(
            f"the generator at {folder} generates {meta['env']}/{meta['hint']}, not {env}/{hint}"
        )
    load(folder)
    return meta


def fresh_params(generator: Generator, key: jax.Array, image_size: int) -> GeneratorParams:
    """A generator's params before training: fresh weights, the hint neither shifted nor scaled."""
    d = generator.spec.dim
    return GeneratorParams(generator.init(key, image_size), jnp.zeros(d), jnp.ones(d))


def stored(params: GeneratorParams) -> dict[str, Any]:
    """What the checkpoint stores: a plain dict (orbax restores it into any tree of that form)."""
    return {"net": params.net, "mean": params.mean, "std": params.std}


@functools.lru_cache(maxsize=16)
def _load(folder: str, mtime: float) -> tuple[Generator, GeneratorParams]:
    meta = describe(folder)
    generator = Generator(meta["env"], meta["hint"], meta["frames"], meta["hidden"])
    image_size = envs.make(meta["env"]).image_size
    abstract = jax.eval_shape(
        jax.vmap(lambda k: fresh_params(generator, k, image_size)),
        jax.random.split(jax.random.key(0), meta["seeds"]),
    )
    abstract = on_this_device(abstract)
    try:
        with ocp.StandardCheckpointer() as loader:
            path = (Path(folder) / PARAMS).absolute()
            require_same_arrays(
                loader.metadata(path).item_metadata, abstract, f"{GENERATOR_JSON} gives"
            )
            params = GeneratorParams(**loader.restore(path, stored(abstract)))
    except Exception as e:  # orbax raises many types for unreadable or mismatched files
        reason = str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__
        raise UsageError(
            f"the generator checkpoint in {folder} is corrupt or does not match {GENERATOR_JSON}: "
            f"{reason}"
        ) from None
    return generator, params


def load(folder: str | Path, seed: int = 0) -> tuple[Generator, GeneratorParams]:
    """The generator in `folder` and its seed `seed`'s params; UsageError if missing or corrupt."""
    meta = describe(folder)
    if not 0 <= seed < meta["seeds"]:
        raise UsageError(f"the generator at {folder} has seeds 0..{meta['seeds'] - 1}, not {seed}")
    resolved = Path(folder).resolve()
    generator, params = _load(str(resolved), (resolved / GENERATOR_JSON).stat().st_mtime)
    return generator, jax.tree.map(lambda x: x[seed], params)


def hinted_env(
    env: str,
    hint: str,
    observe: tuple[str, ...],
    source: str,
    frames: int = 1,
    colour: str = RGB,
    **physics: Any,
) -> Env:
    """`env` with `hint` from `source`: the programmatic hint, or a generator folder's; its pixels
    the last `frames` pictures in `colour` (envs/frames.py; a generator reads the env's own);
    `physics` (physics, warp_capacity, image_size) as `envs.make` takes them."""
    if source == PROGRAMMATIC or "hint" not in observe:
        made = envs.make(env, hint, observe, **physics)
    else:
        generator, _ = load(source)
        made = GeneratedHintEnv(envs.make(env, hint, ("pixels",), **physics), generator, observe)
    stacked = (frames > 1 or colour != RGB) and "pixels" in observe
    return FrameStack(made, frames, colour) if stacked else made


def hinted_params(env: str, task_params: Any, observe: tuple[str, ...], source: str) -> Any:
    """The params of `hinted_env(env, ..., observe, source)` for a variant's `task_params`."""
    if source == PROGRAMMATIC or "hint" not in observe:
        return task_params
    return GeneratedParams(task_params, load(source)[1])
