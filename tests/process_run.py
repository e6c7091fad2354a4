"""One process of a tiny run, for tests/test_devices.py: alone, or one of several processes
that JAX's multi-controller runtime joins into one run (hintsjax.system.devices.join_processes).

    JAX_NUM_PROCESSES=2 JAX_PROCESS_ID=0 JAX_COORDINATOR_ADDRESS=localhost:1234 \\
        XLA_FLAGS=--xla_force_host_platform_device_count=2 \\
        python tests/process_run.py <out_dir> [--resume]

Trains the linear env's ppo_state at 3 seeds into <out_dir>/run (a checkpoint after every
chunk of 2 updates), or with --resume continues <out_dir>/run from its newest checkpoint;
exits with the run's status.
"""

from __future__ import annotations

import datetime
import faulthandler
import sys
from pathlib import Path

import linear_env  # noqa: F401  (registers the test env "linear")
from hintsjax import run

TINY_PPO = {
    "total_env_steps": 320,
    "num_envs": 4,
    "batch_size": 64,
    "minibatch_size": 32,
    "epochs": 1,
}


HUNG_SECONDS = 300  # far beyond a run's 10-80 s: print every thread's stack to the log and exit
# how faulthandler's dump after HUNG_SECONDS begins
HUNG_MARK = f"Timeout ({datetime.timedelta(seconds=HUNG_SECONDS)})!"


def main() -> int:
    faulthandler.dump_traceback_later(HUNG_SECONDS, exit=True)  # a hang shows where it waits
    out = Path(sys.argv[1])
    if sys.argv[2:] == ["--resume"]:
        return run.main_from_values({"resume": str(out / "run"), "compilation_cache": False})
    return run.main_from_values(
        {
            "env": "linear",
            "agent": "ppo_state",
            "seeds": 3,
            "ppo": TINY_PPO,
            "eval_episodes": 2,
            "checkpoint_every": 2,
            "checkpoint_seconds": 0,
            "out_dir": str(out),
            "name": "run",
            "compilation_cache": False,
        }
    )


if __name__ == "__main__":
    sys.exit(main())
