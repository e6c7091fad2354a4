"""What the machine refuses, told apart from bugs: a write (a full disk, a read-only mount, a
missing permission: WriteFailed, naming the path) and memory (OutOfMemory, naming the settings
that size the work). Each is one line and exit 1 at a command's boundary
(hintsjax/system/errors.py)."""

from __future__ import annotations

import contextlib
import errno
import os
import sys
import traceback
from typing import Any

MACHINE = 1  # the exit status of a command the machine stopped: a write it refused, memory it lacks
# A write that fails with one of these is the machine's doing (its disk, mount or permissions), not
# a bug.
WRITE_ERRNOS = {
    errno.ENOSPC,
    errno.EROFS,
    errno.EACCES,
    errno.EPERM,
    errno.EDQUOT,
    errno.EFBIG,
    errno.EIO,
}


class WriteFailed(OSError):
    """A write the machine refused (`WRITE_ERRNOS`), with the path it was writing: one
    line, exit 1."""


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
    """A write to `path`: a refusal of the machine's (`machine_write`) raised as a WriteFailed
    naming it."""
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
    elif backend_failed(error):
        print(f"error: {_backend_line(error)}", file=sys.stderr)
    else:
        line = (
            error if isinstance(error, OutOfMemory) else _memory_line(error, "the sizes you gave")
        )
        print(f"error: {line}", file=sys.stderr)
    return MACHINE


def backend_failed(error: BaseException) -> bool:
    """Whether `error` is JAX failing to start its backend (JAX_PLATFORMS naming a platform this
    machine lacks, a plugin that does not load): the machine's set-up, not a bug."""
    frames = traceback.extract_tb(error.__traceback__)
    return isinstance(error, (AssertionError, RuntimeError)) and any(
        frame.filename.endswith(os.path.join("jax", "_src", "xla_bridge.py")) for frame in frames
    )


def _backend_line(error: BaseException) -> str:
    platforms = os.environ.get("JAX_PLATFORMS")
    asked = f"JAX_PLATFORMS={platforms!r}" if platforms else "its default platforms"
    why = f": {str(error).splitlines()[0][:200]}" if str(error).strip() else ""
    return (
        f"JAX could not start a backend for {asked}{why}; set JAX_PLATFORMS to one this machine "
        "has (cpu), or install its plugin (CUDA: make setup-gpu)"
    )


def machine_refused(error: BaseException) -> bool:
    """Whether `error` is the machine's refusal (`report_machine`), not a bug."""
    return (
        (isinstance(error, OSError) and machine_write(error) is not None)
        or out_of_memory(error)
        or backend_failed(error)
    )
