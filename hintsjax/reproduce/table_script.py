"""A table script's command line: what the script declares (`TableScript`) and its one entry point
(`table_main`).

A table script of experiments/ (classic_control.py, locomotion.py, car_racing.py, playground.py)
declares its runs, the tables they make and its reports, and calls `table_main`, which trains the
runs of --envs (hintsjax.reproduce.sweep), or with --report archives the finished runs and then
writes the tables (with report.py's readers), or --archive only archives them, or --pool pools a
row's seed parts (pool.py); where the script
has them, --learners-report FILE and a mode of its own.
"""

from __future__ import annotations

import argparse
import os
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from hintsjax.reproduce import archive
from hintsjax.reproduce.archive import archive_runs
from hintsjax.reproduce.pool import PoolError, pool_runs
from hintsjax.reproduce.sweep import sweep
from hintsjax.reproduce.sweep_settings import add_settings, chosen_settings
from hintsjax.system.errors import command
from hintsjax.system.refusals import writing_to


@dataclass(frozen=True)
class TableScript:
    """What a table script declares. Each of its `tables` is a sweep (its name in
    runs/sweeps.jsonl) and gives the run ids `env/label` of the envs it is given. With several,
    --table picks the one to train, and a run that an earlier table also trains counts for that
    one: once finished, a later table's sweep leaves it out (Table 4's fc row is Table 2's)."""

    description: str  # --help's opening line
    default_runs: str  # --runs' default
    envs: tuple[str, ...]  # --envs' choices; all of them by default
    tables: dict[int | str, Callable[[list[str]], list[str]]]
    report: Callable[[Path, bool], None]  # --report: (runs, --force)
    # --learners-report FILE: (runs, envs, FILE, --force)
    learners_report: Callable[[Path, list[str], Path, bool], None] | None = None
    seeds: int = 5  # --seeds' default
    # the script's own options
    extra_arguments: Callable[[argparse.ArgumentParser], None] | None = None
    # the script's own mode, tried first (before the parent keeps off the GPU); True when it ran
    extra_mode: Callable[[argparse.ArgumentParser, argparse.Namespace], bool] | None = None

    def run_ids(self) -> list[str]:
        """The runs of every env and table, each once: those --report and --archive archive."""
        return list(
            dict.fromkeys(
                r for env in self.envs for ids in self.tables.values() for r in ids([env])
            )
        )


def add_arguments(
    parser: argparse.ArgumentParser, runs: str, envs: tuple[str, ...], seeds: int = 5
) -> None:
    """The options every sweep script takes (`runs`: the default runs folder; `seeds`: the default
    seeds per run)."""
    parser.add_argument(
        "--report", action="store_true", help="only write the result tables and curves"
    )
    parser.add_argument(
        "--force",
        action="store_true",
        help="with --report or --learners-report: rewrite a table even where it would blank cells "
        "the committed one fills",
    )
    parser.add_argument(
        "--envs", default=",".join(envs), help=f"comma-separated subset of {', '.join(envs)}"
    )
    parser.add_argument("--runs", type=Path, default=Path(runs))
    parser.add_argument("--workers", type=int, default=1, help="configurations trained at once")
    parser.add_argument("--seeds", type=int, default=seeds, help=f"seeds per run (default {seeds})")
    parser.add_argument(
        "--alone",
        action="store_const",
        const=1,
        default=0,
        dest="group_size",
        help="train every run in its own program (default: runs that share shapes train as one "
        "group)",
    )
    parser.add_argument(
        "--group-size",
        type=int,
        default=0,
        metavar="N",
        help="at most N runs per group (default: no limit), e.g. so that each group ends within a "
        "time limit",
    )
    parser.add_argument(
        "--smoke", action="store_true", help="tiny budgets: check the plumbing on a CPU"
    )
    parser.add_argument(
        "--gpus",
        type=lambda s: tuple(g for g in s.split(",") if g),
        default=(),
        metavar="IDS",
        help="comma-separated CUDA device ids; each worker gets the least busy one to itself",
    )
    parser.add_argument(
        "--launch-until",
        type=float,
        default=float("inf"),
        metavar="SECONDS",
        help="start no run after this many seconds; running ones finish (for time-limited "
        "machines)",
    )
    parser.add_argument(
        "--only",
        type=lambda s: tuple(x for x in s.split(",") if x),
        default=(),
        metavar="LABELS",
        help="comma-separated run labels (e.g. ppo_rgb,hints-fc-speed): train only these of the "
        "table's runs",
    )
    parser.add_argument(
        "--experts",
        type=lambda s: Path(s).absolute(),
        default=None,
        help="where expert_ppo runs export their expert and dagger/gail read it "
        "(default: the package's hintsjax/experts/<env>)",
    )
    add_settings(parser)


def chosen_envs(
    parser: argparse.ArgumentParser, args: argparse.Namespace, envs: tuple[str, ...]
) -> list[str]:
    """The envs of --envs; exit 2 naming the valid ones on an unknown env, --workers or --seeds < 1,
    --group-size < 0."""
    names = [n.strip() for n in args.envs.split(",") if n.strip()]
    unknown = [n for n in names if n not in envs]
    if unknown:
        parser.exit(2, f"error: unknown env {unknown}; valid choices: {', '.join(envs)}\n")
    for option in ("workers", "seeds"):
        if getattr(args, option) < 1:
            parser.exit(2, f"error: --{option} must be at least 1, got {getattr(args, option)}\n")
    if args.group_size < 0:
        parser.exit(
            2,
            f"error: --group-size must be at least 1 (or 0 for no limit), got {args.group_size}\n",
        )
    return names


def chosen_runs(
    parser: argparse.ArgumentParser, args: argparse.Namespace, run_ids: list[str]
) -> list[str]:
    """The runs of --only (all when not given); exit 2 naming the valid labels on an unknown one."""
    if not args.only:
        return run_ids
    labels = list(dict.fromkeys(r.split("/")[1] for r in run_ids))
    unknown = [label for label in args.only if label not in labels]
    if unknown:
        parser.exit(2, f"error: unknown run label {unknown}; valid choices: {', '.join(labels)}\n")
    return [r for r in run_ids if r.split("/")[1] in args.only]


def table_main(script: TableScript) -> None:
    """A table script's command line: train the runs of --envs (of --table's table, where it has
    several), or --report or --archive (only archive the finished runs; every report archives
    first), and where the script has them, --learners-report FILE (the learner rows at any seed
    count) and its own mode. Behind the commands' boundary (hintsjax.system.errors.command): a
    results folder it cannot write is one line, exit 1, as for every command."""
    status = _table_command(script)
    if status:
        sys.exit(status)


@command
def _table_command(script: TableScript) -> int:
    _table_main(script)
    return 0


def _table_main(script: TableScript) -> None:
    tables = list(script.tables)
    parser = argparse.ArgumentParser(description=script.description)
    if len(tables) > 1:  # classic_control.py's --table 2 or 4: the type of the tables' names
        parser.add_argument(
            "--table", type=type(tables[0]), choices=tables, help="train the runs of this table"
        )
    add_arguments(parser, script.default_runs, script.envs, script.seeds)
    if script.learners_report is not None:
        parser.add_argument(
            "--learners-report",
            type=Path,
            default=None,
            metavar="FILE",
            help="write the learner rows of --envs from --runs (any seed count) with IQM and "
            "orderings",
        )
    parser.add_argument(
        "--archive",
        action="store_true",
        help="only copy what the reports need of the finished runs into experiments/results/runs "
        "(a few hundred KB a run: what a GPU machine sends back)",
    )
    parser.add_argument(
        "--pool",
        type=lambda s: [Path(x) for x in s.split(",") if x],
        default=None,
        metavar="DIRS",
        help="comma-separated --runs folders, each a part of the rows' seeds (trained with --set "
        "seed=K): only pool each run finished in all of them into one archived run of all their "
        "seeds, under --runs' name in experiments/results/runs (hintsjax/reproduce/pool.py)",
    )
    if script.extra_arguments is not None:
        script.extra_arguments(parser)
    args = parser.parse_args()
    if script.extra_mode is not None and script.extra_mode(parser, args):
        return
    os.environ["JAX_PLATFORMS"] = "cpu"  # the parent only reads configs; workers get the devices
    # the archive and the tables beside it: a write the machine refuses names them
    with writing_to(archive.ARCHIVE.parent):
        if _archive_or_report(script, parser, args):
            return
    table = args.table if len(tables) > 1 else tables[0]
    if table is None:
        parser.exit(2, f"error: give {', '.join(f'--table {t}' for t in tables)} or --report\n")
    names = chosen_envs(parser, args, script.envs)
    ids = chosen_runs(parser, args, script.tables[table](names))
    earlier = {r for t in tables[: tables.index(table)] for r in script.tables[t](names)}
    ids = [r for r in ids if r not in earlier or not (args.runs / r / "eval.json").exists()]
    sweep(
        args.runs,
        ids,
        args.workers,
        args.seeds,
        table,
        args.smoke,
        args.launch_until,
        args.experts,
        args.gpus,
        args.group_size,
        chosen_settings(parser, args),
    )


def _archive_or_report(
    script: TableScript, parser: argparse.ArgumentParser, args: argparse.Namespace
) -> bool:
    """--archive, --pool, --learners-report or --report, where one is given (True), checked
    before anything is written."""
    kept = archive.ARCHIVE / args.runs.name
    if args.archive:
        if not args.runs.is_dir():
            parser.exit(2, f"error: no runs folder at {args.runs}: nothing to archive\n")
        done = archive_runs(args.runs, script.run_ids())
        print(f"archived {len(done)} finished run(s) of {args.runs} in {kept}: {', '.join(done)}")
        return True
    reads = args.report or getattr(args, "learners_report", None)
    if reads and not args.runs.is_dir() and not kept.is_dir():
        parser.exit(2, f"error: no runs folder at {args.runs} and no archived one at {kept}\n")
    if args.pool is not None:
        try:
            done = pool_runs(args.pool, args.runs, script.run_ids())
        except PoolError as e:
            parser.exit(2, f"error: {e}\n")
        print(
            f"pooled {len(done)} run(s) finished in every part of {', '.join(map(str, args.pool))} "
            f"into {kept}: {', '.join(done) or 'none'}"
        )
        return True
    if getattr(args, "learners_report", None):
        archive_runs(args.runs, script.run_ids())
        script.learners_report(
            args.runs, chosen_envs(parser, args, script.envs), args.learners_report, args.force
        )
        return True
    if args.report:
        archive_runs(args.runs, script.run_ids())
        script.report(args.runs, args.force)
        return True
    return False
