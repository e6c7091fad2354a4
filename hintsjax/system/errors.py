"""Bad input (UsageError) and the boundary every command's entry point keeps (`command`): bad
input is one line and exit 2, Ctrl-C (or SIGTERM) one line and exit 130 (143), output to a reader
that went away (`| head`) silence and exit 141, what the machine refused
(hintsjax/system/refusals.py; limits too low for JAX, before anything runs) one line and exit
1, and anything else a bug in hintsjax, reported in one line that says so and where its
traceback was written, exit 1."""

from __future__ import annotations

import functools
import os
import sys
import tempfile
import time
import traceback
from pathlib import Path
from typing import Any, Callable

from hintsjax.system.refusals import MACHINE, limits_too_low, machine_refused, report_machine
from hintsjax.system.signals import (
    Terminated,
    command_begins,
    raise_stop_asked,
    sigint_as_interrupt,
)

INTERRUPTED = 130  # the exit status of a command stopped by Ctrl-C (128 + SIGINT), as a shell's
TERMINATED = 143  # the exit status of a command stopped by SIGTERM (128 + SIGTERM), as a shell's
# the exit status of a command whose reader closed its output (128 + SIGPIPE), as a shell's
CLOSED_PIPE = 141
BUG = 1
USAGE = 2  # the exit status of bad input
# set (to anything but 0): a bug's traceback on stderr, as Python prints it
DEBUG = "HINTSJAX_DEBUG"


class UsageError(ValueError):
    """Bad input from the user: reported in one line, exit status 2."""


def report_usage(error: Exception) -> int:
    """Report bad input in one line; the exit status for it."""
    print(f"error: {error}", file=sys.stderr)
    return USAGE


def described(error: BaseException) -> str:
    """`error` in a few words: its type and the first line of its text (200 characters at most)."""
    text = str(error).strip()
    return f"{type(error).__name__}: {text.splitlines()[0][:200]}" if text else type(error).__name__


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
    what = described(error)
    where = f"its traceback is in {path}" if path else f"{DEBUG}=1 prints its traceback"
    print(
        f"error: a bug in hintsjax ({what}); {where}; please report it with that traceback",
        file=sys.stderr,
    )
    return BUG


def _device_settled() -> None:
    """Wait for the computations still running on the device (a stop leaves them behind): the
    process must not exit under them, where XLA's teardown crashed (SIGABRT, a corrupted heap)."""
    bridge = sys.modules.get("jax._src.xla_bridge")
    try:  # only a backend already started (never start one to exit), in one process (no peers)
        if bridge is None or not bridge.backends_are_initialized():
            return
        jax = sys.modules["jax"]
        if jax.process_count() > 1:
            return
        for array in jax.live_arrays():
            try:
                array.block_until_ready()
            except Exception:  # noqa: BLE001  a failed computation is settled too
                pass
    except Exception:  # noqa: BLE001  settling is a courtesy; the stop's line is printed already
        pass


def command(main: Callable[..., int]) -> Callable[..., int]:
    """A command's entry point (returning its exit status) behind the boundary: UsageError one
    line, exit 2; Ctrl-C one line, exit 130; output whose reader has gone, nothing more, exit 141;
    any other exception `report_bug` (with HINTSJAX_DEBUG set, Python's own traceback instead)."""

    @functools.wraps(main)
    def guarded(*args: Any, **kwargs: Any) -> int:
        refused = limits_too_low()  # under them XLA aborts in C++, past any boundary's reach
        if refused is not None:
            print(f"error: {refused}", file=sys.stderr)
            return MACHINE
        try:
            try:
                command_begins()  # a stop asked while the command's modules imported: raised
                # Ctrl-C raises, and one that Python drops in JAX's gc callback stops the command
                # as it ends
                with sigint_as_interrupt():
                    status = main(*args, **kwargs)
                    if not status:
                        raise_stop_asked()
                return status
            finally:
                # a closed pipe shows here, in the boundary, not at the interpreter's exit
                sys.stdout.flush()
        except UsageError as e:
            return report_usage(e)
        except Terminated:
            print("terminated (SIGTERM)", file=sys.stderr)
            _device_settled()
            return TERMINATED
        except KeyboardInterrupt:
            print("interrupted", file=sys.stderr)
            _device_settled()
            return INTERRUPTED
        except BrokenPipeError:  # `... --help | head`: the reader has what it wanted
            # nor fail flushing at exit
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return CLOSED_PIPE
        except Exception as e:  # noqa: BLE001  the boundary: the machine's refusals, else a bug
            return report_machine(e) if machine_refused(e) else report_bug(e)

    return guarded
