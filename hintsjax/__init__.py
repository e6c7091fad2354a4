"""hintsjax: HINTs (Human-INTuited cues for RL) in JAX. See README.md."""

import os as _os
import sys as _sys
from pathlib import Path as _Path

# `hintsjax.envs` is the checkout's top-level envs/ folder (pyproject.toml's package-dir): an
# editable install maps it there and a normal install copies it into hintsjax/envs. After a normal
# install, a command run from the checkout's root imports this folder (the working directory comes
# first on sys.path), which has no envs/ of its own: then the package also looks beside itself.
_here = _Path(__file__).resolve().parent
if not (_here / "envs").is_dir() and (_here.parent / "envs" / "__init__.py").is_file():
    __path__.append(str(_here.parent))

# A command's process (`python -m hintsjax.<command>`, the `hintsjax` console script): a Ctrl-C or
# SIGTERM while its modules import is kept for the command's boundary to raise as it begins
# (hintsjax/system/signals.py), not lost in JAX's gc callback. Only for the commands that have
# that boundary: any other process keeps Python's own handlers.
_COMMANDS = ("run", "evaluate", "video", "expert", "quickstart", "rank", "generator", "console")
_argv = getattr(_sys, "orig_argv", [])
_module = _argv[_argv.index("-m") + 1] if "-m" in _argv[:-1] else None
_script = _Path(_sys.argv[0]).name if _sys.argv else ""
if _module in {f"hintsjax.{c}" for c in _COMMANDS} or (_module is None and _script == "hintsjax"):
    from hintsjax.system import signals as _signals

    _signals.keep_while_starting()

# XLA's flags, before anything starts JAX's backend: deterministic GPU ops (same seed, same
# result), their autotuning persisted when the user turns them off, no deadlock on a CPU
# (hintsjax/system/xla_flags.py).
from hintsjax.system import xla_flags as _xla_flags  # noqa: E402  (after the envs path above)

_xla_flags.set_defaults()
deterministic_gpu_ops = _xla_flags.deterministic_gpu_ops


# One run over several processes or hosts (hintsjax/system/devices.py): each process must join the
# others before anything starts JAX's backend, as importing some of the package's modules does.
if (
    int(_os.environ.get("JAX_NUM_PROCESSES", "1") or 1) > 1
    or int(_os.environ.get("SLURM_STEP_NUM_TASKS", "1") or 1) > 1
):
    from hintsjax.system.devices import join_processes as _join_processes

    _join_processes()
