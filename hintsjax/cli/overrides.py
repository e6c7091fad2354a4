"""`python -m hintsjax.run`'s arguments, checked before Hydra sees them.

Hydra answers a bad argument with several lines and exit 1, and a sweep (`-m`) runs its jobs
one after another, so a bad value in the third job fails after two have trained. Here every
argument is read first: a key that is no setting, an override Hydra's grammar cannot read,
`+key` for a key that exists or `~key`, an unknown launcher; and a sweep is expanded into its
jobs (Hydra's own basic sweeper's order), each job's values given to `check` before the first
job starts. Each problem is a `UsageError` (one line, exit 2) and nothing is written.
"""

from __future__ import annotations

import copy
import difflib
import importlib.util
from pathlib import Path
from typing import Any, Callable

import yaml
from hydra._internal.core_plugins.basic_sweeper import BasicSweeper
from hydra.core.override_parser.overrides_parser import OverridesParser
from hydra.errors import OverrideParseException

from hintsjax.system.errors import UsageError
from hintsjax.settings import schema

# Hydra's own flags that take the next argument as their value.
HYDRA_VALUE_FLAGS = {
    "--config-name",
    "-cn",
    "--config-path",
    "-cp",
    "--config-dir",
    "-cd",
    "--cfg",
    "-c",
    "--package",
    "-p",
    "--experimental-rerun",
}
MULTIRUN_FLAGS = {"-m", "--multirun"}

# Hydra's launchers that run a sweep's jobs elsewhere: the package that provides them (the cluster
# extra).
LAUNCHERS = {
    "submitit_slurm": "hydra_plugins.hydra_submitit_launcher",
    "submitit_local": "hydra_plugins.hydra_submitit_launcher",
    "basic": "hydra._internal.core_plugins.basic_launcher",
}
GRAMMAR = "https://hydra.cc/docs/advanced/override_grammar/basic"
# settings whose value is a list: key=[a,b]
LIST_KEYS = {"eval_variants", "ppo.hidden", "gail.disc_hidden"}
# names, paths
TEXT_KEYS = {"name", "out_dir", "resume", "expert", "hints_from", "hint_source", "eval_hint_source"}


# Hydra's own sections of the run command's config: no log files or output folders of its own (a run
# makes its folder), a sweep's multirun.yaml in out_dir.
HYDRA_SECTIONS = {
    "defaults": [
        "_self_",
        {"override hydra/hydra_logging": "disabled"},
        {"override hydra/job_logging": "disabled"},
    ],
    "hydra": {
        "output_subdir": None,
        "run": {"dir": "."},
        "sweep": {"dir": "${out_dir}", "subdir": "."},
    },
}


def defaults() -> dict[str, Any]:
    """What Hydra hands over for every key the command line left alone
    (schema.command_line_defaults)."""
    return schema.command_line_defaults()


def hydra_config() -> dict[str, Any]:
    """The run command's config as Hydra's ConfigStore holds it: the settings and Hydra's
    sections."""
    return {**defaults(), **copy.deepcopy(HYDRA_SECTIONS)}


def config_keys() -> list[str]:
    """Every key the command line accepts (nested ones as section.key)."""
    return schema.keys()


def check_launcher(name: str) -> None:
    """UsageError in one line for a launcher Hydra does not have here (not one of LAUNCHERS, or its
    plugin not installed)."""
    if name not in LAUNCHERS:
        raise UsageError(f"unknown hydra/launcher {name!r}; valid choices: {', '.join(LAUNCHERS)}")
    if (
        importlib.util.find_spec(LAUNCHERS[name].rsplit(".", 1)[0]) is None
        or importlib.util.find_spec(LAUNCHERS[name]) is None
    ):
        raise UsageError(
            f"hydra/launcher={name} needs hydra-submitit-launcher: pip install -e '.[cluster]'"
        )


def overrides_of(argv: list[str]) -> list[str]:
    """The `key=value` arguments of argv, Hydra's flags (and their values) left out."""
    found, skip = [], False
    for arg in argv:
        if skip or arg.startswith("-"):
            skip = arg in HYDRA_VALUE_FLAGS and not skip
            continue
        found.append(arg)
    return found


def _is_hydras(key: str) -> bool:
    return key == "hydra" or key.startswith(("hydra.", "hydra/"))


def check_overrides(argv: list[str]) -> None:
    """UsageError for an argument that is not `key=value` with a known key, naming the closest
    valid key (Hydra would print seven lines and exit 1), or that Hydra's grammar cannot read."""
    keys = config_keys()
    overrides = overrides_of(argv)
    for arg in overrides:
        if "=" not in arg and not arg.startswith("~"):
            raise UsageError(
                f"unexpected argument {arg!r}: give key=value pairs (e.g. env=pendulum)"
            )
        key, _, value = arg.partition("=")
        if key.startswith("~"):
            raise UsageError(
                f"{arg!r} would delete a setting; give {key.lstrip('~')}=<value> instead"
            )
        if key.startswith("+") and not key.startswith("++") and key.lstrip("+") in keys:
            raise UsageError(f"{arg!r} adds a key that exists already; write {arg.lstrip('+')}")
        key = key.lstrip("+")
        if key == "hydra/launcher":
            check_launcher(value)
        if _is_hydras(key):
            continue
        if key not in keys:
            close = difflib.get_close_matches(key, keys, n=1)
            hint = f"did you mean {close[0]!r}? " if close else ""
            raise UsageError(
                f"unknown config key {key!r}; {hint}valid: "
                f"{', '.join(k for k in keys if '.' not in k)}, ppo.<key>, dagger.<key>, "
                "gail.<key> (docs/settings.md)"
            )
    parsed = parse(overrides)
    if not MULTIRUN_FLAGS & set(argv):
        for arg, override in zip(overrides, parsed, strict=True):
            if override.is_sweep_override() and not _is_hydras(override.key_or_group):
                raise UsageError(ambiguous(arg))


def ambiguous(arg: str) -> str:
    """The one line for a sweep's value given to one run (Hydra's five-line "Ambiguous value"):
    what it most likely meant (a list for a list-valued key, `+` for hints, a quoted name or
    path), and the sweep."""
    key, _, value = arg.partition("=")
    key = key.lstrip("+")
    if key in LIST_KEYS and "(" not in value:
        meant = f"for a list write {key}=[{value}]"
    elif key == "hint" and "(" not in value:
        meant = f"for several hints write hint={value.replace(',', '+')}"
    elif key in TEXT_KEYS:
        meant = f"for one string quote it: {key}='{value}'"
    else:
        return f"{arg!r} gives several values to one run; for a sweep add -m"
    return f"{arg!r} gives several values to one run: {meant}; for a sweep add -m"


def parse(overrides: list[str]) -> list[Any]:
    """Hydra's parse of the overrides (`Override` objects); UsageError in one line naming the
    argument Hydra's grammar cannot read."""
    parser, parsed = OverridesParser.create(), []
    for arg in overrides:  # one at a time, so the line can name the one that fails
        try:
            parsed += parser.parse_overrides([arg])
        except OverrideParseException as e:
            lines = [
                line.strip()
                for line in str(e).splitlines()[:-1]
                if line.strip() and line.strip() != "^"
            ]
            # not its list of tokens
            reason = lines[-1].split(" expecting ")[0] if lines else "Hydra's grammar"
            raise UsageError(
                f"cannot read {arg!r} ({reason[:120]}); quote a value with other characters, "
                f"key='value' ({GRAMMAR})"
            ) from None
    return parsed


def _set(values: dict[str, Any], key: str, value: Any) -> None:
    *sections, last = key.split(".")
    for section in sections:
        values = values.setdefault(section, {})
    values[last] = value


def sweep_jobs(argv: list[str]) -> list[tuple[str, dict[str, Any]]]:
    """A sweep's jobs (`-m`; [] for a single run) in the order Hydra's basic sweeper runs them:
    (the job's swept values as one string, the values main_from_values would get)."""
    if not MULTIRUN_FLAGS & set(argv):
        return []
    overrides = [o for o in parse(overrides_of(argv)) if not _is_hydras(o.key_or_group)]
    swept = {o.key_or_group for o in overrides if o.is_sweep_override()}
    base, jobs = defaults(), []  # copied for each job
    for batch in BasicSweeper.split_arguments(overrides, None):
        for job in batch:
            values, label = copy.deepcopy(base), []
            for override in parse(job):
                _set(values, override.key_or_group, override.value())
                if override.key_or_group in swept:
                    label.append(override.input_line)
            jobs.append((" ".join(label), values))
    return jobs


def jobs_values(argv: list[str]) -> list[dict[str, Any]]:
    """The values main_from_values gets for each job: a sweep's jobs, or the one run."""
    jobs = [values for _, values in sweep_jobs(argv)]
    if jobs or MULTIRUN_FLAGS & set(argv):
        return jobs
    values = copy.deepcopy(defaults())
    for override in parse(overrides_of(argv)):
        if not _is_hydras(override.key_or_group):
            _set(values, override.key_or_group, override.value())
    return [values]


def asks_only_for_warp(argv: list[str]) -> bool:
    """Whether every job steps its physics with MuJoCo Warp (`physics=warp`; `auto` for an env
    that prefers Warp, on a machine that looks like an NVIDIA GPU's; or a resumed run's
    config.yaml says so), read without starting JAX."""
    from hintsjax import envs

    def physics(values: dict[str, Any]) -> Any:
        if values.get("resume") is None:
            physics = values.get("physics")
            return envs.WARP if envs.likely_warp(str(values.get("env")), physics) else physics
        try:
            return yaml.safe_load((Path(str(values["resume"])) / "config.yaml").read_text()).get(
                "physics"
            )
        except (OSError, UnicodeDecodeError, yaml.YAMLError, AttributeError):
            return None  # checked_request() says what is wrong with the folder

    jobs = jobs_values(argv)
    return bool(jobs) and all(physics(values) == "warp" for values in jobs)


def check_sweep(argv: list[str], check: Callable[[dict[str, Any]], Any]) -> None:
    """`check` (which raises UsageError) on every job of a sweep before the first one runs; the
    error names the job."""
    for overrides, values in sweep_jobs(argv):
        try:
            check(values)
        except UsageError as e:
            raise UsageError(f"sweep job '{overrides}': {e}") from None
