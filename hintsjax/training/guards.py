"""What stops a run that went wrong, found on the host as each chunk's metrics arrive.

A non-finite loss stops training without saving that state (`first_nonfinite`, `stop_nonfinite`:
NonFiniteError, and nonfinite.json in the run folder), so the newest checkpoint is the last good
one; only params that are all finite are checkpointed (`finite_seeds`). `check_physics` reports
MJX-Warp running out of a buffer. None of them adds anything to the compiled training program.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from hintsjax.envs import physics
from hintsjax.system import devices, paths
from hintsjax.system.errors import UsageError
from hintsjax.settings.config import RunConfig


class NonFiniteError(RuntimeError):
    """Training went NaN or infinite: the run stopped without saving that state, so its newest
    checkpoint is the last good one (NONFINITE_JSON in the run folder says where and what)."""

    def __init__(self, message: str, found: dict[str, Any]):
        super().__init__(message)
        self.found = found  # what NONFINITE_JSON holds


# Losses that every sound update keeps finite (episode_return is NaN where no episode ended). A
# non-finite parameter makes the next update's losses non-finite, so checking them on the host
# finds it one update later at most, without adding anything to the compiled training program;
# a checkpoint is written only of params that are all finite (`finite_seeds`).
FINITE_METRICS = ("policy_loss", "value_loss", "entropy")


NONFINITE_JSON = "nonfinite.json"


@jax.jit
def finite_seeds(params: Any) -> jax.Array:
    """[S] bool: whether every parameter of each seed (of every member, for a group) is finite."""
    return jnp.stack(
        [jnp.isfinite(x).reshape(x.shape[0], -1).all(axis=1) for x in jax.tree.leaves(params)]
    ).all(axis=0)


def first_nonfinite(metrics: dict[str, np.ndarray], after: int) -> dict[str, Any] | None:
    """The first update of a chunk's metrics ([S, n] or a group's [S, n, K], `after` updates
    before it) with a loss that is not finite: its update, the loss, the seeds (and members)."""
    for u in range(next(iter(metrics.values())).shape[1]):
        for name in FINITE_METRICS:
            if name in metrics:
                bad = ~np.isfinite(metrics[name][:, u])
                if bad.any():
                    found = {
                        "update": after + u + 1,
                        "quantity": name,
                        "seeds": np.flatnonzero(bad.reshape(len(bad), -1).any(axis=1)).tolist(),
                    }
                    return (
                        found
                        if bad.ndim == 1
                        else {**found, "members": np.flatnonzero(bad.any(axis=0)).tolist()}
                    )
    return None


def stop_nonfinite(run_dir: Path, label: str, found: dict[str, Any]) -> None:
    """Record `found` in the run folder and raise NonFiniteError."""
    if devices.is_main():
        paths.write_text_whole(run_dir / NONFINITE_JSON, json.dumps(found) + "\n")
    where = f"seed(s) {found['seeds']}" + (
        f", member(s) {found['members']}" if "members" in found else ""
    )
    raise NonFiniteError(
        f"{label}: {found['quantity']} is not finite after update {found['update']} ({where}); "
        f"training stopped without saving it",
        found,
    )


def check_physics(cfg: RunConfig, label: str) -> None:
    """UsageError naming `warp_capacity` if MJX-Warp ran out of a buffer in this process (its
    worlds that did were made NaN, so nothing was trained on dropped contacts)."""
    lost = physics.overflow_seen()
    if lost is not None:
        raise UsageError(
            f"{cfg.env} {label}: MJX-Warp ran out of {lost} at warp_capacity={cfg.warp_capacity}; "
            f"train again with a larger warp_capacity (or physics=jax)"
        )
