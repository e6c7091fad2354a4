"""The hint registry: a hint is a pure function `(env_state, env_params) -> float32[d]`.

Each env module registers its hints with `register_hint` beside its dynamics; a composite is
a registered list of other hints' names. Any `+`-joined list of registered names is a hint
too, so `make_hint("pendulum", "angular_velocity+goal_distance")` needs no new code.

To add a hint of your own, write the function and register it:

    @register_hint("pendulum", "height", dim=1, unit="m")
    def height(state, params):
        return jnp.cos(state.theta)[None]

A file (or module) of such registrations is loaded without editing hintsjax by `load_hints`
(`python -m hintsjax.run hints_from=my_hints.py hint=height`); `check_hint_shapes` then checks
that each hint returns the width it was registered with.
"""

from __future__ import annotations

import hashlib
import importlib
import importlib.util
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import jax
import jax.numpy as jnp

from hintsjax.envs.errors import ChoiceError, choose

HintFn = Callable[[Any, Any], jax.Array]


@dataclass(frozen=True)
class HintSpec:
    """One registered hint: its function, width and unit."""

    name: str
    fn: HintFn
    dim: int
    unit: str
    doc: str = ""


_HINTS: dict[str, dict[str, HintSpec]] = {}
_COMPOSITES: dict[str, dict[str, tuple[str, ...]]] = {}


def register_hint(env: str, name: str, dim: int, unit: str) -> Callable[[HintFn], HintFn]:
    """Decorator: register `fn(state, params) -> float32[dim]` as hint `name` of `env`."""

    def wrap(fn: HintFn) -> HintFn:
        doc = (fn.__doc__ or "").strip().splitlines()[0] if fn.__doc__ else ""
        _HINTS.setdefault(env, {})[name] = HintSpec(name, fn, dim, unit, doc)
        return fn

    return wrap


def register_composite(env: str, name: str, parts: tuple[str, ...]) -> None:
    """Register `name` as the concatenation of already registered hints `parts`."""
    for part in parts:
        choose("hint", part, _HINTS.get(env, {}), where=env)
    _COMPOSITES.setdefault(env, {})[name] = tuple(parts)


def share_hints(env: str, source: str) -> None:
    """Give `env` the hints and composites of `source`, now and as `source` gains more (an env
    that is a variant of another's physics, such as `ant_fast` of `ant`)."""
    _HINTS[env] = _HINTS.setdefault(source, {})
    _COMPOSITES[env] = _COMPOSITES.setdefault(source, {})


def register_link_velocity_hints(env: str, link_velocities: Callable[[Any], jax.Array]) -> None:
    """The hints that acrobot and idp share (SPEC section 3), from `link_velocities(state)`, the
    float32[2] speeds (rad/s) of the two hinges, the second relative to the first:
    `angular_velocity_1`, `angular_velocity_2`, `joint` (their sum, the second link's absolute
    angular velocity) and `composite` = [angular_velocity_1, angular_velocity_2]."""

    def angular_velocity_1(state, params):
        """The first hinge's angular velocity."""
        return link_velocities(state)[0]

    def angular_velocity_2(state, params):
        """The second hinge's angular velocity, relative to the first link."""
        return link_velocities(state)[1]

    def joint(state, params):
        """The sum of both: the second link's absolute angular velocity."""
        return link_velocities(state).sum()

    for fn in (angular_velocity_1, angular_velocity_2, joint):
        register_hint(env, fn.__name__, dim=1, unit="rad/s")(fn)
    register_composite(env, "composite", ("angular_velocity_1", "angular_velocity_2"))


def hint_names(env: str) -> list[str]:
    """Every hint name registered for `env`, composites included."""
    return sorted({*_HINTS.get(env, {}), *_COMPOSITES.get(env, {})})


@dataclass(frozen=True)
class Hint:
    """A resolved hint: the concatenation of registered hints, callable as a pure function."""

    env: str
    name: str
    parts: tuple[HintSpec, ...]

    @property
    def dim(self) -> int:
        return sum(p.dim for p in self.parts)

    @property
    def units(self) -> dict[str, str]:
        return {p.name: p.unit for p in self.parts}

    def __call__(self, state: Any, params: Any) -> jax.Array:
        """float32[dim] hint of one (unbatched) state."""
        if not self.parts:
            return jnp.zeros((0,), jnp.float32)
        return jnp.concatenate(
            [jnp.asarray(p.fn(state, params), jnp.float32).reshape(p.dim) for p in self.parts]
        )


NO_HINT = "none"


def side_by_side(env: str, specs: list[str]) -> tuple[str, list[tuple[int, ...]]]:
    """One hint holding every part of the hints `specs` once, side by side in order of first
    appearance (NO_HINT if none has a part), and per spec the positions of its parts in it: how
    an env computes several hints at once (a group's members, a ranking's candidates)."""
    hints = [make_hint(env, spec) for spec in specs]
    parts: list[HintSpec] = []
    for hint in hints:
        parts += [p for p in hint.parts if p not in parts]
    offsets, at = {}, 0
    for p in parts:
        offsets[p.name], at = range(at, at + p.dim), at + p.dim
    takes = [tuple(i for p in hint.parts for i in offsets[p.name]) for hint in hints]
    return "+".join(p.name for p in parts) or NO_HINT, takes


def make_hint(env: str, spec: str) -> Hint:
    """Resolve `spec` (a registered name, a composite, or names joined by '+') for `env`."""
    if spec == NO_HINT:
        return Hint(env, spec, ())
    names: list[str] = []
    for token in spec.split("+"):
        token = token.strip()
        if token in _COMPOSITES.get(env, {}):
            names.extend(_COMPOSITES[env][token])
        elif token in _HINTS.get(env, {}):
            names.append(token)
        else:
            raise ChoiceError("hint", token, hint_names(env), where=f"env '{env}'")
    return Hint(env, spec, tuple(_HINTS[env][n] for n in names))


class HintFileError(ValueError):
    """A hint file that does not import, or a hint that returns another width than it registered."""


def load_hints(source: str) -> str:
    """Import `source`, a Python file (`*.py`, a path) or an importable module's dotted name, whose
    `register_hint` calls add hints; once per file in a process. Its module name (a file's is
    `hintsjax_hints_<digest of its path>`); HintFileError in one line when it cannot be imported."""
    path = Path(source).expanduser()
    try:
        if source.endswith(".py") or path.exists():
            if not path.is_file():
                raise HintFileError(f"hints_from={source}: no such file")
            path = path.resolve()
            name = f"hintsjax_hints_{hashlib.sha256(str(path).encode()).hexdigest()[:12]}"
            if name not in sys.modules:
                spec = importlib.util.spec_from_file_location(name, path)
                module = importlib.util.module_from_spec(spec)
                # first: what it registers is named after it (program_cache digests it)
                sys.modules[name] = module
                try:
                    spec.loader.exec_module(module)
                except BaseException:
                    del sys.modules[name]
                    raise
            return name
        importlib.import_module(source)
        return source
    except HintFileError:
        raise
    except (Exception, SystemExit) as e:  # noqa: BLE001  whatever the user's file raised, in one line
        what = (
            f"{type(e).__name__}: {str(e).strip().splitlines()[0][:200]}"
            if str(e).strip()
            else type(e).__name__
        )
        raise HintFileError(f"hints_from={source} does not import ({what})") from None


def check_hint_shapes(hint: Hint, state: Any, params: Any) -> None:
    """HintFileError naming the first part of `hint` whose function, given `state` (one env's
    state; abstract shapes are enough), returns another number of values than its registered dim."""
    for part in hint.parts:
        try:
            out = jax.eval_shape(part.fn, state, params)
        except Exception as e:  # noqa: BLE001  the user's function fails to trace: one line naming it
            raise HintFileError(
                f"hint '{part.name}' of {hint.env} fails on the env's state ({type(e).__name__}: "
                f"{str(e).strip().splitlines()[0][:160] if str(e).strip() else ''})"
            ) from None
        shape = getattr(out, "shape", None)
        if shape is None or len(shape) > 1 or (shape[0] if shape else 1) != part.dim:
            raise HintFileError(
                f"hint '{part.name}' of {hint.env} returns shape {shape}, not the ({part.dim},) it "
                f"was registered with (dim={part.dim})"
            )
