"""Train from the command line (Hydra), evaluate, and write one run folder.

    python -m hintsjax.run env=pendulum agent=hints hint=composite scheme=fc seeds=5
    python -m hintsjax.run -m scheme=lc,ac,fc,mc       # a sweep, one folder per run
    python -m hintsjax.run resume=runs/<folder>        # go on (ppo.total_env_steps=N: train longer)

A run folder holds config.yaml (resolved), metrics.csv, TensorBoard events (tb/), orbax
checkpoints of the full train state (checkpoints/), eval.json and learning_curve.png.
Bad input is reported in one line with the valid choices, exit status 2, nothing written.
"""

from __future__ import annotations

import errno
import json
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import hydra
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from hintsjax.system import (
    checkpoint,
    compilation_cache,
    devices,
    folder_lock,
    paths,
    requeue,
    xla_flags,
)
from hintsjax.system.errors import (
    INTERRUPTED,
    TERMINATED,
    UsageError,
    command,
    report_bug,
    report_usage,
)
from hintsjax.system.refusals import MACHINE, machine_refused, report_machine
from hintsjax.system.signals import (
    Terminated,
    raise_stop_asked,
    sigint_as_interrupt,
    sigterm_as_interrupt,
)
from hintsjax.settings import schema
from hintsjax.settings.config import RunConfig
from hintsjax.settings.layers import CONFIG_YAML, load_run_config, save_run_config
from hintsjax.cli import choices, overrides
from hintsjax.training.guards import NONFINITE_JSON, NonFiniteError
from hintsjax.training.loop import SECONDS_JSON
from hintsjax.training.outputs import EVAL_JSON, new_run_dir
from hintsjax.training.pipeline import train
from hintsjax.training.request import Request, checked_request, rounded_budget


def main_from_values(values: dict[str, Any]) -> int:
    """Run from plain config values (what Hydra resolved); returns the exit status. SIGTERM (a
    cluster's time limit or preemption) is handled as Ctrl-C is, and always saves the newest state
    whose metrics are logged; so is submitit's preemption signal, after which submitit requeues
    the job (system/requeue.py)."""
    # submitit's own handler kept, whatever its signal; Ctrl-C while compiling is not lost
    with requeue.preemption_as_interrupt(), sigterm_as_interrupt(), sigint_as_interrupt():
        try:
            raise_stop_asked()  # one that Python dropped in an earlier job of this sweep
            return _run(values)
        except requeue.Preempted as e:  # before the run had a folder: nothing to save
            return requeue.hand_over(e, None, "nothing trained")


def requeued_run(out_dir: str, cfg: RunConfig) -> Path | None:
    """The folder in out_dir that this submitit job made for `cfg` before it was requeued (its
    job.json names the job, its config.yaml is cfg, and it has not finished), or None: a run to
    go on with."""
    for folder in requeue.folders_of_this_job(out_dir):
        try:
            if not (folder / EVAL_JSON).exists() and load_run_config(folder, complete=True) == cfg:
                print(f"requeued job {requeue.job_id()}: goes on in {folder}", file=sys.stderr)
                return folder
        except UsageError:  # its config.yaml is unreadable or foreign: not this run's
            continue
    return None


def _run(values: dict[str, Any]) -> int:
    """A run command's values to its exit status: the request checked, its folder opened, the
    training, and the one line each way of stopping early prints (`stopped_early`)."""
    try:
        asked = checked_request(values)
    except UsageError as e:
        return report_usage(e)
    except Exception as e:  # noqa: BLE001  the boundary: the machine's set-up, else a bug
        return report_machine(e) if machine_refused(e) else report_bug(e)
    named = any(
        (values.get("ppo") or {}).get(k) is not None for k in ("total_env_steps", "batch_size")
    )
    # an env's own budget is not the user's to round
    if named and (note := rounded_budget(asked.cfg)) and devices.is_main():
        print(note, file=sys.stderr)
    compilation_cache.enable(compilation_cache.folder(values.get("compilation_cache")))
    folder = RunFolder(asked, existed=paths.existing_part(asked.out_dir))
    try:
        try:
            folder.open()
        except UsageError as e:  # another run holds the folder
            return report_usage(e)
        except Exception as e:  # noqa: BLE001  the boundary: a full disk or read-only folder, else a bug
            where = folder.path or asked.out_dir
            return report_machine(e, where) if machine_refused(e) else report_bug(e, folder.path)
        try:
            train(asked.cfg, folder.path, resume=folder.resume)
            if not (folder.path / CONFIG_YAML).is_file():  # removed, and made again by a write
                raise FileNotFoundError(errno.ENOENT, "removed", str(folder.path / CONFIG_YAML))
        except (Exception, KeyboardInterrupt) as e:  # noqa: BLE001  each kind has its line
            return stopped_early(e, folder)
        return 0
    finally:
        folder.release()


@dataclass
class RunFolder:
    """Where a run trains (`path`): a new folder, the one a requeued job made, or the resumed run's;
    whether this call made it (a run refused before its first update takes it away again) and
    whether it holds a checkpoint to go on from."""

    asked: Request
    existed: Path  # the part of out_dir that stood before this call (paths.existing_part)
    path: Path | None = None
    made: bool = False
    resume: bool = False
    lock: folder_lock.FolderLock | None = None  # process 0's: one run at a time writes a folder

    def open(self) -> None:
        """Make (or find) the folder, take its lock (UsageError naming the run that holds it)
        and write its config; the folder is set as soon as it exists."""
        asked = self.asked
        if asked.run_dir is not None:
            self.path = asked.run_dir
            self.take_lock()  # before anything is written
            # process 0 looks at the folder alone (the restore, on every process, reads it whole)
            self.resume = devices.agree_that(devices.is_main() and checkpoint.any_saved(self.path))
            if not self.resume:  # stopped before its first checkpoint: it trains from the start
                self.check_startable()
            if asked.longer and devices.is_main():
                save_run_config(self.path, asked.cfg)  # the budget it now trains to
            return
        if devices.is_main():
            self.path = requeued_run(asked.out_dir, asked.cfg)
            if self.path is None:
                self.path, self.made = new_run_dir(asked.out_dir, asked.name, asked.cfg), True
        # the folder process 0 made (or found), on every process
        self.path = Path(devices.agree(str(self.path)))
        self.take_lock()
        if self.made:
            save_run_config(self.path, asked.cfg)
            requeue.record(self.path)
        # a requeued run's newest checkpoint, if it had one (process 0 looks: the look tidies it)
        self.resume = devices.agree_that(
            devices.is_main() and checkpoint.latest_update(self.path) is not None
        )

    def take_lock(self) -> None:
        """Process 0 takes the folder's lock; every process raises the same UsageError if another
        run holds it (none waits on a process that has given up)."""
        refused = ""
        if devices.is_main():
            try:
                self.lock = folder_lock.acquire(self.path)
            except UsageError as e:
                refused = str(e)
        refused = devices.agree(refused)
        if refused:
            raise UsageError(refused)

    def check_startable(self) -> None:
        """UsageError for a resumed folder without a checkpoint that once had one (its eval.json or
        seconds.json, which every save writes: its checkpoints were lost, and training from the
        start would drop its log); else one line saying it trains from the start."""
        for saved in (EVAL_JSON, SECONDS_JSON):
            if (self.path / saved).exists():
                raise UsageError(
                    f"{self.path} has no checkpoint in {self.path / checkpoint.CHECKPOINTS} but "
                    f"saved one before (its {saved}): its checkpoints were lost; start a new run "
                    "(or put them back)"
                )
        if devices.is_main():
            print(
                f"note: {self.path} holds no checkpoint yet (stopped before its first): it trains "
                "from the start",
                file=sys.stderr,
            )

    def release(self) -> None:
        if self.lock is not None:
            self.lock.release()

    def take_back(self) -> None:
        """Remove the folder this call made if it holds only its config (and job.json)."""
        path = self.path
        if self.made and path.is_dir() and {p.name for p in path.iterdir()} <= UNTRAINED:
            paths.unmake(path, self.existed)


# what a run folder holds before its first update
UNTRAINED = {CONFIG_YAML, requeue.JOB_JSON, folder_lock.LOCK}


def stopped_early(error: BaseException, folder: RunFolder) -> int:
    """The one line a run that did not reach its end prints, and its exit status."""
    run_dir = folder.path
    # found before the first update (a program that cannot fit): a new folder goes again
    if isinstance(error, UsageError):
        folder.take_back()
        return report_usage(error)
    if not (run_dir / CONFIG_YAML).is_file():  # removed (or moved) under the run
        print(
            f"error: the run folder {run_dir} was removed while the run went on "
            f"({type(error).__name__}); the run stopped",
            file=sys.stderr,
        )
        return MACHINE
    if isinstance(error, checkpoint.CheckpointWriteError):  # the newest complete one stays
        good = checkpoint.newest_listed(run_dir)  # read off the folder: no collective here
        kept = f"the newest complete one is at update {good}" if good else "none is complete"
        print(
            f"error: {error}; {kept}; once it can be written, go on with: "
            f"python -m hintsjax.run resume={run_dir}",
            file=sys.stderr,
        )
        return MACHINE
    if isinstance(error, KeyboardInterrupt):
        return interrupted(error, run_dir)
    if isinstance(error, NonFiniteError):  # its checkpoints were all written before it went so
        good = checkpoint.latest_update(run_dir)  # read once the background writes are done
        if devices.is_main():
            found = {**error.found, "last_good_checkpoint": good}
            paths.write_text_whole(run_dir / NONFINITE_JSON, json.dumps(found) + "\n")
        last = f"update {good}" if good else "none"
        print(f"error: {error}; last good checkpoint: {last} ({run_dir})", file=sys.stderr)
        return 1
    # the boundary: the machine's refusals; else a bug, its traceback kept in the run folder
    return report_machine(error, run_dir) if machine_refused(error) else report_bug(error, run_dir)


def interrupted(stop: KeyboardInterrupt, run_dir: Path) -> int:
    """Ctrl-C or SIGTERM (the loop saved a checkpoint if one was due, and its writes are done):
    one line naming the newest checkpoint and the command that goes on; submitit's preemption
    hands over to submitit, which requeues the job."""
    good = checkpoint.latest_update(run_dir)
    saved = f"checkpoint at update {good}" if good else "no checkpoint yet"
    if isinstance(stop, requeue.Preempted):
        return requeue.hand_over(stop, run_dir, saved)
    stopped = "terminated (SIGTERM)" if isinstance(stop, Terminated) else "interrupted"
    print(
        f"{stopped}; {saved}; go on with: python -m hintsjax.run resume={run_dir}", file=sys.stderr
    )
    return TERMINATED if isinstance(stop, Terminated) else INTERRUPTED


# the schema, read off the fields
ConfigStore.instance().store(name="config", node=overrides.hydra_config())


@hydra.main(version_base=None, config_path=None, config_name="config")
def _hydra_main(cfg: DictConfig) -> None:
    status = main_from_values(OmegaConf.to_container(cfg, resolve=True))
    if status:
        sys.exit(status)  # SystemExit passes through Hydra's exception reporting


@command
def checked_main() -> int:
    """The command line checked (every job of a sweep, before the first trains), then Hydra's run.
    --help: the registries' choices, the settings with their help, then Hydra's page of the
    config."""
    if {"-h", "--help"} & set(sys.argv[1:]):
        print(f"{__doc__.strip()}\n\n{choices.text()}\n\n{schema.help_text()}\n")
    overrides.check_overrides(sys.argv[1:])
    if overrides.asks_only_for_warp(sys.argv[1:]):
        # nothing under MuJoCo Warp repeats bit for bit; they only cost speed
        xla_flags.drop_determinism()
    overrides.check_sweep(sys.argv[1:], checked_request)
    _hydra_main()  # exits itself with a run's non-zero status
    return 0


def main() -> None:
    sys.exit(checked_main())


if __name__ == "__main__":
    main()
