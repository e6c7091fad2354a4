"""Bad input from the user: its error type, its one-line report, and the check most settings share."""

from __future__ import annotations

import math
import sys
from typing import Any


class UsageError(ValueError):
    """Bad input from the user: reported in one line, exit status 2."""


def require_positive(obj: Any, names: tuple[str, ...], prefix: str = "") -> None:
    """UsageError naming the first of `names` (numbers, or tuples of widths) that is not a
    positive finite number (NaN and infinity included)."""
    for name in names:
        value = getattr(obj, name)
        if isinstance(value, tuple) and not all(w > 0 for w in value):
            raise UsageError(f"{prefix}{name} widths must be positive, got {list(value)}")
        if not isinstance(value, tuple) and not 0 < value < math.inf:
            kind = "a positive finite number" if isinstance(value, float) else "positive"
            raise UsageError(f"{prefix}{name} must be {kind}, got {value}")


def require_range(obj: Any, ranges: dict[str, tuple[float, float]], prefix: str = "") -> None:
    """UsageError naming the first of `ranges`' numbers that is not a finite number in its closed
    [low, high] (high may be infinity: any finite number from low up)."""
    for name, (low, high) in ranges.items():
        value = getattr(obj, name)
        if not (low <= value <= high and math.isfinite(value)):
            raise UsageError(f"{prefix}{name} must be a finite number in [{low}, {high}], got {value}")


def fail(error: Exception) -> int:
    """Report bad input in one line; the exit status for it."""
    print(f"error: {error}", file=sys.stderr)
    return 2
