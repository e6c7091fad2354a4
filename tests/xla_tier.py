"""The default tier's XLA flags: tests/conftest.py sets them; a test that compiles more than XLA's
programs (tests/envs/test_physics.py: Warp's kernels) reads from here whether they are on, and one
whose subprocess runs at XLA's default level (test_rank, test_quickstart) takes the level out."""

from __future__ import annotations

import os

OPTIMIZATION = "--xla_backend_optimization_level"  # LLVM's level; 0 in the default tier
LOOP_EMITTERS = "--xla_cpu_use_fusion_emitters=false"


def default_tier_flags() -> str:
    """XLA_FLAGS with the default tier's two flags added."""
    return f"{os.environ.get('XLA_FLAGS', '')} {OPTIMIZATION}=0 {LOOP_EMITTERS}".strip()


def at_o0() -> bool:
    """Whether this process's XLA programs compile at LLVM -O0 (the default tier's flags are
    set)."""
    return f"{OPTIMIZATION}=0" in os.environ.get("XLA_FLAGS", "").split()


def without_optimisation_level() -> str:
    """XLA_FLAGS without the LLVM level, for a subprocess that runs at XLA's default."""
    return " ".join(
        f for f in os.environ.get("XLA_FLAGS", "").split() if not f.startswith(OPTIMIZATION)
    )
