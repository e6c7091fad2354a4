"""A run whose cluster job is requeued goes on in its own folder.

Hydra's submitit launcher (`-m hydra/launcher=submitit_slurm`, or `submitit_local`) runs each job
of a sweep under submitit. At a job's time limit, or when it is preempted, submitit signals the job
(SIGUSR2, or what SUBMITIT_PREEMPT_SIGNAL names), pickles the job's call and requeues it: SLURM
starts the job again under the same job id, the local executor runs it again. The requeued call is
the same command line, which alone would start a new run in a new folder. So, inside a submitit job:

More of what it owns and why: docs/design.md, "Module notes", hintsjax/system/requeue.py.
"""

from __future__ import annotations

import contextlib
import json
import os
import signal
import sys
import time
from pathlib import Path
from typing import Any, Callable

from hintsjax.system import paths
from hintsjax.system.errors import TERMINATED
from hintsjax.system.signals import Terminated, signal_as_interrupt

# {"job_id", "executor", "cluster"}: the submitit job that made the run folder
JOB_JSON = "job.json"


class Preempted(Terminated):
    """submitit's preemption or time-limit signal, raised in the main thread as SIGTERM's
    Terminated is (a run saves its newest logged state); `requeue()` then hands the signal to
    submitit's own handler, which requeues the job and exits."""

    def __init__(self, name: str, requeue: Callable[[], Any]):
        super().__init__(name)
        self.name, self.requeue = name, requeue


def executor() -> str | None:
    """submitit's executor running this process ("slurm", "local"), or None outside a submitit
    job."""
    return os.environ.get("SUBMITIT_EXECUTOR") or None


def _submitit() -> Any:
    """The submitit module inside a submitit job; None outside one, or where submitit is not
    installed (a process that a job's task started, which inherited its variables)."""
    if executor() is None:
        return None
    try:
        import submitit
    except ImportError:
        return None
    return submitit


def job_id() -> str | None:
    """submitit's id of the job this process runs (SLURM's job id, `<array id>_<task>` in an array;
    the same after a requeue), or None outside a submitit job (`_submitit`)."""
    submitit = _submitit()
    return None if submitit is None else str(submitit.JobEnvironment().job_id)


def _job() -> dict[str, str] | None:
    """What names this job in a run folder's job.json: its id, the executor, and SLURM's cluster
    (job ids of clusters that share a file system may meet); None outside a submitit job."""
    job = job_id()
    return (
        None
        if job is None
        else {
            "job_id": job,
            "executor": executor(),
            "cluster": os.environ.get("SLURM_CLUSTER_NAME", ""),
        }
    )


def record(run_dir: Path) -> None:
    """Write this job's names into a new run folder (nothing outside a submitit job)."""
    if (job := _job()) is not None:
        # a full disk: one line
        paths.write_text_whole(Path(run_dir) / JOB_JSON, json.dumps(job) + "\n")


def folders_of_this_job(out_dir: str | Path) -> list[Path]:
    """The run folders in `out_dir` whose job.json names this job, oldest name first (none outside
    a submitit job). A job id can come back (the local executor's is a process id; SLURM's
    counter can be reset), so the caller also compares the run's config."""
    job, out = _job(), Path(out_dir)
    if job is None or not out.is_dir():
        return []
    found = []
    for folder in sorted(p for p in out.iterdir() if p.is_dir()):
        try:
            if json.loads((folder / JOB_JSON).read_text()) == job:
                found.append(folder)
        except (OSError, ValueError):  # no job.json, or not one this package wrote
            continue
    return found


def hand_over(stop: Preempted, folder: Path | None, saved: str) -> int:
    """After a run stopped for submitit's signal (its newest state saved): say so in one line, and
    let submitit's own handler requeue the job, which exits this process. Where submitit will not
    (the job timed out more times than hydra.launcher.max_num_timeout allows), a second line says
    so and names the command that goes on; exit status 143. A task other than the job's first is
    left running by submitit's handler: it waits for the requeue to end it (2 minutes at most)."""
    job = job_id()
    goes_on = f"; go on with: python -m hintsjax.run resume={folder}" if folder else ""
    print(
        f"preempted ({stop.name}); {saved}; submitit is asked to requeue job {job}"
        + (f", which goes on in {folder}" if folder else ""),
        file=sys.stderr,
    )
    from submitit.core.utils import UncompletedJobError

    try:
        stop.requeue()  # on the job's first task: requeues the job, then exits (SystemExit)
    except UncompletedJobError as e:
        print(f"submitit did not requeue job {job} ({e}){goes_on}", file=sys.stderr)
        return TERMINATED
    time.sleep(120)  # another task: the first one's requeue ends this one
    return TERMINATED


def preemption_as_interrupt() -> contextlib.AbstractContextManager:
    """Within this block, inside a submitit job, submitit's preemption signal raises Preempted in
    the main thread (signals.signal_as_interrupt); its handler is put back after. Elsewhere nothing
    changes."""
    submitit = _submitit()
    if submitit is None:
        return contextlib.nullcontext()
    # the signal submitit's handler is set on (USR2 unless told)
    number = submitit.JobEnvironment._usr_sig()
    submitits = signal.getsignal(number)

    def preempted(signum: int, frame: Any) -> Preempted:
        requeue = (lambda: submitits(signum, frame)) if callable(submitits) else (lambda: None)
        return Preempted(signal.Signals(signum).name, requeue)

    return signal_as_interrupt(number, preempted)
