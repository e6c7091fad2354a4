"""The XLA flags hintsjax sets before JAX starts its backend (hintsjax/__init__.py calls
`set_defaults` on import; XLA reads XLA_FLAGS once, when the first backend starts): deterministic
GPU ops unless XLA_FLAGS names the flag (`drop_determinism` takes them off for physics=warp, which
cannot repeat anyway), a persisted autotune folder when they are off, and on a CPU the schedule
that can deadlock MJX's batched LAPACK kernels turned off.

More of what it owns and why: docs/design.md, "Module notes", hintsjax/system/xla_flags.py.
"""

from __future__ import annotations

import os
from importlib.metadata import PackageNotFoundError, version
from pathlib import Path

DETERMINISTIC = "--xla_gpu_deterministic_ops"
AUTOTUNE_FOLDER = "--xla_gpu_per_fusion_autotune_cache_dir"
CPU_SCHEDULER = "--xla_cpu_enable_concurrency_optimized_scheduler"
OFF = ("", "off", "none", "false", "0", "no")

# The flags hintsjax added, kept beside XLA_FLAGS for the processes this one starts (a sweep's
# workers, run_path.py's commands): they inherit both, and tell the flags a user chose from ours.
ADDED = "HINTSJAX_XLA_FLAGS_ADDED"

# whether XLA_FLAGS named deterministic ops before hintsjax set them (the user's choice stands)
user_chose_determinism = False


def _flags() -> str:
    return os.environ.get("XLA_FLAGS", "")


def _add(flag: str) -> None:
    os.environ["XLA_FLAGS"] = f"{_flags()} {flag}".strip()
    os.environ[ADDED] = f"{os.environ.get(ADDED, '')} {flag}".strip()


def _drop(prefix: str) -> None:
    for name in ("XLA_FLAGS", ADDED):
        os.environ[name] = " ".join(
            f for f in os.environ.get(name, "").split() if not f.startswith(prefix)
        )


def deterministic_gpu_ops() -> bool:
    """Whether XLA_FLAGS asks for deterministic GPU ops (the last setting of the flag wins)."""
    settings = [f.split("=", 1)[-1] for f in _flags().split() if f.startswith(DETERMINISTIC)]
    return bool(settings) and settings[-1].lower() in ("true", "1")


def autotune_folder() -> str | None:
    """The persisted autotune folder beside the compilation cache (made), or None where the
    cache is off or the folder cannot be made."""
    root = os.environ.get("HINTSJAX_COMPILATION_CACHE", "~/.cache/hintsjax/xla")
    if root.strip().lower() in OFF:
        return None
    try:
        folder = Path(root).expanduser() / f"autotune-jaxlib-{version('jaxlib')}"
        folder.mkdir(parents=True, exist_ok=True)
    except (OSError, PackageNotFoundError):
        return None
    return str(folder)


def _persist_autotuning() -> None:
    if not deterministic_gpu_ops() and AUTOTUNE_FOLDER not in _flags():
        folder = autotune_folder()
        if folder is not None:
            _add(f"{AUTOTUNE_FOLDER}={folder}")


def set_defaults() -> None:
    """The flags above, each unless XLA_FLAGS names it already (not counting those a parent
    hintsjax process added: they are set afresh here)."""
    global user_chose_determinism
    inherited = os.environ.pop(ADDED, "").split()
    mine = _flags().split()
    for flag in inherited:  # one copy each, the user's own copies stay
        if flag in mine:
            mine.remove(flag)
    os.environ["XLA_FLAGS"] = " ".join(mine)
    user_chose_determinism = DETERMINISTIC in _flags()
    if not user_chose_determinism:
        _add(f"{DETERMINISTIC}=true")
    if CPU_SCHEDULER not in _flags():
        _add(f"{CPU_SCHEDULER}=false")
    _persist_autotuning()


def drop_determinism() -> bool:
    """Deterministic GPU ops off (with the autotune folder), unless the user chose them or JAX's
    backend has started (its flags are read); whether they are now off."""
    # here: hintsjax/__init__ imports this module to set XLA's flags, before jax
    from jax._src import xla_bridge

    started = getattr(xla_bridge, "backends_are_initialized", lambda: True)()
    if not (user_chose_determinism or started):
        _drop(DETERMINISTIC)
        _add(f"{DETERMINISTIC}=false")
        _persist_autotuning()
    return not deterministic_gpu_ops()
