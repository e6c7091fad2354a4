"""The one error type for bad names: it always says what the valid choices are."""

from __future__ import annotations

from typing import Iterable, Mapping, TypeVar

T = TypeVar("T")


class ChoiceError(ValueError):
    """An unknown name was asked for; the message names the valid choices."""

    def __init__(self, kind: str, name: str, choices: Iterable[str], where: str = ""):
        self.kind, self.name, self.choices = kind, name, sorted(choices)
        scope = f" for {where}" if where else ""
        super().__init__(
            f"unknown {kind} '{name}'{scope}; valid choices: {', '.join(self.choices)}"
        )


def choose(kind: str, name: str, table: Mapping[str, T], where: str = "") -> T:
    """`table[name]`, or a ChoiceError naming the valid keys."""
    if name not in table:
        raise ChoiceError(kind, name, table.keys(), where)
    return table[name]
