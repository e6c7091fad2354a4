"""A setting declared once: `setting(...)` is a dataclass field that carries what the rest of the
package reads off it (its help line, whether it is a traced number, whether older saved runs may
lack it, its choices), so that PPO's `Hyper`, a group's shape list, the command line's schema,
`--help`, docs/settings.md and the loading of older run folders all follow from the fields, as
CleanRL documents each `Args` field in place and rejax marks `pytree_node` on it.
"""

from __future__ import annotations

import dataclasses
from typing import Any

from hintsjax.system.errors import UsageError

HELP, TRACED, SAVED_MAY_LACK, CHOICES, PER_ENV = (
    "help",
    "traced",
    "saved_may_lack",
    "choices",
    "per_env",
)


def setting(
    default: Any = dataclasses.MISSING,
    help: str = "",
    *,
    traced: bool = False,
    saved_may_lack: bool = False,
    choices: tuple[str, ...] | None = None,
    per_env: bool = False,
) -> Any:
    """A settings dataclass's field. `help`: one line for --help and docs/settings.md. `traced`: a
    number carried as an array in the runner state (PPO's `Hyper`), so a group's members may differ
    in it; otherwise it fixes shapes or the program's structure and they must agree.
    `saved_may_lack`: added after runs were first saved, so a saved config without it means its
    default. `choices`: the valid values of a text setting. `per_env`: a top-level setting that an
    env's `TRAINING` may set (every section's setting may), so the command line's schema leaves it
    null."""
    if not help:
        raise TypeError("a setting needs its help line")
    metadata = {
        HELP: help,
        TRACED: traced,
        SAVED_MAY_LACK: saved_may_lack,
        CHOICES: choices,
        PER_ENV: per_env,
    }
    return dataclasses.field(default=default, metadata=metadata)


def settings_of(cls: type) -> tuple[dataclasses.Field, ...]:
    """The fields of a settings dataclass that are settings (`setting(...)`), in declaration
    order."""
    return tuple(f for f in dataclasses.fields(cls) if HELP in f.metadata)


def names(cls: type, **wanted: Any) -> tuple[str, ...]:
    """The names of `cls`'s settings whose metadata has the values `wanted` (e.g. traced=True)."""
    return tuple(
        f.name for f in settings_of(cls) if all(f.metadata[k] == v for k, v in wanted.items())
    )


def allows_none(f: dataclasses.Field) -> bool:
    """Whether a field's type admits None (`float | None`)."""
    return str(f.type).replace(" ", "").endswith("|None")


def check_choices(obj: Any, prefix: str = "") -> None:
    """UsageError naming a text setting of `obj` that is not one of its declared choices."""
    for f in settings_of(type(obj)):
        value, valid = getattr(obj, f.name), f.metadata[CHOICES]
        if valid is not None and value not in valid:
            raise UsageError(f"unknown {prefix}{f.name} {value!r}; valid: {', '.join(valid)}")
