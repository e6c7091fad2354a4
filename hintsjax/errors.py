"""Bad input from the user: its error type, its one-line report, and the check most settings share."""

from __future__ import annotations

import sys
from typing import Any


class UsageError(ValueError):
    """Bad input from the user: reported in one line, exit status 2."""


def require_positive(obj: Any, names: tuple[str, ...], prefix: str = "") -> None:
    """UsageError naming the first of `names` (numbers, or tuples of widths) that is not positive."""
    for name in names:
        value = getattr(obj, name)
        if isinstance(value, tuple) and not all(w > 0 for w in value):
            raise UsageError(f"{prefix}{name} widths must be positive, got {list(value)}")
        if not isinstance(value, tuple) and value <= 0:
            raise UsageError(f"{prefix}{name} must be positive, got {value}")


def fail(error: Exception) -> int:
    """Report bad input in one line; the exit status for it."""
    print(f"error: {error}", file=sys.stderr)
    return 2
