"""hintsjax.envs: pure-JAX environments whose pictures and hints are computed in the graph.

    from hintsjax import envs
    env = envs.make("pendulum", hint="composite")
    params = envs.make_params("pendulum", variant="swingto")
    ts = env.reset(key, params)

A new env is one module (dynamics, reward, picture, hints and training defaults beside each
other) plus one line in `REGISTRY`.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from hintsjax.envs import physics as _physics  # first: imports mujoco.mjx without its Warp backend (envs/physics.py)
from hintsjax.envs import acrobot, ant, car_racing, halfcheetah, humanoid, idp, pendulum  # noqa: E402
from hintsjax.envs.core import OBS_KEYS, AutoReset, Env, SquashedActions, Step, Timestep
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.envs.hints import NO_HINT, Hint, hint_names, make_hint, register_composite, register_hint
from hintsjax.envs.mjx_env import MjxEnv
from hintsjax.envs.physics import AUTO, DEFAULT_CAPACITY, JAX, WARP, PhysicsUnavailable


@dataclass(frozen=True)
class EnvEntry:
    """A registered env: its class, its named params variants (the first is the default) and its
    training defaults (`TRAINING` beside the env; hintsjax/env_defaults.py reads them)."""

    cls: type[Env]
    variants: dict[str, Any]
    training: dict[str, Any] = field(default_factory=dict)


REGISTRY: dict[str, EnvEntry] = {
    "pendulum": EnvEntry(pendulum.Pendulum, pendulum.VARIANTS, pendulum.TRAINING),
    "acrobot": EnvEntry(acrobot.Acrobot, acrobot.VARIANTS, acrobot.TRAINING),
    "idp": EnvEntry(idp.InvertedDoublePendulum, idp.VARIANTS, idp.TRAINING),
    "ant": EnvEntry(ant.Ant, ant.VARIANTS, ant.TRAINING),
    "ant_fast": EnvEntry(ant.AntFast, ant.VARIANTS, ant.FAST_TRAINING),
    "halfcheetah": EnvEntry(halfcheetah.HalfCheetah, halfcheetah.VARIANTS, halfcheetah.TRAINING),
    "humanoid": EnvEntry(humanoid.Humanoid, humanoid.VARIANTS, humanoid.TRAINING),
    "car_racing": EnvEntry(car_racing.CarRacing, car_racing.VARIANTS, car_racing.TRAINING),
}


def env_names() -> list[str]:
    return sorted(REGISTRY)


def make(name: str, hint: str = NO_HINT, observe: tuple[str, ...] = OBS_KEYS, physics: str = AUTO,
         warp_capacity: float = DEFAULT_CAPACITY) -> Env:
    """The env `name` observing `observe`, with hint `hint` (see `hints.make_hint`); an MJX env
    stepped by `physics` (`resolve_physics`; Warp's buffers `warp_capacity` times the model's
    most contacts per world)."""
    entry = choose("env", name, REGISTRY)
    impl = resolve_physics(name, physics)
    if issubclass(entry.cls, MjxEnv):
        return entry.cls(make_hint(name, hint), observe, impl, warp_capacity)
    return entry.cls(make_hint(name, hint), observe)


def mjx_env_names() -> list[str]:
    """The envs whose physics is a MuJoCo model (stepped by MJX's JAX solver or MJX-Warp)."""
    return [name for name in env_names() if issubclass(REGISTRY[name].cls, MjxEnv)]


def resolve_physics(name: str, physics: str = AUTO) -> str:
    """`jax` or `warp`: what `physics` (auto, jax or warp) steps env `name` with on this
    platform (envs/physics.py `resolve`). ChoiceError for an unknown value; PhysicsUnavailable
    for warp where it cannot run, or for an env with no MuJoCo model."""
    import jax

    cls = choose("env", name, REGISTRY).cls
    if not issubclass(cls, MjxEnv):
        choose("physics", physics, dict.fromkeys(_physics.CHOICES))
        if physics == WARP:
            raise PhysicsUnavailable(f"{name} has no MuJoCo model; physics=warp is for {', '.join(mjx_env_names())}")
        return JAX
    return _physics.resolve(physics, jax.default_backend(), cls.warp_by_default)


def variant_names(name: str) -> list[str]:
    return list(choose("env", name, REGISTRY).variants)


def make_params(name: str, variant: str | None = None) -> Any:
    """The params pytree of `name`'s variant (its default variant if None)."""
    variants = choose("env", name, REGISTRY).variants
    return variants[next(iter(variants))] if variant is None else choose("variant", variant, variants, name)


__all__ = [
    "AUTO", "DEFAULT_CAPACITY", "JAX", "OBS_KEYS", "WARP", "AutoReset", "ChoiceError", "Env", "EnvEntry", "Hint", "MjxEnv",
    "NO_HINT", "PhysicsUnavailable", "REGISTRY", "SquashedActions", "Step", "Timestep", "choose", "env_names", "hint_names",
    "make", "make_hint", "make_params", "mjx_env_names", "register_composite", "register_hint", "resolve_physics",
    "variant_names",
]
