"""The settings as the command line and the documents see them, read off the fields
(hintsjax.settings.fields): the command line's schema (Hydra's config, with null wherever the layers
below decide), the keys a saved config may lack, the settings page of `--help` and
docs/settings.md (`python -m hintsjax.settings.schema` rewrites it)."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from hintsjax.settings.config import SECTIONS, CommandSettings, RunConfig
from hintsjax.settings.fields import HELP, PER_ENV, SAVED_MAY_LACK, settings_of

# in a checkout (not in a wheel)
SETTINGS_MD = Path(__file__).resolve().parents[2] / "docs" / "settings.md"


def _plain(value: Any) -> Any:
    return list(value) if isinstance(value, tuple) else value


def command_line_defaults() -> dict[str, Any]:
    """What the run command starts from before its arguments: every setting, nested by section; null
    where an env may set it (every section's setting, and a top-level one marked `per_env`), so
    that the env's layer decides (hintsjax.settings.layers.run_config), else the dataclass's
    default."""
    top = {
        f.name: None if f.metadata[PER_ENV] else _plain(f.default) for f in settings_of(RunConfig)
    }
    own = {f.name: _plain(f.default) for f in settings_of(CommandSettings)}
    return {
        **top,
        **own,
        **{name: {f.name: None for f in settings_of(cls)} for name, cls in SECTIONS.items()},
    }


def declared() -> list[tuple[str, dataclasses.Field]]:
    """(key as the command line names it, its field) for every setting, in the command line's order:
    a run's, the command's own, then each section's as section.key."""
    top = [(f.name, f) for cls in (RunConfig, CommandSettings) for f in settings_of(cls)]
    return top + [
        (f"{name}.{f.name}", f) for name, cls in SECTIONS.items() for f in settings_of(cls)
    ]


def keys() -> list[str]:
    """Every key the run command accepts, a section's as section.key."""
    return [key for key, _ in declared()]


def saved_may_lack() -> set[str]:
    """The settings (section.key for a section's) whose absence from a saved config means their
    default."""
    return {key for key, f in declared() if f.metadata[SAVED_MAY_LACK]}


def as_typed(value: Any) -> str:
    """A value as the command line writes it: null, true, [256,256]."""
    if value is None:
        return "null"
    if isinstance(value, bool):
        return str(value).lower()
    return str(_plain(value)).replace(" ", "").replace("'", "")


def all_rows() -> list[tuple[str, str, str]]:
    """(key, the dataclass's default as the command line writes it, help) for every setting."""
    return [(key, as_typed(f.default), f.metadata[HELP]) for key, f in declared()]


def help_text() -> str:
    """The settings page of `python -m hintsjax.run --help`: each key, its default and its help."""
    rows = all_rows()
    width = max(len(f"{k}={d}") for k, d, _ in rows)
    lines = [f"  {f'{k}={d}':<{width}}  {h}" for k, d, h in rows]
    return "\n".join(
        ["Settings (key=default; an env's TRAINING may set its own, docs/settings.md):", *lines]
    )


def markdown() -> str:
    """docs/settings.md: every setting, its default and its help, one table a section."""

    def table(rows: list[tuple[str, str, str]]) -> list[str]:
        return [
            "| key | default | what it does |",
            "|---|---|---|",
            *(f"| `{k}` | `{d}` | {h.replace('|', '/')} |" for k, d, h in rows),
        ]

    lines = [
        "# Settings",
        "",
        (
            "Every setting of `python -m hintsjax.run key=value`, its default and what it does, "
            "written by"
        ),
        (
            "`python -m hintsjax.settings.schema` from the fields that declare them "
            "(hintsjax/settings/config.py,"
        ),
        (
            "hintsjax/settings/algorithm_settings.py); `tests/test_config_schema.py` fails when "
            "this page is stale."
        ),
        (
            "A default here is the dataclass's: an env's `TRAINING` (envs/<env>.py) sets its own "
            "over it, and"
        ),
        (
            "`null` on the command line takes the env's. A resumed run keeps the settings it was "
            "started with."
        ),
        "",
        "## The run",
        "",
        *table([row for row in all_rows() if "." not in row[0]]),
    ]
    for name, cls in SECTIONS.items():
        rows = [row for row in all_rows() if row[0].startswith(f"{name}.")]
        lines += [
            "",
            f"## `{name}.*`",
            "",
            (cls.__doc__ or "").strip().splitlines()[0],
            "",
            *table(rows),
        ]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    SETTINGS_MD.write_text(markdown())
    print(f"wrote {SETTINGS_MD}")
