"""A run killed with SIGKILL, as a crash or the kernel's out-of-memory killer would: no clean-up,
no `finally` blocks, no flushed files. Used by tests/test_cli.py.

    python tests/killed_run.py after|during|interrupt|terminate '<run values as JSON>'
    python tests/killed_run.py group <folder>

`after`: killed once the first checkpoint is completely written. `during`: killed as soon as the
second checkpoint has been handed to the background writer, so its files are (most likely)
half-written. `group`: tests/test_group.py's group of two cue-env configurations (`killed_group`)
trained into <folder>, killed once the group's first checkpoint is written. `interrupt`: not
killed but sent SIGINT (Ctrl-C) once the first chunk's metrics are logged, raised in the main
thread so that it takes effect there and then; it exits with the run's own status. `terminate`:
sent SIGTERM (as a cluster's time limit or preemption) by a real kill at the same point; it exits
with the run's own status.
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


def stopped_at_the_first_report(stop, what: str) -> None:
    """Run the command's values (argv[2]), calling `stop` once the first chunk's metrics are logged
    (the chunk loop's log calls check_physics then); exit with the run's status (never 0)."""
    real_check, checks = loop.check_physics, []

    def check_then_stop(*args):
        real_check(*args)
        checks.append(1)
        if len(checks) == 1:
            stop()

    loop.check_physics = check_then_stop
    status = run.main_from_values(json.loads(sys.argv[2]))
    if status == 0:
        sys.exit(f"the run ended without being {what} (the hook ran {len(checks)} time(s))")
    sys.exit(status)


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

    if mode == "terminate":  # a real kill, as a scheduler's
        stopped_at_the_first_report(lambda: os.kill(os.getpid(), signal.SIGTERM), "terminated")
    if mode == "interrupt":
        # Python raises KeyboardInterrupt on SIGINT only if the signal was not ignored when it
        # started (a test runner's child may inherit SIG_IGN; a terminal's never does), and a
        # library may take the handler over: set Python's own, and check that at the first report
        # the run's own stands in for it (hintsjax/system/signals.py's sigint_as_interrupt)
        signal.signal(signal.SIGINT, signal.default_int_handler)

        def interrupt() -> None:
            handler = signal.getsignal(signal.SIGINT)
            if getattr(handler, "__qualname__", "") != "signal_as_interrupt.<locals>.handler":
                sys.exit(f"SIGINT's handler at the first report is {handler!r}, not hintsjax's")
            # As Ctrl-C, but raised in this (the main) thread, so it takes effect here and now
            signal.raise_signal(signal.SIGINT)

        stopped_at_the_first_report(interrupt, "interrupted")
    checkpoint.save = save_then_die
    if mode == "group":
        from test_group import killed_group

        pipeline.train_group(*killed_group(Path(sys.argv[2])), progress=False)
    else:
        run.main_from_values(json.loads(sys.argv[2]))
    sys.exit("the run ended without being killed")


if __name__ == "__main__":
    main()
