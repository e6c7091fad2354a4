"""Paths a command will write, checked before any work: a folder that is a file, a file that is
a folder, or a place that cannot be written is one line naming it (UsageError), not a traceback
after training. A write the machine refuses all the same (a full disk) is one line naming the
path (hintsjax.system.refusals.WriteFailed), and `write_whole` leaves what was there intact."""

from __future__ import annotations

import os
import shutil
from pathlib import Path
from typing import Callable

from hintsjax.system.errors import UsageError
from hintsjax.system.refusals import writing_to


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


def existing_part(path: str | os.PathLike) -> Path:
    """The longest part of `path` (made absolute) that exists: what `unmake` keeps."""
    return _nearest_existing(Path(path).expanduser().absolute())


def unmake(folder: str | os.PathLike, existed: Path) -> None:
    """Remove `folder` (one this command made) and the folders above it that were made for it:
    up to `existed` (`existing_part` before it was made), each only if empty."""
    folder = Path(folder).expanduser().absolute()
    shutil.rmtree(folder, ignore_errors=True)
    for parent in folder.parents:
        if parent == existed or not parent.is_relative_to(existed):
            break
        try:
            parent.rmdir()
        except OSError:
            break


def check_folder(path: str | os.PathLike, what: str, shown: Path | None = None) -> None:
    """UsageError unless `path` is a folder this process may write in, or one it can make (the
    message names `shown`, default `path`)."""
    path = Path(path).expanduser().absolute()
    shown = shown or path
    there = _nearest_existing(path)
    if not there.is_dir():
        raise UsageError(f"{what} {shown}: {there} is a file, not a folder")
    if not os.access(there, os.W_OK | os.X_OK):
        raise UsageError(f"{what} {shown}: cannot write in {there}")


def check_file(path: str | os.PathLike, what: str) -> None:
    """UsageError unless `path` can be written as a file: not a folder, in a folder that is
    writable or can be made."""
    path = Path(path).expanduser().absolute()
    if path.is_dir():
        raise UsageError(f"{what} {path} is a folder; give a file's path")
    check_folder(path.parent, what, shown=path)


def write_whole(path: str | os.PathLike, write: Callable[[Path], None]) -> None:
    """`write(p)` of the file at `path`, whole or not at all: into a sibling, flushed to the disk,
    then renamed over it, so a failed write (a full disk) or a stop in the middle (Ctrl-C, a crash)
    leaves what was there; a path that is not a regular file (/dev/stdout) is written directly. A
    refusal of the machine's is a WriteFailed naming `path`."""
    path = Path(path)
    with writing_to(path):
        if path.exists() and not path.is_file():
            write(path)
            return
        part = path.with_name(f".{path.name}.part")
        try:
            write(part)
            fd = os.open(part, os.O_RDONLY)
            try:
                os.fsync(fd)  # its bytes on the disk before the rename makes them the file
            finally:
                os.close(fd)
            part.replace(path)
        finally:
            part.unlink(missing_ok=True)


def write_text_whole(path: str | os.PathLike, text: str) -> None:
    """`text` as the file at `path`, whole or not at all (`write_whole`)."""
    write_whole(path, lambda part: part.write_text(text))
