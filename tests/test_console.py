"""The `hintsjax` console script (hintsjax/console.py): each subcommand is its module's
`python -m`, a missing or unknown one is one line naming the commands (exit 2), and the --help
of run, generator, rank, evaluate and video lists every env with its hints, every agent and
scheme."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from test_cli import SHIPPED_ENVS

import command_runs

from hintsjax.models.agents import AGENTS
from hintsjax.models.conditioning import SCHEMES
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.cli import choices
from hintsjax import console, envs

ROOT = Path(__file__).resolve().parents[1]


def command(*args: str, module: str = "hintsjax.console") -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", module, *args], cwd=ROOT, capture_output=True, text=True, timeout=300
    )


TOOLS = ("generator", "rank", "evaluate", "video", "expert", "quickstart")
MISSING = "{missing}"  # in a case's arguments: a folder that does not exist


@pytest.fixture(scope="module")
def console_runs(tmp_path_factory):
    """`python -m hintsjax.console <args>` from the checkout's root for each args this file
    checks, through one interpreter start (tests/command_runs.py: a child forked per case runs
    the console script's module, which runs the subcommand's, as `python -m` does): args as a
    string -> (exit status, stdout, stderr), and the missing folder's path."""
    root = tmp_path_factory.mktemp("console")
    missing = str(root / "missing")
    cases = [
        "--help",
        "run env=nope",
        f"evaluate {MISSING}",
        "generator frames=two",
        "run --help",
        *(f"{name} --help" for name in TOOLS),
    ]
    done = command_runs.outcomes(
        "hintsjax.console",
        [c.replace(MISSING, missing).split() for c in cases],
        root,
        runs=tuple(c.module for c in console.COMMANDS.values()),
        cwd=ROOT,
    )
    return {c: out[:3] for c, out in zip(cases, done, strict=True)}, missing


def test_pyproject_installs_the_console_script():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"hintsjax": "hintsjax.console:main"}


def test_help_lists_every_command_and_each_is_a_module_run_as_main(console_runs):
    returncode, stdout, _ = console_runs[0]["--help"]
    assert returncode == 0
    listed = [line.split()[0] for line in stdout.splitlines() if line.startswith("  ")]
    assert (
        listed
        == ["run", "evaluate", "video", "expert", "generator", "rank", "quickstart"]
        == list(console.COMMANDS)
    )
    for name, c in console.COMMANDS.items():
        source = (ROOT / (c.module.replace(".", "/") + ".py")).read_text()
        assert c.module == f"hintsjax.{name}" and 'if __name__ == "__main__":' in source, name


def test_a_missing_or_unknown_command_is_one_line_naming_the_commands(capsys):
    assert console.main([]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith(
        "error: give a command: run, evaluate, video, expert, generator"
    )
    assert console.main(["trian", "env=pendulum"]) == 2
    err = capsys.readouterr().err
    assert (
        err.count("\n") == 1
        and "unknown command 'trian'; valid choices: evaluate, expert, generator" in err
    )


def test_a_subcommand_is_its_module_with_the_rest_of_the_arguments(console_runs):
    """The command's own one-line errors and exit statuses come back through the console script."""
    outcomes, missing = console_runs
    for args, err in [
        ("run env=nope", "error: unknown env 'nope'; valid choices: acrobot, ant"),
        (f"evaluate {MISSING}", f"error: no run folder at {missing}\n"),
        ("generator frames=two", "error: frames must be int, got 'two'\n"),
    ]:
        returncode, _, stderr = outcomes[args]
        assert returncode == 2 and stderr.startswith(err) and stderr.count("\n") == 1, stderr[-500:]


def listed_choices(page: str) -> None:
    """Every shipped env with each of its hints (its default first), every agent and every scheme
    are on `page`."""
    for name in SHIPPED_ENVS:
        block = page[page.index(f"\n  {name}\n") :].splitlines()
        assert block[2].startswith("    hints:    "), block[:4]
        hints = block[2].removeprefix("    hints:    ").split(", ")
        assert hints[0] == f"{ENV_DEFAULTS[name]['hint']} (default)"
        assert sorted(h.removesuffix(" (default)") for h in hints) == envs.hint_names(name)
    assert f"agent:  {', '.join(AGENTS)}" in page and f"scheme: {', '.join(SCHEMES)}" in page
    assert "playground:<name>, brax:<name>" in page


def test_run_help_lists_the_choices_then_hydras_settings_both_ways(console_runs):
    (returncode, page, _), module_page = (
        console_runs[0]["run --help"],
        command("--help", module="hintsjax.run"),
    )
    assert returncode == module_page.returncode == 0
    assert page == module_page.stdout
    listed_choices(page)
    assert page.index("Choices") < page.index("== Config ==") and "starts_per_rollout: null" in page


@pytest.mark.parametrize("name", TOOLS)
def test_each_tools_help_lists_its_settings_and_the_choices(name, console_runs):
    returncode, stdout, stderr = console_runs[0][f"{name} --help"]
    assert returncode == 0 and stdout.startswith(f"usage: python -m hintsjax.{name}"), stderr[-500:]
    listed_choices(stdout)
    if name in ("generator", "rank"):
        assert "  env=pendulum" in stdout and "  seeds=" in stdout


def test_the_choices_follow_the_registries():
    page = choices.text()
    pendulum = page[page.index("\n  pendulum\n") :].splitlines()
    assert pendulum[2] == (
        "    hints:    composite (default), angular_velocity, goal_distance, partial_state, "
        "state, torque"
    )
    assert pendulum[3] == "    variants: swingup, swingto"
