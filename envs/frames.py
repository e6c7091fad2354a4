"""The last pictures of an episode, carried in the state: for an agent that sees several at once
(`frames=`, the run setting) and for a learned hint generator that reads its hint off them.

`FramedState` holds a wrapped env's state and its last k pictures; `FrameStack` is the env whose
"pixels" observation is those k pictures side by side along the channels, oldest first, so one
picture cannot hide a velocity (MuJoCo Playground's vision tasks stack 3 grey frames the same
way), each RGB or grey (`colour=`: one channel, the mean of the three, as Playground's). A new
episode repeats its first picture k times, as Playground's do. The state and hint observations,
the reward, the ends, the metrics and `render` (the newest picture, for videos) are the wrapped
env's, so the stack is one more pure piece that jits and vmaps with the rest.
"""

from __future__ import annotations

from typing import Any

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax.envs.core import Env, Step

RGB, GREY = "rgb", "grey"
COLOURS = (RGB, GREY)  # the pictures an agent sees: as drawn, or one channel


@struct.dataclass
class FramedState:
    """The wrapped env's state and its last k pictures (oldest first; a new episode repeats its
    first picture); `t` mirrors the wrapped state's step count."""

    env_state: Any
    frames: jax.Array  # uint8[k, S, S, C]: C 3 (RGB) or 1 (grey)
    t: jax.Array


def push_frame(frames: jax.Array, frame: jax.Array) -> jax.Array:
    """The last k pictures after `frame`: [k, ...] -> [k, ...]."""
    return jnp.concatenate([frames[1:], frame[None]], axis=0)


def grey(picture: jax.Array) -> jax.Array:
    """uint8[S, S, 3] -> uint8[S, S, 1]: the mean of the three channels, rounded (Playground's
    vision tasks' grey, there in floats)."""
    return jnp.round(picture.astype(jnp.float32).mean(-1, keepdims=True)).astype(jnp.uint8)


def picture(inner: Env, state: Any, params: Any, colour: str = RGB) -> jax.Array:
    """`inner`'s picture of `state` in `colour`."""
    drawn = inner._render(state, params)
    return grey(drawn) if colour == GREY else drawn


def framed_start(inner: Env, state: Any, params: Any, k: int, colour: str = RGB) -> FramedState:
    """`state`, a fresh episode of `inner`, with its first picture repeated k times."""
    first = picture(inner, state, params, colour)
    return FramedState(state, jnp.repeat(first[None], k, axis=0), state.t)


def framed_step(
    inner: Env, key: jax.Array, state: FramedState, action: jax.Array, params, colour: str = RGB
) -> Step:
    """`inner`'s transition of the wrapped state, its new picture pushed onto the last ones."""
    out = inner.transition(key, state.env_state, action, params)
    # as Env.step advances the wrapped env's count
    advanced = out.state.replace(t=state.env_state.t + 1)
    frames = push_frame(state.frames, picture(inner, advanced, params, colour))
    return Step(FramedState(advanced, frames, state.t), out.reward, out.terminated)


def side_by_side(frames: jax.Array) -> jax.Array:
    """uint8[k, S, S, C] -> uint8[S, S, k * C]: the k pictures along the channels, oldest first."""
    k, s, _, c = frames.shape
    return jnp.moveaxis(frames, 0, 2).reshape(s, s, k * c)


class FrameStack(Env):
    """`inner` whose "pixels" are its last `k` pictures in `colour`, uint8[S, S, 3k] or [S, S, k]
    grey (`side_by_side`); every other piece is `inner`'s. Its params are `inner`'s."""

    def __init__(self, inner: Env, k: int, colour: str = RGB):
        if colour not in COLOURS:
            raise ValueError(f"colour must be one of {', '.join(COLOURS)}, got {colour!r}")
        if k < 1 or (k < 2 and colour == RGB):
            raise ValueError(f"a frame stack holds 1 grey picture or 2 or more, got {k} {colour}")
        self.inner, self.k, self.colour = inner, int(k), colour
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
        state = self.inner.initial_state(key, params)
        return framed_start(self.inner, state, params, self.k, self.colour)

    def transition(self, key: jax.Array, state: FramedState, action: jax.Array, params) -> Step:
        return framed_step(self.inner, key, state, action, params, self.colour)

    def render(self, state: FramedState, params: Any) -> jax.Array:
        """uint8[S, S, 3]: the newest picture (grey in all three channels where it is grey)."""
        return jnp.broadcast_to(state.frames[-1], (*state.frames.shape[1:3], 3))

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
