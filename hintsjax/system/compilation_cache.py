"""JAX's persistent compilation cache in a user cache folder, so a second run of the same command
starts training within seconds instead of compiling again.

XLA keys each entry by the program, the compiler flags, the jax version and the device, so a
cache written by another machine or version is never used for the wrong program: its entries
simply miss. An unreadable entry is skipped by jax with a warning and compiled afresh; a folder
that cannot be made or written turns the cache off with one warning line.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

import jax

ENV_VAR = "HINTSJAX_COMPILATION_CACHE"  # a folder, or "off"
DEFAULT = Path("~/.cache/hintsjax/xla")
# Programs that compile faster than this are not worth a file (jax's own default is 1 s).
MIN_COMPILE_SECONDS = 1.0


OFF = ("", "off", "none", "false", "0", "no")


def folder(setting: bool | str | None) -> str | None:
    """The cache folder of a `compilation_cache` setting: true for $HINTSJAX_COMPILATION_CACHE, else
    ~/.cache/hintsjax/xla; a path for that folder; false or None for no cache (as is the variable
    set to 'off')."""
    if setting is None or setting is False or str(setting).strip().lower() in OFF:
        return None
    value = (
        os.environ.get(ENV_VAR, str(DEFAULT))
        if setting is True or str(setting).lower() == "true"
        else str(setting)
    )
    return None if value.strip().lower() in OFF else value


def enable(
    folder: str | os.PathLike | None, min_compile_seconds: float = MIN_COMPILE_SECONDS
) -> Path | None:
    """Turn the persistent cache on in `folder` (None: leave it off); returns the folder in use,
    or None (with one warning line on stderr) when it cannot be made or written."""
    if folder is None:
        return None
    path = Path(folder).expanduser()
    try:
        path.mkdir(parents=True, exist_ok=True)
        probe = path / f".probe-{os.getpid()}"
        probe.write_bytes(b"")
        probe.unlink()
    except OSError as e:
        print(
            f"warning: compilation cache off: cannot write {path} "
            f"({e.strerror or type(e).__name__})",
            file=sys.stderr,
        )
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", min_compile_seconds)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
    return path


def in_use() -> Path | None:
    """The folder the persistent cache writes to in this process, or None when it is off."""
    folder = jax.config.jax_compilation_cache_dir
    return Path(folder) if folder else None
