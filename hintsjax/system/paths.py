"""Paths a command will write, checked before any work: a folder that is a file, a file that is
a folder, or a place that cannot be written is one line naming it (UsageError), not a traceback
after training."""

from __future__ import annotations

import os
from pathlib import Path

from hintsjax.system.errors import UsageError


def _nearest_existing(path: Path) -> Path:
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


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
