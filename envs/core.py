"""The environment protocol: pure `reset(key, params)` / `step(key, state, action, params)`.

Every env in the suite subclasses `Env` and supplies four pure pieces: how a fresh state is
drawn, how a state advances under an action, how it is drawn as a picture, and its state
observation; optionally a fifth, `metrics`: named scalars of a state that evaluation reports
for the state each episode ended in (the car's progress). `Env` adds the time limit, the
dictionary observation and the hint; `AutoReset` adds fresh episodes on `terminated |
truncated` and keeps the pre-reset observation so that a learner can bootstrap on truncation.
"""

from __future__ import annotations

from typing import Any, Callable

import jax
import jax.numpy as jnp
from flax import struct

from hintsjax.envs.hints import Hint

OBS_KEYS = ("pixels", "state", "hint")


@struct.dataclass
class Timestep:
    """What `reset` and `step` return: the new state, what the agent sees and the outcome."""

    state: Any
    obs: dict[str, jax.Array]
    reward: jax.Array
    terminated: jax.Array
    truncated: jax.Array
    # Observation of the state an episode ended in; set by AutoReset, where `obs` is the next
    # episode's first observation. Equal to `obs` on steps where nothing ended.
    final_obs: dict[str, jax.Array] | None = None
    # Logged statistics (dicts only for metrics).
    info: dict[str, jax.Array] = struct.field(default_factory=dict)


@struct.dataclass
class Step:
    """What an env's `transition` returns: the next state and the task's outcome."""

    state: Any
    reward: jax.Array
    terminated: jax.Array


class Env:
    """Base class of every env. Subclasses set the class attributes, `default_params` and the
    four pure pieces (`initial_state`, `transition`, `render`, `state_obs`); optionally
    `metrics`, scalars of a state reported at each evaluation episode's end (default: none).

    Instances are static configuration (which hint, which observations are built); everything
    that varies per episode lives in the state, everything a sweep may vary lives in params.
    """

    name: str = ""
    max_steps: int = 0
    action_size: int = 0
    # the picture's side in pixels; an instance may draw at another (`image_size=`)
    image_size: int = 64
    # True: the env draws at its own side only (the car's precomputed grid)
    fixed_image_size: bool = False

    def __init__(
        self, hint: Hint, observe: tuple[str, ...] = OBS_KEYS, image_size: int | None = None
    ):
        unknown = set(observe) - set(OBS_KEYS)
        if unknown:
            raise ValueError(f"unknown observation keys {sorted(unknown)}; valid: {OBS_KEYS}")
        if image_size is not None:
            self.check_image_size(image_size)
            self.image_size = int(image_size)
        self.hint = hint
        self.observe = tuple(observe)
        # The picture through one jax.jit per env: a program that draws several (a step's and
        # AutoReset's fresh start) traces the drawing once.
        self._render = jax.jit(self.render)

    @classmethod
    def check_image_size(cls, image_size: int) -> None:
        """ValueError where this env cannot draw pictures `image_size` pixels a side."""
        if image_size == cls.image_size:
            return
        if cls.fixed_image_size:
            raise ValueError(
                f"{cls.name} draws {cls.image_size}x{cls.image_size} pictures only "
                f"(image_size={cls.image_size} or null), not {image_size}"
            )
        if not 1 <= image_size:
            raise ValueError(f"image_size must be a positive number of pixels, got {image_size}")

    # -- the four pieces each env supplies ---------------------------------------------------
    def default_params(self) -> Any:
        raise NotImplementedError

    def initial_state(self, key: jax.Array, params: Any) -> Any:
        """A fresh episode's state (with `t = 0`), drawn from the start distribution."""
        raise NotImplementedError

    def transition(self, key: jax.Array, state: Any, action: jax.Array, params: Any) -> Step:
        """Advance one control step: dynamics, reward and termination (not the time limit)."""
        raise NotImplementedError

    def render(self, state: Any, params: Any) -> jax.Array:
        """uint8[S, S, 3] picture of the state."""
        raise NotImplementedError

    def state_obs(self, state: Any, params: Any) -> jax.Array:
        """float32[n] state observation, as the Gymnasium reference env returns it."""
        raise NotImplementedError

    def action_range(self, params: Any) -> tuple[jax.Array, jax.Array]:
        """float32[A] low and high of the actions `transition` applies: it clips any other action
        into them (what `SquashedActions` maps onto)."""
        raise NotImplementedError

    # -- optional ----------------------------------------------------------------------------
    def metrics(self, state: Any, params: Any) -> dict[str, jax.Array]:
        """Named float scalars of a state, reported by evaluation for the state each episode
        ended in (e.g. the car's progress); {} (the default) adds nothing to the report."""
        return {}

    # -- the protocol -------------------------------------------------------------------------
    @property
    def state_size(self) -> int:
        params = self.default_params()
        shape = jax.eval_shape(
            lambda k: self.state_obs(self.initial_state(k, params), params), jax.random.key(0)
        )
        return int(shape.shape[0])

    def observation(self, state: Any, params: Any) -> dict[str, jax.Array]:
        """The dictionary observation, with only the keys in `self.observe`."""
        build: dict[str, Callable[[], jax.Array]] = {
            "pixels": lambda: self._render(state, params),
            "state": lambda: self.state_obs(state, params),
            "hint": lambda: self.hint(state, params),
        }
        return {k: build[k]() for k in self.observe}

    def reset(self, key: jax.Array, params: Any) -> Timestep:
        """Start an episode."""
        state = self.initial_state(key, params)
        zero = jnp.zeros((), jnp.float32)
        false = jnp.zeros((), bool)
        return Timestep(state, self.observation(state, params), zero, false, false)

    def step(self, key: jax.Array, state: Any, action: jax.Array, params: Any) -> Timestep:
        """Advance one step; `truncated` is set when the time limit is reached."""
        out = self.transition(key, state, action, params)
        next_state = out.state.replace(t=state.t + 1)
        truncated = (next_state.t >= self.max_steps) & ~out.terminated
        return Timestep(
            next_state,
            self.observation(next_state, params),
            out.reward.astype(jnp.float32),
            out.terminated,
            truncated,
        )


def fresh_episodes(key: jax.Array, env: Any, params: Any, n: int) -> Timestep:
    """`n` fresh episodes of `env` (any env or wrapper with `reset`), one key of `key`'s split each:
    the batch a run, a rollout or an evaluation starts from."""
    return jax.vmap(env.reset, in_axes=(0, None))(jax.random.split(key, n), params)


def rows_where(fn: Callable[[Any], Any], xs: Any, where: jax.Array, chunk: int) -> Any:
    """`fn` (batched rows [K, ...] -> a pytree of [K, ...]) of the rows of `xs` ([N, ...]) where
    `where` (bool[N]) holds, zeros elsewhere: `fn` runs on `chunk` rows at a time (N a multiple of
    it), the asked rows first, and only for as many chunks as there are asked rows: none where no
    row is asked, N / chunk (one whole batch's worth) where every one is. What a step pays for the
    few envs it needs something of (a truncated episode's value, an ended one's fresh start)."""
    n = where.shape[0]
    order = jnp.argsort(~where, stable=True)  # the asked rows first
    count = where.sum()
    shapes = jax.eval_shape(fn, jax.tree.map(lambda x: x[:chunk], xs))
    zeros = jax.tree.map(lambda s: jnp.zeros((n, *s.shape[1:]), s.dtype), shapes)

    def one(carry):
        i, out = carry
        rows = jax.lax.dynamic_slice_in_dim(order, i * chunk, chunk)
        got = fn(jax.tree.map(lambda x: x[rows], xs))
        asked = where[rows]

        def put(o: jax.Array, g: jax.Array) -> jax.Array:
            kept = jnp.where(asked.reshape(-1, *(1,) * (g.ndim - 1)), g, jnp.zeros_like(g))
            return o.at[rows].set(kept)

        return i + 1, jax.tree.map(put, out, got)

    start = (jnp.zeros((), jnp.int32), zeros)
    return jax.lax.while_loop(lambda c: c[0] * chunk < count, one, start)[1]


@struct.dataclass
class EpisodeState:
    """AutoReset's state: the env's state plus the running episode statistics."""

    env_state: Any
    episode_return: jax.Array
    episode_length: jax.Array


class AutoReset:
    """Wraps an Env so that `step` starts a fresh episode whenever one ends.

    On the step that ends an episode `obs` is the new episode's first observation and
    `final_obs` the observation of the state it ended in; `info` carries the finished
    episode's return and length (valid where `terminated | truncated`).
    """

    def __init__(self, env: Env):
        self.env = env

    def __getattr__(self, name):
        return getattr(self.env, name)

    def reset(self, key: jax.Array, params: Any) -> Timestep:
        ts = self.env.reset(key, params)
        zero = jnp.zeros((), jnp.float32)
        state = EpisodeState(ts.state, zero, jnp.zeros((), jnp.int32))
        return ts.replace(
            state=state, final_obs=ts.obs, info=_episode_info(zero, state.episode_length)
        )

    def fresh_start(self, key: jax.Array, params: Any) -> Timestep:
        """A start for `step`'s `fresh`: the wrapped env's reset."""
        return self.env.reset(key, params)

    def step(
        self,
        key: jax.Array,
        state: EpisodeState,
        action: jax.Array,
        params: Any,
        fresh: Timestep | None = None,
    ) -> Timestep:
        """One step; where the episode ends, the next one starts from `fresh` (a `fresh_start`).

        Without `fresh` a start is drawn here, on every step: vmapped code computes it whether or
        not an episode ended, a whole reset (and picture) per step; `step_ended` is the same
        step of a batch drawing only the ended envs' starts. A rollout may instead draw one
        start per env up front and pass it to each of its steps (an env whose episodes end
        twice in one rollout then starts both from it).
        """
        step_key, reset_key = jax.random.split(key)
        ts = self.env.step(step_key, state.env_state, action, params)
        fresh = self.env.reset(reset_key, params) if fresh is None else fresh
        return self.go_on(state, ts, fresh)

    def step_ended(
        self, keys: jax.Array, state: EpisodeState, action: jax.Array, params: Any, chunk: int
    ) -> Timestep:
        """`step` vmapped over N envs (keys, state and action batched, no `fresh`), with each
        ended episode's start drawn as `step` draws it (same key, same start) but only for the
        envs whose episodes ended, `chunk` of them at a time (`rows_where`): a step where none
        ended draws no start, where a vmapped `step` draws (and pictures) N."""
        keys = jax.vmap(jax.random.split)(keys)
        ts = jax.vmap(self.env.step, in_axes=(0, 0, 0, None))(
            keys[:, 0], state.env_state, action, params
        )
        fresh = rows_where(
            lambda k: jax.vmap(self.env.reset, in_axes=(0, None))(k, params),
            keys[:, 1],
            ts.terminated | ts.truncated,
            chunk,
        )
        return jax.vmap(self.go_on)(state, ts, fresh)

    def go_on(self, state: EpisodeState, ts: Timestep, fresh: Timestep) -> Timestep:
        """The step `ts` from `state` with its episode statistics, going on from `fresh` where
        its episode ended."""
        done = ts.terminated | ts.truncated
        episode_return = state.episode_return + ts.reward
        episode_length = state.episode_length + 1
        pick = lambda a, b: jax.tree.map(lambda x, y: jnp.where(done, x, y), a, b)  # noqa: E731
        next_state = EpisodeState(
            pick(fresh.state, ts.state),
            jnp.where(done, 0.0, episode_return),
            jnp.where(done, 0, episode_length),
        )
        return ts.replace(
            state=next_state,
            obs=pick(fresh.obs, ts.obs),
            final_obs=ts.obs,
            info=_episode_info(episode_return, episode_length),
        )


class SquashedActions:
    """Wraps an Env so that its actions are unbounded: u in R^A becomes
    low + (high - low) * (tanh(u) + 1) / 2 in the env's `action_range`, so no action is clipped.

    The agent's tanh-squashed Gaussian (`ppo.action_head=tanh`): the policy samples u from its
    Gaussian and PPO's ratio of two policies' densities at u equals their ratio at the squashed
    action (the squash's Jacobian cancels), so the learner is PPO's as it is; a deterministic
    policy acts tanh(mean), mapped.
    """

    def __init__(self, env: Env):
        self.env = env

    def __getattr__(self, name):
        return getattr(self.env, name)

    def squash(self, u: jax.Array, params: Any) -> jax.Array:
        low, high = self.env.action_range(params)
        return low + (high - low) * (jnp.tanh(u) + 1.0) / 2.0

    def step(self, key: jax.Array, state: Any, action: jax.Array, params: Any) -> Timestep:
        return self.env.step(key, state, self.squash(action, params), params)


def _episode_info(episode_return: jax.Array, episode_length: jax.Array) -> dict[str, jax.Array]:
    return {"episode_return": episode_return, "episode_length": episode_length}
