"""A hintsjax env as Gymnasium 1.x sees it: `VectorEnv` (many envs, one jitted call a step) and
`SingleEnv` (one env, what `gymnasium.make` and `check_env` take).

Both draw their randomness from the same per-env key stream, so a vector env reset with seed s
steps exactly as Gymnasium's own `SyncVectorEnv` (autoreset_mode=SAME_STEP) over single envs
seeded s, s+1, ... does (tests/test_gym.py checks it):

    reset(seed=s):  key = seed_key(s); key, k = split(key); state = env.reset(k)
    reset():        key, k = split(key); state = env.reset(k)         (the stream goes on)
    step(a):        key, k = split(key); state = env.step(k, state, a)

and where a vector env's episode ends, it resets that env as `reset()` does, in the same step
(`AutoresetMode.SAME_STEP`: the observation returned starts the next episode; the last one of the
ended episode is in `info["final_obs"]`, as Gymnasium's vector envs put it).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from functools import lru_cache
from typing import Any, Callable, Sequence

import gymnasium
import jax
import jax.numpy as jnp
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import batch_space

from hintsjax import envs
from hintsjax.envs.errors import ChoiceError

_UINT32 = (1 << 32) - 1


def seed_key(seed: int) -> np.ndarray:
    """uint32[2] JAX key of a Gymnasium seed (a non-negative int): jax.random.PRNGKey(seed) where
    that is exact (seeds below 2^64; PRNGKey itself drops the high 32 bits without 64-bit mode),
    a hash of the seed (NumPy's SeedSequence) beyond."""
    if seed < 1 << 64:
        return np.array([(seed >> 32) & _UINT32, seed & _UINT32], np.uint32)
    return np.random.SeedSequence(seed).generate_state(2, np.uint32)


def default_hint(name: str) -> str:
    """The hint env `name` trains with by default (its TRAINING's), `none` where it has none."""
    return envs.choose("env", name, envs.REGISTRY).training.get("hint") or envs.NO_HINT


def _observe(observe: str | Sequence[str] | None, hint: envs.Hint) -> tuple[tuple[str, ...], bool]:
    """The keys to observe and whether the observation is a Dict (a list of keys) or one array
    (one key as a string). None: the pixels, and the hint where it has a width."""
    if observe is None:
        observe = ("pixels", "hint") if hint.dim else ("pixels",)
    names = ", ".join(envs.OBS_KEYS)
    if not isinstance(observe, str) and not (
        isinstance(observe, Sequence) and all(isinstance(k, str) for k in observe)
    ):
        raise TypeError(f"observe must be one of {names}, or a list of them; got {observe!r}")
    keys = (observe,) if isinstance(observe, str) else tuple(observe)
    for key in keys:
        envs.choose("observation key", key, dict.fromkeys(envs.OBS_KEYS))
    if not keys or len(set(keys)) != len(keys):
        raise ValueError(
            f"observe={observe!r}: name each of {', '.join(envs.OBS_KEYS)} at most once, at least "
            "one"
        )
    if "hint" in keys and not hint.dim:
        raise ValueError(
            f"observe={observe!r} asks for the hint, but hint='{hint.name}' has none; "
            f"valid hints: {', '.join(envs.hint_names(hint.env))}"
        )
    return keys, not isinstance(observe, str)


@dataclass(frozen=True)
class Programs:
    """One configured env and its jitted pieces, shared by every Gymnasium env made with the same
    settings (so a second `make` compiles nothing). Keys are uint32[2] (batched: [N, 2])."""

    env: envs.Env
    split: Callable  # key -> (next key, key to use)
    reset: Callable  # the env's own reset, jitted: (key, params) -> Timestep
    step: Callable  # the env's own step, jitted: (key, state, action, params) -> Timestep
    picture: Callable  # the env's own render, jitted: (state, params) -> uint8[S, S, 3]
    # (keys [N, 2], params) -> (keys, states, obs): split, then reset, per env
    vector_reset: Callable
    # (keys, states, actions [N, A], params) -> (keys, states, obs, reward [N],
    vector_step: Callable
    #   terminated [N], truncated [N], final_obs): split, then step, per env; SAME_STEP autoreset


def _split(key: jax.Array) -> tuple[jax.Array, jax.Array]:
    next_key, sub = jax.random.split(key)
    return next_key, sub


@lru_cache(maxsize=None)
def programs(
    name: str, hint: str, observe: tuple[str, ...], image_size: int | None, physics: str
) -> Programs:
    """The env `name` with `hint`, observing `observe`, and its jitted reset and step (one env: the
    env's own, so the single env runs hintsjax's programs as they are; N envs: vmapped, in one
    call), cached by these settings."""
    env = envs.make(name, hint=hint, observe=observe, physics=physics, image_size=image_size)

    def reset(key, params):
        key, sub = _split(key)
        ts = env.reset(sub, params)
        return key, ts.state, ts.obs

    def step(key, state, action, params):
        key, sub = _split(key)
        ts = env.step(sub, state, action, params)
        return key, ts.state, ts.obs, ts.reward, ts.terminated, ts.truncated

    def vector_step(keys, states, actions, params):
        keys, states, obs, reward, terminated, truncated = jax.vmap(step, (0, 0, 0, None))(
            keys, states, actions, params
        )
        done = terminated | truncated

        def restart(keys, states, obs):
            # only where some episode ended: a vmapped reset costs a picture per env
            fresh_keys, fresh_states, fresh_obs = jax.vmap(reset, (0, None))(keys, params)
            pick = lambda a, b: jax.tree.map(  # noqa: E731
                lambda x, y: jnp.where(done.reshape(done.shape + (1,) * (x.ndim - 1)), x, y), a, b
            )
            return pick(fresh_keys, keys), pick(fresh_states, states), pick(fresh_obs, obs)

        next_keys, next_states, next_obs = jax.lax.cond(
            done.any(), restart, lambda *a: a, keys, states, obs
        )
        return next_keys, next_states, next_obs, reward, terminated, truncated, obs

    return Programs(
        env,
        jax.jit(_split),
        jax.jit(env.reset),
        jax.jit(env.step),
        jax.jit(env.render),
        jax.jit(jax.vmap(reset, (0, None))),
        jax.jit(vector_step),
    )


class _Settings:
    """What both Gymnasium envs resolve from their arguments: the programs, params, spaces."""

    def __init__(
        self,
        env: str,
        hint: str | None,
        variant: str | None,
        observe: str | Sequence[str] | None,
        image_size: int | None,
        physics: str,
    ):
        self.name = env
        if hint is not None and not isinstance(hint, str):
            raise TypeError(f"hint must be a name or names joined by '+', got {hint!r}")
        if image_size is not None and not _whole(image_size):  # never rounded
            raise TypeError(f"image_size must be an int (pixels a side), got {image_size!r}")
        self.hint = default_hint(env) if hint is None else hint
        resolved = envs.make_hint(env, self.hint)
        self.keys, self.as_dict = _observe(observe, resolved)
        self.variant = variant if variant is not None else envs.variant_names(env)[0]
        self.params = envs.make_params(env, self.variant)
        self.programs = programs(env, self.hint, self.keys, image_size, physics)
        made = self.programs.env
        side = made.image_size
        boxes = {  # made only for the keys observed: the state's width is traced (Env.state_size)
            "pixels": lambda: spaces.Box(0, 255, (side, side, 3), np.uint8),
            "state": lambda: spaces.Box(-np.inf, np.inf, (made.state_size,), np.float32),
            "hint": lambda: spaces.Box(-np.inf, np.inf, (resolved.dim,), np.float32),
        }
        self.observation_space = (
            spaces.Dict({k: boxes[k]() for k in self.keys})
            if self.as_dict
            else boxes[self.keys[0]]()
        )
        low, high = (np.asarray(x, np.float32) for x in made.action_range(self.params))
        self.action_space = spaces.Box(low, high, (made.action_size,), np.float32)

    def to_numpy(self, obs: dict[str, np.ndarray]) -> Any:
        """A hintsjax observation (host arrays) as the observation space holds it."""
        return {k: obs[k] for k in self.keys} if self.as_dict else obs[self.keys[0]]


def _host(tree: Any) -> Any:
    """`tree`'s arrays on the host, in one transfer, as writable NumPy arrays (a CPU array comes
    back as a read-only view of JAX's buffer, which a learner that edits observations cannot
    use)."""
    return jax.tree.map(lambda x: x if x.flags.writeable else x.copy(), jax.device_get(tree))


def _seeds(seed: int | Sequence[int] | None, num_envs: int) -> list[int] | None:
    """Each env's seed: s + i for a seed s, a list as given (one per env), None for none;
    TypeError for anything else (a string, a float: never read digit by digit or rounded)."""
    if seed is None:
        return None
    if _whole(seed):
        seeds = [int(seed) + i for i in range(num_envs)]
    elif isinstance(seed, Sequence) and not isinstance(seed, str) and all(map(_whole, seed)):
        seeds = [int(s) for s in seed]
    else:
        raise TypeError(f"seed must be an int or a list of {num_envs} ints, got {seed!r}")
    if len(seeds) != num_envs or min(seeds) < 0:
        raise ValueError(f"seed={seed!r}: give one non-negative int, or a list of {num_envs}")
    return seeds


def _whole(value: Any) -> bool:
    """An int as Gymnasium takes one (NumPy's too), not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def _finite(actions: np.ndarray) -> np.ndarray:
    """`actions` (float32), or ValueError naming the first env whose action is NaN or infinite:
    the physics would carry it on silently (NaN states, hints and rewards, black pictures)."""
    bad = ~np.isfinite(actions.reshape(actions.shape[0], -1)).all(axis=1)
    if bad.any():
        raise ValueError(
            f"actions must be finite numbers; env {int(np.flatnonzero(bad)[0])} got "
            f"{actions[int(np.flatnonzero(bad)[0])].tolist()}"
        )
    return actions


def _check_fits(settings: _Settings, num_envs: int) -> None:
    """ValueError naming num_envs when its pictures alone (uint8, and the float32 the renderer
    draws them in) pass the device's memory: found before anything is allocated."""
    side = settings.programs.env.image_size if "pixels" in settings.keys else 0
    need = num_envs * side * side * 3 * (1 + 4)
    device = jax.local_devices()[0]
    stats = device.memory_stats() if device.platform != "cpu" else None
    have = (
        int(stats["bytes_limit"])
        if stats and "bytes_limit" in stats
        else os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")
    )
    if need > have:
        most = have // max(side * side * 3 * 5, 1)
        raise ValueError(
            f"num_envs={num_envs} cannot fit: its pictures alone need {need / 2**30:.1f} GiB, a "
            f"device has {have / 2**30:.1f} GiB; at most about {most} envs"
        )


def _no_options(options: dict[str, Any] | None) -> None:
    if options:
        raise ValueError(
            f"reset options {sorted(options)} are not supported: hintsjax's envs take none"
        )


class VectorEnv(gymnasium.vector.VectorEnv):
    """`num_envs` copies of hintsjax env `env`, stepped by one jitted, vmapped call (on the device
    JAX picks) with one transfer to NumPy a step. Observations: a Dict of `pixels` (uint8[N, S, S,
    3]) and `hint` (float32[N, d]) by default, `observe=` any of pixels, state and hint (one name as
    a string: that array alone); actions float32[N, A] in the env's own range. Autoreset SAME_STEP.

    `gymnasium.make_vec("hintsjax/<env>-v0", num_envs, hint=, variant=, observe=, image_size=,
    physics=)` makes one (`import hintsjax.gym` registers the ids); unknown names raise ChoiceError,
    one line naming the valid ones.
    """

    metadata = {"autoreset_mode": AutoresetMode.SAME_STEP, "render_modes": []}

    def __init__(
        self,
        env: str,
        num_envs: int = 1,
        hint: str | None = None,
        variant: str | None = None,
        observe: str | Sequence[str] | None = None,
        image_size: int | None = None,
        physics: str = envs.AUTO,
    ):
        if not _whole(num_envs):
            raise TypeError(f"num_envs must be an int, got {num_envs!r}")
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        self.settings = _Settings(env, hint, variant, observe, image_size, physics)
        _check_fits(self.settings, int(num_envs))
        self.num_envs = int(num_envs)
        self.single_observation_space = self.settings.observation_space
        self.single_action_space = self.settings.action_space
        self.observation_space = batch_space(self.single_observation_space, self.num_envs)
        self.action_space = batch_space(self.single_action_space, self.num_envs)
        self.metadata = dict(
            self.metadata, env=env, hint=self.settings.hint, variant=self.settings.variant
        )
        self._keys = self._states = None

    def reset(
        self, *, seed: int | Sequence[int] | None = None, options: dict[str, Any] | None = None
    ):
        """obs of N fresh episodes, {}; seed s (or a list of N seeds) seeds env i with s + i."""
        _no_options(options)
        super().reset(seed=seed if isinstance(seed, (int, np.integer)) or seed is None else None)
        seeds = _seeds(seed, self.num_envs)
        if seeds is None and self._keys is None:
            seeds = [int(s) for s in self.np_random.integers(0, 2**63, self.num_envs)]
        keys = (
            jnp.asarray(np.stack([seed_key(s) for s in seeds])) if seeds is not None else self._keys
        )
        self._keys, self._states, obs = self.settings.programs.vector_reset(
            keys, self.settings.params
        )
        return self.settings.to_numpy(_host(obs)), {}

    def step(self, actions):
        """(obs, reward float64[N], terminated bool[N], truncated bool[N], info); where an episode
        ended, info['final_obs'][i] is its last observation (`_final_obs` marks which)."""
        if self._keys is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        actions = _finite(np.asarray(actions, np.float32).reshape(self.action_space.shape))
        actions = jnp.asarray(actions)
        self._keys, self._states, *out = self.settings.programs.vector_step(
            self._keys, self._states, actions, self.settings.params
        )
        obs, reward, terminated, truncated, final_obs = _host(out)  # the one transfer
        done = terminated | truncated
        info: dict[str, Any] = {}
        if done.any():
            final = np.full(self.num_envs, None, dtype=object)
            for i in np.flatnonzero(done):
                final[i] = self.settings.to_numpy({k: v[i] for k, v in final_obs.items()})
            info = {
                "final_obs": final,
                "_final_obs": done,
                "final_info": {},
                "_final_info": done.copy(),
            }
        return (
            self.settings.to_numpy(obs),
            reward.astype(np.float64),
            terminated.astype(bool),
            truncated.astype(bool),
            info,
        )


class SingleEnv(gymnasium.Env):
    """One hintsjax env as a `gymnasium.Env` (`gymnasium.make("hintsjax/<env>-v0", ...)`): the
    vector env's spaces without the batch axis, no autoreset (reset after terminated or truncated),
    and `render_mode="rgb_array"` returning the env's picture (uint8[S, S, 3])."""

    metadata = {"render_modes": ["rgb_array"], "render_fps": 30}

    def __init__(
        self,
        env: str,
        hint: str | None = None,
        variant: str | None = None,
        observe: str | Sequence[str] | None = None,
        image_size: int | None = None,
        physics: str = envs.AUTO,
        render_mode: str | None = None,
    ):
        if render_mode not in (None, "rgb_array"):
            raise ChoiceError("render_mode", str(render_mode), ["rgb_array"])
        self.settings = _Settings(env, hint, variant, observe, image_size, physics)
        self.observation_space = self.settings.observation_space
        self.action_space = self.settings.action_space
        self.render_mode = render_mode
        self._key = self._state = None

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        """(obs, {}) of a fresh episode; a seed restarts the env's random stream, None goes on with
        it."""
        _no_options(options)
        super().reset(seed=seed)
        if seed is None and self._key is None:
            seed = int(self.np_random.integers(0, 2**63))
        key = jnp.asarray(seed_key(seed)) if seed is not None else self._key
        self._key, sub = self.settings.programs.split(key)
        ts = self.settings.programs.reset(sub, self.settings.params)
        self._state = ts.state
        return self.settings.to_numpy(_host(ts.obs)), {}

    def step(self, action):
        """(obs, reward, terminated, truncated, {}) after `action` (float32[A]; clipped by the
        env)."""
        if self._key is None:
            raise gymnasium.error.ResetNeeded("call reset() before step()")
        action = np.asarray(action, np.float32).reshape(self.action_space.shape)
        action = jnp.asarray(_finite(action[None])[0])
        self._key, sub = self.settings.programs.split(self._key)
        ts = self.settings.programs.step(sub, self._state, action, self.settings.params)
        self._state = ts.state
        obs, reward, terminated, truncated = _host((ts.obs, ts.reward, ts.terminated, ts.truncated))
        return self.settings.to_numpy(obs), float(reward), bool(terminated), bool(truncated), {}

    def render(self):
        """uint8[S, S, 3] picture of the current state (render_mode="rgb_array"), else None."""
        if self.render_mode is None or self._state is None:
            return None
        return np.array(self.settings.programs.picture(self._state, self.settings.params))
