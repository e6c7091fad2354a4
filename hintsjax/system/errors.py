"""Bad input from the user: its error type, its one-line report, and the check most settings
share; and the boundary every command's entry point keeps (`command`): bad input is one line
and exit 2, Ctrl-C one line and exit 130, output to a reader that went away (`| head`) silence
and exit 141, and anything else is a bug in hintsjax, reported in one line that says so and
where its traceback was written, exit 1."""

from __future__ import annotations

import argparse
import functools
import math
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any, Callable

INTERRUPTED = 130  # the exit status of a command stopped by Ctrl-C (128 + SIGINT), as a shell's
CLOSED_PIPE = 141  # the exit status of a command whose reader closed its output (128 + SIGPIPE), as a shell's
BUG = 1
DEBUG = "HINTSJAX_DEBUG"  # set (to anything but 0): a bug's traceback on stderr, as Python prints it


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


def report_bug(error: BaseException, folder: Path | None = None) -> int:
    """A bug in hintsjax (not bad input): its traceback written to `folder`/traceback.txt (a run
    folder), else to a file in the temporary folder; one line saying so and where; the exit status.
    With HINTSJAX_DEBUG set, `error` is raised again instead (Python prints its traceback)."""
    if os.environ.get(DEBUG, "0") not in ("", "0"):
        raise error
    text = "".join(traceback.format_exception(error))
    path = None
    for place in ([Path(folder) / "traceback.txt"] if folder is not None else []) + [
            Path(tempfile.gettempdir()) / f"hintsjax-traceback-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"]:
        try:
            place.write_text(text)
            path = place
            break
        except OSError:
            continue
    what = f"{type(error).__name__}: {str(error).strip().splitlines()[0][:200]}" if str(error).strip() else type(error).__name__
    where = f"its traceback is in {path}" if path else f"{DEBUG}=1 prints its traceback"
    print(f"error: a bug in hintsjax ({what}); {where}; please report it with that traceback", file=sys.stderr)
    return BUG


def command(main: Callable[..., int]) -> Callable[..., int]:
    """A command's entry point (returning its exit status) behind the boundary: UsageError one
    line, exit 2; Ctrl-C one line, exit 130; output whose reader has gone, nothing more, exit 141;
    any other exception `report_bug` (with HINTSJAX_DEBUG set, Python's own traceback instead)."""

    @functools.wraps(main)
    def guarded(*args: Any, **kwargs: Any) -> int:
        try:
            try:
                return main(*args, **kwargs)
            finally:
                sys.stdout.flush()  # a closed pipe shows here, in the boundary, not at the interpreter's exit
        except UsageError as e:
            return fail(e)
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            return INTERRUPTED
        except BrokenPipeError:  # `... --help | head`: the reader has what it wanted
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # nor fail flushing at exit
            return CLOSED_PIPE
        except Exception as e:  # noqa: BLE001  the boundary: whatever escapes is a bug
            return report_bug(e)

    return guarded


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line (`error: ...; see <prog> --help`), exit 2."""

    def error(self, message: str):  # noqa: D102
        self.exit(2, f"error: {message}; see {self.prog} --help\n")
