"""hintsjax.envs: pure-JAX environments whose pictures and hints are computed in the graph.

    from hintsjax import envs
    env = envs.make("pendulum", hint="composite")
    params = envs.make_params("pendulum", variant="swingto")
    ts = env.reset(key, params)

A new env is one module (dynamics, reward, picture, hints and training defaults beside each
other) plus one line in `REGISTRY`. A task of MuJoCo Playground or Brax is an env with no module:
`make("playground:CartpoleSwingup")` or `make("brax:hopper")` adapts it (envs/adapter.py,
`ADAPTERS`; docs/playground.md).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable

import jax

# first: imports mujoco.mjx without its Warp backend (envs/physics.py)
from hintsjax.envs import physics as _physics
from hintsjax.envs import acrobot, adapter, ant, car_racing, halfcheetah, humanoid, idp, pendulum  # noqa: E402
from hintsjax.envs.adapter import EnvUnavailable
from hintsjax.envs.core import (
    OBS_KEYS,
    AutoReset,
    Env,
    SquashedActions,
    Step,
    Timestep,
    fresh_episodes,
    rows_where,
)
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.envs.hints import (
    NO_HINT,
    Hint,
    HintFileError,
    check_hint_shapes,
    hint_names,
    load_hints,
    make_hint,
    register_composite,
    register_hint,
)
from hintsjax.envs.mjx_env import MjxEnv
from hintsjax.envs.physics import AUTO, DEFAULT_CAPACITY, JAX, WARP, PhysicsUnavailable


@dataclass(frozen=True)
class EnvEntry:
    """A registered env: its class, its named params variants (the first is the default), its
    training defaults (`TRAINING` beside the env; hintsjax/settings/env_defaults.py reads them) and
    what its constructor takes besides the hint and the observation (an adapted env's task)."""

    cls: type[Env]
    variants: dict[str, Any]
    training: dict[str, Any] = field(default_factory=dict)
    options: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Adapter:
    """A source of tasks that `<source>:<task>` names: how it loads a task (envs/adapter.py's
    `Task`; ChoiceError naming its tasks for an unknown one) and a task's training defaults, and
    the hints it gives the tasks it knows (beside the generic ones every adapted env has)."""

    load: Callable[[str], adapter.Task]
    training: Callable[[str], dict[str, Any]]
    hints: Callable[[adapter.Task], None] = lambda task: None


def _playground() -> Adapter:
    # imports only mujoco here; Playground itself when a task is loaded
    from hintsjax.envs import playground

    return Adapter(playground.load, playground.training, playground.register_task_hints)


def _brax() -> Adapter:
    try:  # imports brax only when a brax: env is asked for
        from hintsjax.envs import brax_env
    except ImportError as e:  # a pinned dependency that does not import here: the machine's set-up
        raise adapter.EnvUnavailable(
            f"env=brax:<name> needs Brax, which does not import here ({type(e).__name__}: {e}); "
            "reinstall the project's pins: pip install -e ."
        ) from None
    return Adapter(brax_env.load, brax_env.training)


ADAPTERS: dict[str, Callable[[], Adapter]] = {"playground": _playground, "brax": _brax}


class EnvRegistry(dict):
    """The envs by name: the suite's own, and any `<source>:<task>` of `ADAPTERS`, loaded, given its
    hints and added on its first look-up (`in`, `[]`, `get`); iterating lists those added so far."""

    def __contains__(self, name: object) -> bool:
        return dict.__contains__(self, name) or self._adapt(name)

    def __missing__(self, name: str) -> EnvEntry:
        if self._adapt(name):
            return dict.__getitem__(self, name)
        raise KeyError(name)

    def get(self, name: str, default: Any = None) -> Any:
        return self[name] if name in self else default

    def keys(self) -> list[str]:
        """The names an unknown env's error lists: those added so far and each source's pattern."""
        return [*dict.keys(self), *(f"{source}:<name>" for source in ADAPTERS)]

    def _adapt(self, name: object) -> bool:
        """Whether `name` is `<source>:<task>` (then added); ChoiceError for an unknown source or
        task, adapter.EnvUnavailable for a task that cannot be made here."""
        source, colon, task = str(name).partition(":")
        if not colon:
            return False
        made = choose("env source", source, ADAPTERS, where=f"env '{name}'")()
        loaded = made.load(task)
        adapter.register_generic_hints(loaded)
        made.hints(loaded)
        self[str(name)] = EnvEntry(
            adapter.AdaptedEnv, adapter.variants(loaded), made.training(task), {"task": loaded}
        )
        return True


REGISTRY: EnvRegistry = EnvRegistry(
    {
        "pendulum": EnvEntry(pendulum.Pendulum, pendulum.VARIANTS, pendulum.TRAINING),
        "acrobot": EnvEntry(acrobot.Acrobot, acrobot.VARIANTS, acrobot.TRAINING),
        "idp": EnvEntry(idp.InvertedDoublePendulum, idp.VARIANTS, idp.TRAINING),
        "ant": EnvEntry(ant.Ant, ant.VARIANTS, ant.TRAINING),
        "ant_fast": EnvEntry(ant.AntFast, ant.VARIANTS, ant.FAST_TRAINING),
        "halfcheetah": EnvEntry(
            halfcheetah.HalfCheetah, halfcheetah.VARIANTS, halfcheetah.TRAINING
        ),
        "humanoid": EnvEntry(humanoid.Humanoid, humanoid.VARIANTS, humanoid.TRAINING),
        "car_racing": EnvEntry(car_racing.CarRacing, car_racing.VARIANTS, car_racing.TRAINING),
    }
)


def env_names() -> list[str]:
    return sorted(REGISTRY)


def make(
    name: str,
    hint: str = NO_HINT,
    observe: tuple[str, ...] = OBS_KEYS,
    physics: str = AUTO,
    warp_capacity: float = DEFAULT_CAPACITY,
    image_size: int | None = None,
) -> Env:
    """The env `name` observing `observe`, with hint `hint` (see `hints.make_hint`); an MJX env
    stepped by `physics` (`resolve_physics`; Warp's buffers `warp_capacity` times the model's
    most contacts per world); its pictures `image_size` pixels a side (None: the env's own)."""
    entry = choose("env", name, REGISTRY)
    impl = resolve_physics(name, physics)
    if issubclass(entry.cls, MjxEnv):
        return entry.cls(make_hint(name, hint), observe, impl, warp_capacity, image_size)
    return entry.cls(make_hint(name, hint), observe, image_size, **entry.options)


def check_drawable(name: str) -> None:
    """adapter.EnvUnavailable naming the first geom of an adapted env's model that its picture
    cannot draw (a mesh, a height field); nothing for the suite's envs, which all draw."""
    entry = choose("env", name, REGISTRY)
    if "task" in entry.options:
        adapter.make_scene(entry.options["task"])


def mjx_env_names() -> list[str]:
    """The envs whose physics is a MuJoCo model (stepped by MJX's JAX solver or MJX-Warp)."""
    return [name for name in env_names() if issubclass(REGISTRY[name].cls, MjxEnv)]


def resolve_physics(name: str, physics: str = AUTO) -> str:
    """`jax` or `warp`: what `physics` (auto, jax or warp) steps env `name` with on this
    platform (envs/physics.py `resolve`). ChoiceError for an unknown value; PhysicsUnavailable
    for warp where it cannot run, or for an env with no MuJoCo model."""
    cls = choose("env", name, REGISTRY).cls
    if not issubclass(cls, MjxEnv):
        choose("physics", physics, dict.fromkeys(_physics.CHOICES))
        if physics == WARP and cls is adapter.AdaptedEnv:
            raise PhysicsUnavailable(
                f"{name} steps with its own MJX physics (JAX); physics=warp is for "
                f"{', '.join(mjx_env_names())}"
            )
        if physics == WARP:
            raise PhysicsUnavailable(
                f"{name} has no MuJoCo model; physics=warp is for {', '.join(mjx_env_names())}"
            )
        return JAX
    return _physics.resolve(physics, jax.default_backend(), cls.warp_by_default, jax.device_count())


def likely_warp(name: str, physics: str) -> bool:
    """Whether `physics` (warp, or auto as `auto_likely_warp` reads it) steps env `name` with
    MJX-Warp on this machine, read without starting JAX: what a command, a sweep's worker and the
    bench decide their XLA flags by."""
    return physics == WARP or (physics == AUTO and auto_likely_warp(name))


def auto_likely_warp(name: str) -> bool:
    """Whether physics=auto will step env `name` with MJX-Warp on this machine, read without
    starting JAX (`gpu_likely`): what a command decides its XLA flags by. An adapted env
    (`source:name`) or an unknown name: False, without looking it up (its check says what is
    wrong)."""
    if ":" in name or name not in env_names():
        return False
    cls = REGISTRY[name].cls
    return (
        issubclass(cls, MjxEnv)
        and cls.warp_by_default
        and _physics.warp_installed()
        and _physics.gpu_likely()
    )


def variant_names(name: str) -> list[str]:
    return list(choose("env", name, REGISTRY).variants)


def make_params(name: str, variant: str | None = None) -> Any:
    """The params pytree of `name`'s variant (its default variant if None)."""
    variants = choose("env", name, REGISTRY).variants
    return (
        variants[next(iter(variants))]
        if variant is None
        else choose("variant", variant, variants, name)
    )


__all__ = [
    "ADAPTERS",
    "AUTO",
    "DEFAULT_CAPACITY",
    "JAX",
    "OBS_KEYS",
    "WARP",
    "Adapter",
    "AutoReset",
    "ChoiceError",
    "Env",
    "EnvEntry",
    "EnvRegistry",
    "EnvUnavailable",
    "Hint",
    "HintFileError",
    "MjxEnv",
    "NO_HINT",
    "PhysicsUnavailable",
    "REGISTRY",
    "check_drawable",
    "check_hint_shapes",
    "load_hints",
    "SquashedActions",
    "Step",
    "Timestep",
    "choose",
    "env_names",
    "fresh_episodes",
    "rows_where",
    "hint_names",
    "make",
    "make_hint",
    "make_params",
    "mjx_env_names",
    "register_composite",
    "register_hint",
    "resolve_physics",
    "variant_names",
]
