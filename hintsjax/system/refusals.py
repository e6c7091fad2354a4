"""What the machine refuses, told apart from bugs and by its cause: a write (a full disk, a
read-only mount, a missing permission: WriteFailed, naming the path), too many open files, memory
(OutOfMemory, naming the settings that size the work) and limits too low to start JAX at all
(`limits_too_low`, checked before a command runs). Each is one line and exit 1 at a command's
boundary (hintsjax/system/errors.py)."""

from __future__ import annotations

import contextlib
import errno
import os
import re
import resource
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


# Too many files open at once: the process's limit (ulimit -n) or the system's table
FILE_LIMIT_ERRNOS = {errno.EMFILE, errno.ENFILE}
# A disk with no room, whatever error carries it (tensorstore's, XLA's): the machine's doing
DISK_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT}
# What to do, beside the cause's own words, where these say more than the path
ADVICE = {
    errno.ENOSPC: "free space there (or write to another disk) and run again",
    errno.EDQUOT: "free space within your quota (or write to another disk) and run again",
    errno.EFBIG: "a file outgrew the size limit (ulimit -f): raise it and run again",
    errno.EMFILE: "raise the limit (ulimit -n 4096) and run again",
}
# Below these a command is refused before it starts (`limits_too_low`): XLA aborts in C++ when it
# cannot map its threads' data or its compiled code, and a run opens about 20 files at once
# (docs/tests.md, "Faults of the machine", gives the measurements).
MIN_ADDRESS_SPACE = 4 * 2**30  # bytes: ulimit -v (RLIMIT_AS) and ulimit -d (RLIMIT_DATA)
MIN_OPEN_FILES = 64  # ulimit -n (RLIMIT_NOFILE)


def os_errno(error: BaseException) -> int | None:
    """The errno of the OS's refusal behind `error`, or behind the errors it was raised from or
    while handling (not those `raise ... from None` hides): an OSError's own; else one its text
    names, as tensorstore's does under orbax (`[os_error_code='28']`, `[Errno 24]`) or by the
    refusal's own words ("No space left on device"). None when nothing says the OS refused
    something."""
    seen: set[int] = set()
    while error is not None and id(error) not in seen:
        seen.add(id(error))
        if isinstance(error, OSError) and error.errno is not None:
            return error.errno
        text = str(error)
        found = re.search(r"os_error_code='(\d+)'|\[Errno (\d+)\]", text)
        if found:
            return int(found.group(1) or found.group(2))
        for code in (*WRITE_ERRNOS, *FILE_LIMIT_ERRNOS):
            if os.strerror(code) in text:
                return code
        error = error.__cause__ or (None if error.__suppress_context__ else error.__context__)
    return None


def cause_text(error: BaseException) -> str:
    """`error`'s cause in a few words: the OS's refusal behind it (`os_errno`; too many open files
    with the limit that says how many), else the first line of its text."""
    code = os_errno(error)
    if code in FILE_LIMIT_ERRNOS:
        soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
        return f"too many open files (this process may open {soft} at once: ulimit -n)"
    if code is not None:
        return os.strerror(code)
    text = str(error).strip()
    return text.splitlines()[0][:200] if text else type(error).__name__


def _advised(text: str, code: int | None) -> str:
    advice = ADVICE.get(errno.EMFILE if code in FILE_LIMIT_ERRNOS else code)
    return f"{text}; {advice}" if advice else text


def limits_too_low() -> str | None:
    """The one line refusing to start under a limit too low for JAX (`MIN_ADDRESS_SPACE`,
    `MIN_OPEN_FILES`), naming it and how to raise it; None when the limits leave room."""
    for limit, flag in ((resource.RLIMIT_AS, "-v"), (resource.RLIMIT_DATA, "-d")):
        soft, _ = resource.getrlimit(limit)
        if soft != resource.RLIM_INFINITY and soft < MIN_ADDRESS_SPACE:
            return (
                f"this process may map at most {soft / 2**30:.1f} GiB of memory (ulimit {flag} "
                f"{soft // 1024}); JAX needs {MIN_ADDRESS_SPACE // 2**30} GiB or more to start "
                f"and compile: raise it (ulimit {flag} unlimited) and run again"
            )
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft != resource.RLIM_INFINITY and soft < MIN_OPEN_FILES:
        return (
            f"this process may open only {soft} files at once (ulimit -n); a run needs "
            f"{MIN_OPEN_FILES} or more: raise it (ulimit -n 4096) and run again"
        )
    return None


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
        _advised(
            f"could not {verb} {where if where is not None else 'a file'}: "
            f"{error.strerror or os.strerror(error.errno)}",
            error.errno,
        ),
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
    Python's MemoryError): the machine's limit, not a bug. A file's refusal is not memory, though
    tensorstore calls a full disk RESOURCE_EXHAUSTED too (`os_errno`)."""
    if isinstance(error, OutOfMemory):
        return True
    text = str(error)
    return os_errno(error) not in DISK_FULL_ERRNOS | FILE_LIMIT_ERRNOS and (
        isinstance(error, MemoryError) or "RESOURCE_EXHAUSTED" in text or "Out of memory" in text
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
    elif (code := os_errno(error)) in FILE_LIMIT_ERRNOS:
        print(f"error: {_advised(cause_text(error), code)}", file=sys.stderr)
    elif code in DISK_FULL_ERRNOS:
        where = path if path is not None else "a file"
        line = _advised(f"could not write {where}: {cause_text(error)}", code)
        print(f"error: {line}", file=sys.stderr)
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
        or os_errno(error) in FILE_LIMIT_ERRNOS | DISK_FULL_ERRNOS
        or out_of_memory(error)
        or backend_failed(error)
    )
