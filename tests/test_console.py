"""The `hintsjax` console script (hintsjax/console.py): each subcommand is its module's
`python -m`, a missing or unknown one is one line naming the commands (exit 2), and the --help
of run, generator, rank, evaluate and video lists every env with its hints, every agent and scheme."""

from __future__ import annotations

import subprocess
import sys
import tomllib
from pathlib import Path

import pytest
from test_cli import SHIPPED_ENVS

from hintsjax.models.agents import AGENTS
from hintsjax.models.conditioning import SCHEMES
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.cli import choices
from hintsjax import console, envs

ROOT = Path(__file__).resolve().parents[1]


def command(*args: str, module: str = "hintsjax.console") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", module, *args], cwd=ROOT, capture_output=True, text=True, timeout=300)


def test_pyproject_installs_the_console_script():
    scripts = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["scripts"]
    assert scripts == {"hintsjax": "hintsjax.console:main"}


def test_help_lists_every_command_and_each_is_a_module_run_as_main():
    out = command("--help")
    assert out.returncode == 0
    listed = [line.split()[0] for line in out.stdout.splitlines() if line.startswith("  ")]
    assert listed == ["run", "evaluate", "video", "expert", "generator", "rank", "quickstart"] == list(console.COMMANDS)
    for name, c in console.COMMANDS.items():
        source = (ROOT / (c.module.replace(".", "/") + ".py")).read_text()
        assert c.module == f"hintsjax.{name}" and 'if __name__ == "__main__":' in source, name


def test_a_missing_or_unknown_command_is_one_line_naming_the_commands(capsys):
    assert console.main([]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: give a command: run, evaluate, video, expert, generator")
    assert console.main(["trian", "env=pendulum"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown command 'trian'; valid choices: evaluate, expert, generator" in err


def test_a_subcommand_is_its_module_with_the_rest_of_the_arguments(tmp_path):
    """The command's own one-line errors and exit statuses come back through the console script."""
    for args, err in [(["run", "env=nope"], "error: unknown env 'nope'; valid choices: acrobot, ant"),
                      (["evaluate", str(tmp_path / "missing")], f"error: no run folder at {tmp_path / 'missing'}\n"),
                      (["generator", "frames=two"], "error: frames must be int, got 'two'\n")]:
        out = command(*args)
        assert out.returncode == 2 and out.stderr.startswith(err) and out.stderr.count("\n") == 1, out.stderr[-500:]


def listed_choices(page: str) -> None:
    """Every shipped env with each of its hints (its default first), every agent and every scheme
    are on `page`."""
    for name in SHIPPED_ENVS:
        block = page[page.index(f"\n  {name}\n"):].splitlines()
        assert block[2].startswith("    hints:    "), block[:4]
        hints = block[2].removeprefix("    hints:    ").split(", ")
        assert hints[0] == f"{ENV_DEFAULTS[name]['hint']} (default)"
        assert sorted(h.removesuffix(" (default)") for h in hints) == envs.hint_names(name)
    assert f"agent:  {', '.join(AGENTS)}" in page and f"scheme: {', '.join(SCHEMES)}" in page
    assert "playground:<name>, brax:<name>" in page


def test_run_help_lists_the_choices_then_hydras_settings_both_ways():
    console_page, module_page = command("run", "--help"), command("--help", module="hintsjax.run")
    assert console_page.returncode == module_page.returncode == 0
    assert console_page.stdout == module_page.stdout
    page = console_page.stdout
    listed_choices(page)
    assert page.index("Choices") < page.index("== Config ==") and "starts_per_rollout: null" in page


@pytest.mark.parametrize("name", ["generator", "rank", "evaluate", "video", "expert", "quickstart"])
def test_each_tools_help_lists_its_settings_and_the_choices(name):
    out = command(name, "--help")
    assert out.returncode == 0 and out.stdout.startswith(f"usage: python -m hintsjax.{name}"), out.stderr[-500:]
    listed_choices(out.stdout)
    if name in ("generator", "rank"):
        assert "  env=pendulum" in out.stdout and "  seeds=" in out.stdout


def test_the_choices_follow_the_registries():
    page = choices.text()
    pendulum = page[page.index("\n  pendulum\n"):].splitlines()
    assert pendulum[2] == "    hints:    composite (default), angular_velocity, goal_distance, partial_state, state, torque"
    assert pendulum[3] == "    variants: swingup, swingto"
