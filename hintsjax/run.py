"""Train from the command line (Hydra), evaluate, and write one run folder.

    python -m hintsjax.run env=pendulum agent=hints hint=composite scheme=fc seeds=5
    python -m hintsjax.run -m scheme=lc,ac,fc,mc          # a sweep, one folder per run
    python -m hintsjax.run resume=runs/<folder>           # go on (ppo.total_env_steps=N: train longer)

A run folder holds config.yaml (resolved), metrics.csv, TensorBoard events (tb/), orbax
checkpoints of the full train state (checkpoints/), eval.json and learning_curve.png.
Bad input is reported in one line with the valid choices, exit status 2, nothing written.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path
from typing import Any

import hydra
from hydra.core.config_store import ConfigStore
from omegaconf import DictConfig, OmegaConf

from hintsjax.system import checkpoint, compilation_cache, devices, paths, requeue, xla_flags
from hintsjax.system.errors import (
    INTERRUPTED,
    TERMINATED,
    UsageError,
    command,
    report_bug,
    report_usage,
)
from hintsjax.system.refusals import machine_refused, report_machine
from hintsjax.system.signals import sigterm_as_interrupt, Terminated
from hintsjax.settings import schema
from hintsjax.settings.config import RunConfig
from hintsjax.settings.layers import CONFIG_YAML, load_run_config, save_run_config
from hintsjax.cli import choices, overrides
from hintsjax.training.guards import NONFINITE_JSON, NonFiniteError
from hintsjax.training.outputs import EVAL_JSON, new_run_dir
from hintsjax.training.pipeline import train
from hintsjax.training.request import request, rounded_budget


def main_from_values(values: dict[str, Any]) -> int:
    """Run from plain config values (what Hydra resolved); returns the exit status. SIGTERM (a
    cluster's time limit or preemption) is handled as Ctrl-C is, and always saves the newest state
    whose metrics are logged; so is submitit's preemption signal, after which submitit requeues
    the job (system/requeue.py)."""
    # submitit's own handler kept, whatever its signal
    with requeue.preemption_as_interrupt(), sigterm_as_interrupt():
        try:
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
    try:
        asked = request(values)
    except UsageError as e:
        return report_usage(e)
    except Exception as e:  # noqa: BLE001  the boundary: a bug, not bad input
        return report_bug(e)
    cfg, run_dir = asked.cfg, asked.run_dir
    named = any(
        (values.get("ppo") or {}).get(k) is not None for k in ("total_env_steps", "batch_size")
    )
    # an env's own budget is not the user's to round
    if named and (note := rounded_budget(cfg)) and devices.is_main():
        print(note, file=sys.stderr)
    compilation_cache.enable(compilation_cache.folder(values.get("compilation_cache")))
    # what stays if the run goes again before its first update
    existed = paths.existing_part(asked.out_dir)
    # a folder made by this call (not a resumed or requeued run's); a checkpoint to go on from
    made = resume = False
    try:
        if run_dir is None:
            if devices.is_main():
                run_dir = requeued_run(asked.out_dir, cfg)
                if run_dir is None:
                    run_dir, made = new_run_dir(asked.out_dir, asked.name, cfg), True
                    save_run_config(run_dir, cfg)
                    requeue.record(run_dir)
            # the folder process 0 made (or found), on every process
            run_dir = Path(devices.agree(str(run_dir)))
            # a requeued run's newest checkpoint, if it had one (process 0 looks: the look tidies the folder)
            resume = devices.agree_that(
                devices.is_main() and checkpoint.latest_update(run_dir) is not None
            )
        else:
            resume = True
            if asked.longer and devices.is_main():
                save_run_config(run_dir, cfg)  # the budget it now trains to
    except Exception as e:  # noqa: BLE001  the boundary: a full disk or read-only folder, else a bug
        return (
            report_machine(e, run_dir or asked.out_dir)
            if machine_refused(e)
            else report_bug(e, run_dir)
        )
    try:
        train(cfg, run_dir, resume=resume)
    # found before the first update (a program that cannot fit): a new folder goes again
    except UsageError as e:
        if (
            made
            and run_dir.is_dir()
            and {p.name for p in run_dir.iterdir()} <= {CONFIG_YAML, requeue.JOB_JSON}
        ):
            paths.unmake(run_dir, existed)
        return report_usage(e)
    # the newest complete checkpoint stays; resume from it
    except checkpoint.CheckpointWriteError as e:
        print(f"error: {e}", file=sys.stderr)
        return 1
    # Ctrl-C (SIGTERM): advance saved a checkpoint if one was due, and its writes are done
    except KeyboardInterrupt as e:
        good = checkpoint.latest_update(run_dir)
        saved = f"checkpoint at update {good}" if good else "no checkpoint yet"
        # submitit's signal: its own handler requeues the job and exits
        if isinstance(e, requeue.Preempted):
            return requeue.hand_over(e, run_dir, saved)
        stopped = "terminated (SIGTERM)" if isinstance(e, Terminated) else "interrupted"
        print(
            f"{stopped}; {saved}; go on with: python -m hintsjax.run resume={run_dir}",
            file=sys.stderr,
        )
        return TERMINATED if isinstance(e, Terminated) else INTERRUPTED
    except NonFiniteError as e:  # its checkpoints were all written before it went non-finite
        good = checkpoint.latest_update(run_dir)  # read once the background writes are done
        if devices.is_main():
            (run_dir / NONFINITE_JSON).write_text(
                json.dumps({**e.found, "last_good_checkpoint": good}) + "\n"
            )
        print(
            f"error: {e}; last good checkpoint: {f'update {good}' if good else 'none'} ({run_dir})",
            file=sys.stderr,
        )
        return 1
    except Exception as e:  # noqa: BLE001  the boundary: the machine's refusals; else a bug, its traceback kept in the run folder
        return report_machine(e, run_dir) if machine_refused(e) else report_bug(e, run_dir)
    return 0


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
    --help: the registries' choices, the settings with their help, then Hydra's page of the config."""
    if {"-h", "--help"} & set(sys.argv[1:]):
        print(f"{__doc__.strip()}\n\n{choices.text()}\n\n{schema.help_text()}\n")
    overrides.check_overrides(sys.argv[1:])
    if overrides.asks_only_for_warp(sys.argv[1:]):
        # nothing under MuJoCo Warp repeats bit for bit; they only cost speed
        xla_flags.drop_determinism()
    overrides.check_sweep(sys.argv[1:], request)
    _hydra_main()  # exits itself with a run's non-zero status
    return 0


def main() -> None:
    sys.exit(checked_main())


if __name__ == "__main__":
    main()
