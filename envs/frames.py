"""The last pictures of an episode, carried in the state: for an agent that sees several at once
(`frames=`, the run setting) and for a learned hint generator that reads its hint off them.

`FramedState` holds a wrapped env's state and its last k pictures; `FrameStack` is the env whose
"pixels" observation is those k pictures side by side along the channels, oldest first, so one
picture cannot hide a velocity (MuJoCo Playground's vision tasks stack 3 grey frames the same
way). A new episode repeats its first picture k times, as Playground's do. The state and hint
observations, the reward, the ends, the metrics and `render` (the newest picture, for videos) are
the wrapped env's, so the stack is one more pure piece that jits and vmaps with the rest.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax.envs.core import Env, Step


@struct.dataclass
class FramedState:
    """The wrapped env's state and its last k pictures (oldest first; a new episode repeats its
    first picture); `t` mirrors the wrapped state's step count."""

    env_state: Any
    frames: jax.Array  # uint8[k, S, S, 3]
    t: jax.Array


def push_frame(frames: jax.Array, frame: jax.Array) -> jax.Array:
    """The last k pictures after `frame`: [k, ...] -> [k, ...]."""
    return jnp.concatenate([frames[1:], frame[None]], axis=0)


def framed_start(inner: Env, state: Any, params: Any, k: int) -> FramedState:
    """`state`, a fresh episode of `inner`, with its first picture repeated k times."""
    return FramedState(state, jnp.repeat(inner._render(state, params)[None], k, axis=0), state.t)


def framed_step(inner: Env, key: jax.Array, state: FramedState, action: jax.Array, params) -> Step:
    """`inner`'s transition of the wrapped state, its new picture pushed onto the last ones."""
    out = inner.transition(key, state.env_state, action, params)
    # as Env.step advances the wrapped env's count
    advanced = out.state.replace(t=state.env_state.t + 1)
    frames = push_frame(state.frames, inner._render(advanced, params))
    return Step(FramedState(advanced, frames, state.t), out.reward, out.terminated)


def side_by_side(frames: jax.Array) -> jax.Array:
    """uint8[k, S, S, C] -> uint8[S, S, k * C]: the k pictures along the channels, oldest first."""
    k, s, _, c = frames.shape
    return jnp.moveaxis(frames, 0, 2).reshape(s, s, k * c)


class FrameStack(Env):
    """`inner` whose "pixels" are its last `k` pictures, uint8[S, S, 3k] (`side_by_side`); every
    other piece is `inner`'s. Its params are `inner`'s."""

    def __init__(self, inner: Env, k: int):
        if k < 2:
            raise ValueError(f"a frame stack holds 2 pictures or more, got {k}")
        self.inner, self.k = inner, int(k)
        self.name, self.max_steps = inner.name, inner.max_steps
        self.action_size, self.image_size = inner.action_size, inner.image_size
        super().__init__(inner.hint, inner.observe)

    def __getattr__(self, name: str) -> Any:  # the wrapped env's own (its scene, its camera)
        if name == "inner":  # not yet set
            raise AttributeError(name)
        return getattr(self.inner, name)

    def default_params(self) -> Any:
        return self.inner.default_params()

    def initial_state(self, key: jax.Array, params: Any) -> FramedState:
        return framed_start(self.inner, self.inner.initial_state(key, params), params, self.k)

    def transition(self, key: jax.Array, state: FramedState, action: jax.Array, params) -> Step:
        return framed_step(self.inner, key, state, action, params)

    def render(self, state: FramedState, params: Any) -> jax.Array:
        return state.frames[-1]

    def state_obs(self, state: FramedState, params: Any) -> jax.Array:
        return self.inner.state_obs(state.env_state, params)

    def action_range(self, params: Any) -> tuple[jax.Array, jax.Array]:
        return self.inner.action_range(params)

    def metrics(self, state: FramedState, params: Any) -> dict[str, jax.Array]:
        return self.inner.metrics(state.env_state, params)

    def observation(self, state: FramedState, params: Any) -> dict[str, jax.Array]:
        build = {
            "pixels": lambda: side_by_side(state.frames),
            "state": lambda: self.inner.state_obs(state.env_state, params),
            "hint": lambda: self.inner.hint(state.env_state, params),
        }
        return {k: build[k]() for k in self.observe}
