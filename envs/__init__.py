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

import contextlib
import io

with contextlib.redirect_stdout(io.StringIO()):  # mjx prints a notice when its optional warp backend is absent
    from mujoco import mjx  # noqa: F401

from hintsjax.envs import acrobot, ant, car_racing, halfcheetah, humanoid, idp, pendulum  # noqa: E402
from hintsjax.envs.core import OBS_KEYS, AutoReset, Env, SquashedActions, Step, Timestep
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.envs.hints import NO_HINT, Hint, hint_names, make_hint, register_composite, register_hint


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


def make(name: str, hint: str = NO_HINT, observe: tuple[str, ...] = OBS_KEYS) -> Env:
    """The env `name` observing `observe`, with hint `hint` (see `hints.make_hint`)."""
    entry = choose("env", name, REGISTRY)
    return entry.cls(make_hint(name, hint), observe)


def variant_names(name: str) -> list[str]:
    return list(choose("env", name, REGISTRY).variants)


def make_params(name: str, variant: str | None = None) -> Any:
    """The params pytree of `name`'s variant (its default variant if None)."""
    variants = choose("env", name, REGISTRY).variants
    return variants[next(iter(variants))] if variant is None else choose("variant", variant, variants, name)


__all__ = [
    "OBS_KEYS", "AutoReset", "ChoiceError", "Env", "EnvEntry", "Hint", "NO_HINT", "REGISTRY", "SquashedActions", "Step",
    "Timestep", "choose", "env_names", "hint_names", "make", "make_hint", "make_params",
    "register_composite", "register_hint", "variant_names",
]
