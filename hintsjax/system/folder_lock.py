"""One writer a run folder: a run holds an advisory lock (`fcntl.flock` on the folder's LOCK file)
for as long as it trains there, and a second run on the same folder is refused in one line naming
the holder (its pid, host and start), exit 2. The kernel lets a lock go when its holder's process
ends, SIGKILL included, so a lock is never stale; a clean exit removes the file. `holder` tells a
reader (evaluate, video, expert) whether a run is training in the folder now."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import sys
import time
from dataclasses import dataclass
from pathlib import Path

from hintsjax.system.errors import UsageError
from hintsjax.system.refusals import writing_to

LOCK = "writer.lock"  # in a run folder while a run trains there: who holds it, as JSON


@dataclass
class FolderLock:
    """A run folder's lock, held (`acquire`) until `release`."""

    folder: Path
    fd: int | None

    def release(self) -> None:
        """Remove the lock file, then let the lock go (a run that waits for it takes a new file)."""
        if self.fd is None:
            return
        try:
            (self.folder / LOCK).unlink()
        except OSError:  # gone with its folder (a run refused before its first update removes it)
            pass
        os.close(self.fd)
        self.fd = None


def acquire(folder: Path) -> FolderLock:
    """The lock of `folder`, or UsageError naming the run that holds it."""
    folder = Path(folder)
    path = folder / LOCK
    while True:
        with writing_to(path):
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            if not _locked(fd, folder):  # a file system that takes no locks
                os.close(fd)
                return FolderLock(folder, None)
            try:
                same = os.fstat(fd).st_ino == os.stat(path).st_ino
            except FileNotFoundError:  # its holder removed the file between our open and our lock
                same = False
            if same:
                mine = {"pid": os.getpid(), "host": socket.gethostname()}
                mine["since"] = time.strftime("%H:%M:%S")
                with writing_to(path):
                    os.ftruncate(fd, 0)
                    os.write(fd, json.dumps(mine).encode())
                return FolderLock(folder, fd)
        except BaseException:
            os.close(fd)  # the lock goes with it
            raise
        os.close(fd)


@contextlib.contextmanager
def holding(folders: list[Path]):
    """The locks of `folders` (each made if missing, each once) for the block; UsageError naming
    the first held by another run, with those taken before it let go. A sweep's worker writes its
    group's folder and each member's."""
    with contextlib.ExitStack() as stack:
        for folder in dict.fromkeys(Path(f).absolute() for f in folders):
            folder.mkdir(parents=True, exist_ok=True)
            stack.callback(acquire(folder).release)
        yield


def _locked(fd: int, folder: Path) -> bool:
    """Take the lock on `fd`: True; UsageError naming the holder if another run has it; False,
    with one line saying so, on a file system that takes no locks (NFS without its lock daemon,
    Lustre's noflock), where nothing then keeps a second run out."""
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except BlockingIOError:
        raise UsageError(
            f"{folder} is being written by another run ({_holder_text(_read(fd))}); one run at a "
            "time trains in a folder: wait for it to end or stop it, then run again"
        ) from None
    except OSError as e:
        print(
            f"warning: {folder} takes no lock ({os.strerror(e.errno)}): nothing keeps a second "
            "run from writing it at once",
            file=sys.stderr,
        )
        return False
    return True


def holder(folder: Path) -> str | None:
    """Who trains in `folder` now (pid, host, start), or None: read from its lock file, whose pid is
    checked on this host (a file left by a killed run names a process that is gone)."""
    try:
        found = json.loads((Path(folder) / LOCK).read_text())
    except (OSError, ValueError):
        return None
    if not isinstance(found, dict) or found.get("host") != socket.gethostname():
        return _holder_text(found) if isinstance(found, dict) else None
    try:
        os.kill(int(found.get("pid", -1)), 0)
    except (OSError, ValueError, OverflowError):
        return None
    return _holder_text(found)


def _read(fd: int) -> dict:
    try:
        return json.loads(os.pread(fd, 4096, 0) or b"{}")
    except (OSError, ValueError):
        return {}


def _holder_text(found: dict) -> str:
    return (
        f"pid {found.get('pid', '?')} on {found.get('host', '?')}, since {found.get('since', '?')}"
    )


def say_if_training(folder: Path) -> None:
    """A reader's one line when a run still trains in `folder` (it reads the newest checkpoint)."""
    held = holder(folder)
    mine = f"pid {os.getpid()} on {socket.gethostname()},"  # a sweep's worker exports its expert
    if held is not None and not held.startswith(mine):
        print(
            f"note: {folder} is still training ({held}): this reads its newest checkpoint",
            file=sys.stderr,
        )
