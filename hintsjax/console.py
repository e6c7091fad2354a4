"""`hintsjax <command> [arguments]`: the console script (pyproject's [project.scripts]), one
subcommand per command module, each run exactly as `python -m hintsjax.<command>` runs it.

Each command takes the arguments its kind expects, and `--help` lists them:
  run                    Hydra's `key=value` settings (docs/settings.md) (`-m` sweeps a comma list)
  generator, rank        `key=value` settings of their own dataclass (hintsjax.cli.arguments)
  evaluate, video, expert, quickstart
                         a run folder and `--flags` (argparse), as tools on folders take
"""

from __future__ import annotations

import runpy
import sys
from dataclasses import dataclass

from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.system.errors import UsageError, command

PROG = "hintsjax"


@dataclass(frozen=True)
class Command:
    """A subcommand: the module whose `python -m` it is, and what it does (one line)."""

    module: str
    about: str


COMMANDS = {
    "run": Command("hintsjax.run", "train an agent: env=, agent=, scheme=, hint=, ppo.<key>= ..."),
    "evaluate": Command("hintsjax.evaluate", "evaluate a run folder's agent on its env's variants"),
    "video": Command(
        "hintsjax.video", "a GIF of one episode of a run folder's agent, its hint drawn"
    ),
    "expert": Command(
        "hintsjax.expert", "export a state PPO run's best seed as an expert for dagger and gail"
    ),
    "generator": Command(
        "hintsjax.generator", "train a learned hint generator (hint_source=<its folder>)"
    ),
    "rank": Command("hintsjax.rank", "rank candidate hints of an env before training with them"),
    "quickstart": Command(
        "hintsjax.quickstart", "a first agent on CPU beside a random policy, with its GIF"
    ),
}


def usage() -> str:
    """The console script's --help page: its commands, one line each."""
    width = max(map(len, COMMANDS))
    return "\n".join(
        [
            (
                f"usage: {PROG} <command> [arguments]   "
                f"({PROG} <command> --help: that command's arguments)"
            ),
            "",
            *(f"  {name:<{width}}  {c.about}" for name, c in COMMANDS.items()),
            "",
            f"{PROG} <command> is python -m hintsjax.<command>.",
        ]
    )


@command
def main(argv: list[str] | None = None) -> int:
    """Run the command that argv names with the rest of argv, as `python -m hintsjax.<command>`
    runs it; its exit status. UsageError naming the commands for a missing or unknown one."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if not argv:
        raise UsageError(f"give a command: {', '.join(COMMANDS)} (see {PROG} --help)")
    if argv[0] in ("-h", "--help"):
        print(usage())
        return 0
    try:
        picked = choose("command", argv[0], COMMANDS)
    except ChoiceError as e:
        raise UsageError(f"{e} (see {PROG} --help)") from None
    return run_module(picked.module, argv[1:])


def run_module(module: str, args: list[str]) -> int:
    """`python -m <module> <args>` in this process: the module run as __main__ (as Hydra
    expects of its entry) with sys.argv set as `python -m` sets it; its exit status."""
    saved = sys.argv
    sys.argv = [module, *args]  # runpy puts the module's file in sys.argv[0]
    try:
        runpy.run_module(module, run_name="__main__", alter_sys=True)
    except SystemExit as e:
        if e.code is None or isinstance(e.code, int):
            return e.code or 0
        print(e.code, file=sys.stderr)  # what Python does with a message for an exit status
        return 1
    finally:
        sys.argv = saved
    return 0


if __name__ == "__main__":
    sys.exit(main())
