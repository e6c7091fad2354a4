"""A run killed with SIGKILL, as a crash or the kernel's out-of-memory killer would: no clean-up,
no `finally` blocks, no flushed files. Used by tests/test_cli.py.

    python tests/killed_run.py after|during|interrupt '<run values as JSON>'
    python tests/killed_run.py group <folder>

`after`: killed once the first checkpoint is completely written. `during`: killed as soon as the
second checkpoint has been handed to the background writer, so its files are (most likely)
half-written. `group`: tests/test_group.py's group of two cue-env configurations (`killed_group`)
trained into <folder>, killed once the group's first checkpoint is written. `interrupt`: not
killed but sent SIGINT (Ctrl-C) once the first chunk's metrics are logged, raised in the main
thread so that it takes effect there and then; it exits with the run's own status.
"""

from __future__ import annotations

import json
import os
import signal
import sys
from pathlib import Path

from hintsjax.system import checkpoint
from hintsjax import run
from hintsjax.training import loop, pipeline


def main() -> None:
    mode = sys.argv[1]
    real, saves = checkpoint.save, []

    def save_then_die(run_dir, state, update):
        real(run_dir, state, update)
        saves.append(update)
        if mode in ("after", "group") and len(saves) == 1:
            checkpoint.flush(run_dir)  # wait for the files, then die
            os.kill(os.getpid(), signal.SIGKILL)
        if mode == "during" and len(saves) == 2:
            os.kill(os.getpid(), signal.SIGKILL)

    if mode == "interrupt":
        real_check, checks = loop.check_physics, []

        def check_then_interrupt(*args):  # loop.advance's report calls it once a chunk's metrics are logged
            real_check(*args)
            checks.append(1)
            if len(checks) == 1:
                # As Ctrl-C, but sent to this (the main) thread: os.kill's process-wide signal may land
                # in any of XLA's threads and be handled later, under load after the run has gone on
                # past this report (or inside orbax's asyncio loop, which takes SIGINT for itself)
                signal.raise_signal(signal.SIGINT)

        loop.check_physics = check_then_interrupt
        sys.exit(run.main_from_values(json.loads(sys.argv[2])))
    checkpoint.save = save_then_die
    if mode == "group":
        from test_group import killed_group

        pipeline.train_group(*killed_group(Path(sys.argv[2])), progress=False)
    else:
        run.main_from_values(json.loads(sys.argv[2]))
    sys.exit("the run ended without being killed")


if __name__ == "__main__":
    main()
