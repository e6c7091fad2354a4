"""The checks most settings share: positive, in a range, within JAX's int32 (its integers without
x64), each a UsageError naming the setting and the value it got."""

from __future__ import annotations

import math
from typing import Any

from hintsjax.system.errors import UsageError

# the largest integer setting: what JAX's int32 (its integers without x64) holds
INT_MAX = 2**31 - 1
INT_MIN = -(2**31)


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
            raise UsageError(
                f"{prefix}{name} must be a finite number in [{low}, {high}], got {value}"
            )


def beyond_int32(value: int) -> str | None:
    """What is wrong with an integer setting beyond JAX's int32 (such a number overflows a
    conversion, or wraps, far from where it was given), as `must be ...`; None where it fits."""
    if value > INT_MAX:
        return f"must be at most {INT_MAX} (what JAX's int32 holds)"
    if value < INT_MIN:
        return f"must be at least {INT_MIN} (what JAX's int32 holds)"
    return None


def require_int32(obj: Any, names: tuple[str, ...], prefix: str = "") -> None:
    """UsageError naming the first of `names` (integers, or tuples of them) beyond JAX's int32."""
    for name in names:
        value = getattr(obj, name)
        for v in value if isinstance(value, tuple) else (value,):
            if isinstance(v, int) and beyond_int32(v):
                raise UsageError(f"{prefix}{name} {beyond_int32(v)}, got {v}")
