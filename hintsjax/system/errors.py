"""Bad input from the user: its error type, its one-line report, and the check most settings
share; and the boundary every command's entry point keeps (`command`): bad input is one line
and exit 2, Ctrl-C (or SIGTERM) one line and exit 130 (143), output to a reader that went away
(`| head`) silence and exit 141, a write the machine refused (a full disk, a read-only mount, a
missing permission) or memory it does not have one line naming the path or the setting, exit 1,
and anything else is a bug in hintsjax, reported in one line that says so and where its traceback
was written, exit 1."""

from __future__ import annotations

import argparse
import contextlib
import errno
import functools
import math
import os
import signal
import sys
import tempfile
import threading
import time
import traceback
from pathlib import Path
from typing import Any, Callable

INTERRUPTED = 130  # the exit status of a command stopped by Ctrl-C (128 + SIGINT), as a shell's
TERMINATED = 143  # the exit status of a command stopped by SIGTERM (128 + SIGTERM), as a shell's
# the exit status of a command whose reader closed its output (128 + SIGPIPE), as a shell's
CLOSED_PIPE = 141
BUG = 1
MACHINE = 1  # the exit status of a command the machine stopped: a write it refused, memory it lacks
# the largest integer setting: what JAX's int32 (its integers without x64) holds
INT_MAX = 2**31 - 1
INT_MIN = -(2**31)
# A write that fails with one of these is the machine's doing (its disk, mount or permissions), not a bug.
WRITE_ERRNOS = {
    errno.ENOSPC,
    errno.EROFS,
    errno.EACCES,
    errno.EPERM,
    errno.EDQUOT,
    errno.EFBIG,
    errno.EIO,
}
# set (to anything but 0): a bug's traceback on stderr, as Python prints it
DEBUG = "HINTSJAX_DEBUG"


class UsageError(ValueError):
    """Bad input from the user: reported in one line, exit status 2."""


class Terminated(KeyboardInterrupt):
    """SIGTERM (a cluster's time limit or preemption, `kill`), raised in the main thread as Ctrl-C
    raises KeyboardInterrupt, so whatever handles Ctrl-C (a run saves its newest logged state)
    handles it too; reported as its own line, exit 143."""


_stops: list[KeyboardInterrupt] = []  # the stop a signal asked for (within `signal_as_interrupt`)
_blocks: list[int] = []  # the signals of the `signal_as_interrupt` blocks open now, outermost first
_deferring: list[bool] = []  # `stops_deferred` blocks open now


@contextlib.contextmanager
def signal_as_interrupt(number: int, make: Callable[[int, Any], KeyboardInterrupt]):
    """Within this block the signal `number` raises `make(number, frame)` in the main thread, as
    Ctrl-C raises KeyboardInterrupt (once: another signal while a stop is under way is ignored,
    and SIGKILL still kills); the signal's handler is put back after. Outside the main thread
    (where Python cannot handle signals) nothing changes.

    Within `stops_deferred` (training's loop) the stop is only kept, and the loop raises it at its
    safe points (`raise_stop_asked`), so that it never lands in the middle of a metrics row or a
    checkpoint's hand-over. Python also drops an exception raised while a garbage collector's
    callback runs (JAX has one: it prints "Exception ignored in ..." and goes on); the kept stop is
    raised at the next safe point then too."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if not _stops:
            _stops.append(make(signum, frame))
            if not _deferring:
                raise _stops[0]

    previous = signal.signal(number, handler)
    _blocks.append(number)
    try:
        yield
    finally:
        signal.signal(number, signal.SIG_DFL if previous is None else previous)
        _blocks.pop()
        # the outermost block: a stop taken in an inner one still holds off the outer's signal till
        # here
        if not _blocks:
            _stops.clear()


@contextlib.contextmanager
def stops_deferred():
    """Within this block a signal's stop (`signal_as_interrupt`) is kept, not raised: the code in
    it raises the stop at its own safe points (`raise_stop_asked`)."""
    _deferring.append(True)
    try:
        yield
    finally:
        _deferring.pop()


def raise_stop_asked() -> None:
    """Raise the stop a signal asked for, if any (`signal_as_interrupt`): kept within
    `stops_deferred`, or dropped by Python where it was raised."""
    if _stops:
        raise _stops[0]


def sigterm_as_interrupt():
    """Within this block SIGTERM raises Terminated in the main thread (`signal_as_interrupt`)."""
    return signal_as_interrupt(signal.SIGTERM, lambda number, frame: Terminated())


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


def whole(text: str) -> int:
    """An argparse `type`: an integer that JAX's int32 holds."""
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"invalid int value: {text!r}") from None
    if beyond_int32(value):
        raise argparse.ArgumentTypeError(f"{beyond_int32(value)}, got {text}")
    return value


class WriteFailed(OSError):
    """A write the machine refused (`WRITE_ERRNOS`), with the path it was writing: one line, exit 1."""


def machine_write(error: OSError, path: Any = None) -> WriteFailed | None:
    """`error` as a WriteFailed naming `path` (or the error's own file name) if the machine
    refused a write (`WRITE_ERRNOS`); None for any other OSError."""
    if isinstance(error, WriteFailed):
        return error
    if error.errno not in WRITE_ERRNOS:
        return None
    where = error.filename or path
    # A refused permission or a failed disk may have been a read, where nothing says it was a write
    verb = (
        "read or write"
        if path is None and error.errno in (errno.EACCES, errno.EPERM, errno.EIO)
        else "write"
    )
    return WriteFailed(
        error.errno,
        f"could not {verb} {where if where is not None else 'a file'}: "
        f"{error.strerror or os.strerror(error.errno)}",
    )


@contextlib.contextmanager
def writing_to(path: Any):
    """A write to `path`: a refusal of the machine's (`machine_write`) raised as a WriteFailed naming it."""
    try:
        yield
    except OSError as e:
        failed = machine_write(e, path)
        if failed is None:
            raise
        raise failed from None


class OutOfMemory(RuntimeError):
    """An allocation the device refused, with the settings that size it: one line, exit 1."""


def out_of_memory(error: BaseException) -> bool:
    """Whether `error` is an allocation that failed (XLA's RESOURCE_EXHAUSTED or "Out of memory",
    Python's MemoryError): the machine's limit, not a bug."""
    text = str(error)
    return (
        isinstance(error, (MemoryError, OutOfMemory))
        or "RESOURCE_EXHAUSTED" in text
        or "Out of memory" in text
    )


@contextlib.contextmanager
def sized_by(lower: str):
    """Work whose memory `lower` (settings, as the user writes them) sizes: an allocation that fails
    in it is raised as OutOfMemory naming them."""
    try:
        yield
    except Exception as e:
        if isinstance(e, OutOfMemory) or not out_of_memory(e):
            raise
        raise OutOfMemory(_memory_line(e, lower)) from None


def _memory_line(error: BaseException, lower: str) -> str:
    text = str(error)
    amount = (
        text[text.find("Out of memory") :].splitlines()[0][:80]
        if "Out of memory" in text
        else type(error).__name__
    )
    return f"the device ran out of memory ({amount}); lower {lower} and run again"


def report_machine(error: BaseException, path: Any = None) -> int:
    """One line for what the machine refused (a write, naming its path, else `path`; memory, naming
    the settings to lower); the exit status."""
    if isinstance(error, OSError) and machine_write(error) is not None:
        print(f"error: {machine_write(error, path).strerror}", file=sys.stderr)
    else:
        print(
            f"error: {error if isinstance(error, OutOfMemory) else _memory_line(error, 'the sizes you gave')}",
            file=sys.stderr,
        )
    return MACHINE


def machines(error: BaseException) -> bool:
    """Whether `error` is the machine's refusal (`report_machine`), not a bug."""
    return (isinstance(error, OSError) and machine_write(error) is not None) or out_of_memory(error)


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
        Path(tempfile.gettempdir())
        / f"hintsjax-traceback-{time.strftime('%Y%m%d-%H%M%S')}-{os.getpid()}.txt"
    ]:
        try:
            place.write_text(text)
            path = place
            break
        except OSError:
            continue
    what = (
        f"{type(error).__name__}: {str(error).strip().splitlines()[0][:200]}"
        if str(error).strip()
        else type(error).__name__
    )
    where = f"its traceback is in {path}" if path else f"{DEBUG}=1 prints its traceback"
    print(
        f"error: a bug in hintsjax ({what}); {where}; please report it with that traceback",
        file=sys.stderr,
    )
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
                # a closed pipe shows here, in the boundary, not at the interpreter's exit
                sys.stdout.flush()
        except UsageError as e:
            return fail(e)
        except Terminated:
            print("terminated (SIGTERM)", file=sys.stderr)
            return TERMINATED
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            return INTERRUPTED
        except BrokenPipeError:  # `... --help | head`: the reader has what it wanted
            # nor fail flushing at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return CLOSED_PIPE
        except Exception as e:  # noqa: BLE001  the boundary: the machine's refusals, else a bug
            return report_machine(e) if machines(e) else report_bug(e)

    return guarded


class ArgumentParser(argparse.ArgumentParser):
    """argparse's parser whose errors are one line (`error: ...; see <prog> --help`), exit 2."""

    def error(self, message: str):  # noqa: D102
        self.exit(2, f"error: {message}; see {self.prog} --help\n")
