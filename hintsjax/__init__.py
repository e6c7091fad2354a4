"""hintsjax: HINTs (Human-INTuited cues for RL) in JAX. See README.md."""

import os as _os
from pathlib import Path as _Path

# `hintsjax.envs` is the checkout's top-level envs/ folder (pyproject.toml's package-dir): an
# editable install maps it there and a normal install copies it into hintsjax/envs. After a normal
# install, a command run from the checkout's root imports this folder (the working directory comes
# first on sys.path), which has no envs/ of its own: then the package also looks beside itself.
_here = _Path(__file__).resolve().parent
if not (_here / "envs").is_dir() and (_here.parent / "envs" / "__init__.py").is_file():
    __path__.append(str(_here.parent))

# Same seed, same result on a GPU too. Without this flag two processes training the same seed on
# an H100 ended with different params (XLA autotunes GPU kernels per compile; measured with
# experiments/determinism.py). It must be set before jax starts; to opt out, put
# --xla_gpu_deterministic_ops=false in XLA_FLAGS yourself (1.5-1.8x faster training: below, and
# experiments/results/bench_h100_determinism.txt).
if "xla_gpu_deterministic_ops" not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ.get("XLA_FLAGS", "") + " --xla_gpu_deterministic_ops=true").strip()

# No deadlock on a CPU. XLA's CPU runtime runs independent parts of a program at once on its
# thread pool (as many threads as cores), and jaxlib's batched LAPACK kernels (the Cholesky and
# triangular solves of MJX's constraint solver and mass matrix) split their batch over that same
# pool and wait for the pieces: when every pool thread is such a kernel, nothing is left to run
# the pieces and the program stops for good (the ant's training program on 2 cores, and
# tests/test_cpu_deadlock.py's two independent batched Cholesky solves). XLA's schedule that
# orders a program for concurrency is what puts them side by side; without it they run one after
# the other. Set the flag in XLA_FLAGS yourself to choose otherwise.
if "xla_cpu_enable_concurrency_optimized_scheduler" not in _os.environ.get("XLA_FLAGS", ""):
    _os.environ["XLA_FLAGS"] = (_os.environ["XLA_FLAGS"] + " --xla_cpu_enable_concurrency_optimized_scheduler=false").strip()


def deterministic_gpu_ops() -> bool:
    """Whether XLA_FLAGS asks for deterministic GPU ops (the last setting of the flag wins)."""
    settings = [f.split("=", 1)[-1] for f in _os.environ.get("XLA_FLAGS", "").split() if f.startswith("--xla_gpu_deterministic_ops")]
    return bool(settings) and settings[-1].lower() in ("true", "1")


# Reproducible without deterministic ops too, on one machine. With the flag off, XLA fuses the
# networks' matrix products into Triton kernels whose tiling it autotunes by timing them, so two
# compiles of one program may pick different kernels and round differently; XLA's own remedy is
# a persisted autotune cache (its docs/determinism.md). So the first compile on a machine tunes
# and writes the folder, and later ones read the same choices: the pendulum's training then gave
# the same params in three processes, 1.52x faster than with deterministic ops; the ant's did
# not, since MJX's sums over the body tree run as scatter-adds with float atomics
# (experiments/results/profile_update_h100.json, docs/throughput.md). The folder sits beside the
# compilation cache (HINTSJAX_COMPILATION_CACHE, or ~/.cache/hintsjax/xla; off when that is off).
def _autotune_folder() -> str | None:
    from importlib.metadata import PackageNotFoundError, version

    root = _os.environ.get("HINTSJAX_COMPILATION_CACHE", "~/.cache/hintsjax/xla")
    if root.strip().lower() in ("", "off", "none", "false", "0", "no"):
        return None
    try:
        folder = _Path(root).expanduser() / f"autotune-jaxlib-{version('jaxlib')}"
        folder.mkdir(parents=True, exist_ok=True)
    except (OSError, PackageNotFoundError):
        return None
    return str(folder)


if not deterministic_gpu_ops() and "xla_gpu_per_fusion_autotune_cache_dir" not in _os.environ["XLA_FLAGS"]:
    _tuned = _autotune_folder()
    if _tuned is not None:
        _os.environ["XLA_FLAGS"] += f" --xla_gpu_per_fusion_autotune_cache_dir={_tuned}"


# One run over several processes or hosts (hintsjax/devices.py): each process must join the
# others before anything starts JAX's backend, as importing some of the package's modules does.
if int(_os.environ.get("JAX_NUM_PROCESSES", "1") or 1) > 1 or int(_os.environ.get("SLURM_STEP_NUM_TASKS", "1") or 1) > 1:
    from hintsjax.devices import join_processes as _join_processes

    _join_processes()
