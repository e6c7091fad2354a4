"""`key=value` command-line arguments into a settings dataclass (the tools beside the run command:
hintsjax.generator, hintsjax.rank), checked against its fields' types in one line each; `--help`
lists the settings with their defaults and the registries' choices (hintsjax.cli.choices). The
argparse commands share its one-line parser errors (`ArgumentParser`) and int32 type
(`int32_arg`)."""

from __future__ import annotations

import argparse
import dataclasses
from typing import Any, TypeVar

from hintsjax.system.checks import beyond_int32
from hintsjax.system.errors import UsageError
from hintsjax.cli import choices

T = TypeVar("T")


def help_page(cls: type, prog: str, about: str) -> str:
    """The --help page of a `key=value` command: what it does, its settings and their defaults, the
    choices."""
    settings = [
        f"  {f.name}={'null' if f.default is None else f.default}" for f in dataclasses.fields(cls)
    ]
    return "\n".join(
        [
            f"usage: {prog} [key=value ...]",
            "",
            about,
            "",
            "Settings (key=default):",
            *settings,
            "",
            choices.text(),
        ]
    )


def parse_key_values(cls: type[T], argv: list[str], prog: str = "", about: str = "") -> T:
    """`cls(**values)` from `key=value` arguments (str fields take the text as it is; int and float
    fields a number; `null`, or nothing for a number, gives None where the field allows it);
    UsageError naming the valid keys or the expected type. `-h` or `--help` prints `help_page` and
    exits 0, as argparse does."""
    if {"-h", "--help"} & set(argv):
        print(help_page(cls, prog, about))
        raise SystemExit(0)
    kinds = {f.name: str(f.type) for f in dataclasses.fields(cls)}
    values: dict[str, Any] = {}
    for arg in argv:
        key, eq, raw = arg.partition("=")
        if not eq or key not in kinds:
            raise UsageError(
                f"unexpected argument {arg!r}: give key=value with a key of {', '.join(kinds)}"
            )
        kind = kinds[key]
        if kind.endswith("None") and (raw == "null" or (raw == "" and not kind.startswith("str"))):
            values[key] = None
        elif kind.startswith("str"):
            values[key] = raw
        else:
            try:
                values[key] = (int if kind.startswith("int") else float)(raw)
            except ValueError:
                raise UsageError(f"{key} must be {kind}, got {raw!r}") from None
            if isinstance(values[key], int) and beyond_int32(values[key]):
                raise UsageError(f"{key} {beyond_int32(values[key])}, got {raw}")
    return cls(**values)


def int32_arg(text: str) -> int:
    """An argparse `type`: an integer that JAX's int32 holds."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}") from None
    if beyond_int32(value):
        raise argparse.ArgumentTypeError(f"{beyond_int32(value)}, got {text}")
    return value


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line (`error: ...; see <prog> --help`), exit 2."""

    def error(self, message: str):  # noqa: D102
        self.exit(2, f"error: {message}; see {self.prog} --help\n")
