"""From plain values to a validated RunConfig, and back: the layers (the dataclass defaults, the
env's, the env's for the agent, the command line), their types, and a run folder's config.yaml
written and read back.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Mapping

import yaml

from hintsjax import envs
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.system import paths
from hintsjax.system.checks import require_int32
from hintsjax.system.errors import UsageError
from hintsjax.settings.config import RunConfig, SECTIONS
from hintsjax.settings.env_defaults import ENV_DEFAULTS, stack_layers
from hintsjax.settings import schema


CONFIG_YAML = "config.yaml"  # a run folder's resolved config


def _fields(cls) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


TUPLES = {"hidden", "disc_hidden", "eval_variants"}  # list-valued keys (YAML and Hydra give lists)


def _as_tuple(key: str, value: Any) -> tuple:
    """A list-valued setting as a tuple: variant names (one name alone is a list of one), or
    layer widths (whole positive numbers, at least one); UsageError naming `key` otherwise."""
    if key == "eval_variants":
        return (value,) if isinstance(value, str) else tuple(str(v) for v in value)
    if not isinstance(value, (list, tuple)):
        raise UsageError(f"{key} must be a list of layer widths such as [256,256], got {value!r}")
    if not value or not all(isinstance(w, int) and not isinstance(w, bool) for w in value):
        raise UsageError(f"{key} must be a list of at least one whole number, got {list(value)}")
    return tuple(value)


def run_config(values: Mapping[str, Any], resolved: bool = False) -> RunConfig:
    """Build and validate a RunConfig from plain values (e.g. Hydra's), applying env defaults.

    Layers, later winning: the dataclass defaults, the env's defaults (ENV_DEFAULTS[env]), the
    env's defaults for this agent (ENV_DEFAULTS[env]["agents"][agent]), then `values`. A value of
    None takes the layer below. With `resolved`, `values` is a run's saved config (to_dict): taken
    as it is, None included, over the dataclass defaults only, so that today's env defaults do not
    change what a run was trained with (a key it predates takes the dataclass default).
    """
    values = dict(values)
    env = values.get("env") or RunConfig.env
    try:
        defaults = dict(choose("env", env, ENV_DEFAULTS))
    except ChoiceError as e:
        raise UsageError(str(e)) from None
    if values.get("hints_from") is not None:
        values["hints_from"] = hint_file(str(values["hints_from"]))
    per_agent = defaults.pop("agents", {})
    _check_env_layers(env, [defaults, *per_agent.values()])
    if resolved:
        merged = {
            k: dict(v) if k in SECTIONS and isinstance(v, Mapping) else v for k, v in values.items()
        }
        # a run saved before the setting was stepped by MJX's JAX solver
        merged.setdefault("physics", envs.JAX)
    else:
        merged = stack_layers(
            defaults, per_agent.get(values.get("agent") or RunConfig.agent, {}), values
        )
    unknown = {k for k in merged if k not in SECTIONS} - _fields(RunConfig)
    unknown |= {
        f"{name}.{k}"
        for name, cls in SECTIONS.items()
        for k in merged.get(name, {})
        if k not in _fields(cls)
    }
    if unknown:
        raise UsageError(f"unknown config keys {sorted(unknown)}")
    try:
        for prefix, section in [
            ("", merged),
            *((f"{name}.", merged.get(name, {})) for name in SECTIONS),
        ]:
            for k in TUPLES & set(section):
                section[k] = _as_tuple(prefix + k, section[k])
        sections = {name: cls(**merged.pop(name, {})) for name, cls in SECTIONS.items()}
        cfg = RunConfig(**merged, **sections)
        _check_types(cfg)
    except UsageError:
        raise
    except (TypeError, ValueError) as e:
        raise UsageError(f"bad config value: {e}") from None
    cfg = cfg.validate()
    # what the run steps with, kept
    return dataclasses.replace(cfg, physics=envs.resolve_physics(cfg.env, cfg.physics))


# The top-level settings the command line gives a value, not null (schema.command_line_defaults).
VALUED_ON_THE_COMMAND_LINE = {
    k for k, v in schema.command_line_defaults().items() if v is not None and k not in SECTIONS
}


def _check_env_layers(env: str, layers: list[Mapping[str, Any]]) -> None:
    """TypeError where an env's TRAINING sets a top-level setting that the command line gives a
    value (declare it `per_env` on its field): the command line's value would win over the env's
    there but not in run_config, so the two would train differently."""
    fixed = sorted({k for layer in layers for k in layer if k in VALUED_ON_THE_COMMAND_LINE})
    if fixed:
        raise TypeError(
            f"env {env}'s TRAINING sets {', '.join(fixed)}, which the command line gives a value; "
            "an env may set a section's settings and those declared per_env "
            "(hintsjax/settings/config.py)"
        )


def hint_file(source: str) -> str:
    """`hints_from`'s file or module loaded (its registered hints added): the absolute path of a
    file, so that a run folder's config finds it from elsewhere; UsageError if it does not
    import."""
    try:
        envs.load_hints(source)
    except envs.HintFileError as e:
        raise UsageError(str(e)) from None
    path = Path(source).expanduser()
    return str(path.resolve()) if source.endswith(".py") or path.exists() else source


def _check_types(cfg: RunConfig) -> None:
    """UsageError naming a setting of the wrong type, or an integer beyond JAX's int32 (every count,
    size and seed: `seed=99999999999999999999` overflowed only once a run folder was made)."""
    for prefix, obj in (("", cfg), *((f"{name}.", getattr(cfg, name)) for name in SECTIONS)):
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            kind = {"int": int, "float": (int, float), "bool": bool, "str": str}.get(str(f.type))
            if kind is not None and (
                not isinstance(value, kind) or (kind is int and isinstance(value, bool))
            ):
                raise UsageError(f"{prefix}{f.name} must be {f.type}, got {value!r}")
            if str(f.type).startswith(("int", "tuple[int")):
                require_int32(obj, (f.name,), prefix)


def to_dict(cfg: RunConfig) -> dict[str, Any]:
    """Plain nested dict (tuples as lists) of a RunConfig, for YAML."""

    def plain(x):
        if isinstance(x, tuple):
            return [plain(v) for v in x]
        if isinstance(x, dict):
            return {k: plain(v) for k, v in x.items()}
        return x

    return plain(dataclasses.asdict(cfg))


def save_run_config(run_dir: Path, cfg: RunConfig) -> None:
    """Write the resolved config into a run folder (what load_run_config reads back), whole or
    not at all (a resumed run that trains longer rewrites it)."""
    text = yaml.safe_dump(to_dict(cfg), sort_keys=False)
    paths.write_text_whole(Path(run_dir) / CONFIG_YAML, text)


# Settings added since runs were first saved whose absence means their default (`saved_may_lack` on
# their fields), so a saved config without them is complete.
OPTIONAL_IN_SAVED = schema.saved_may_lack()


def missing_keys(values: Mapping[str, Any]) -> list[str]:
    """The settings of today's RunConfig that a saved config (to_dict's layout) lacks."""
    missing = sorted(_fields(RunConfig) - set(SECTIONS) - OPTIONAL_IN_SAVED - set(values))
    return missing + [
        f"{name}.{k}"
        for name, cls in SECTIONS.items()
        for k in sorted(_fields(cls) - set(values.get(name) or {}))
        if f"{name}.{k}" not in OPTIONAL_IN_SAVED
    ]


def load_run_config(run_dir: Path, complete: bool = False) -> RunConfig:
    """The validated config a run folder was trained with. With `complete` (a run to go on with),
    a config that lacks any of today's settings is refused, not filled in with defaults: it was
    cut short, or written by an older hintsjax whose run would continue under other settings."""
    path = Path(run_dir) / CONFIG_YAML
    if not Path(run_dir).is_dir():
        raise UsageError(f"no run folder at {run_dir}")
    try:
        values = yaml.safe_load(path.read_text())
    # missing, unreadable, not UTF-8, not YAML
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:
        raise UsageError(f"cannot read {path}: {type(e).__name__}") from None
    if not isinstance(values, dict):
        raise UsageError(f"{path} is not a run config")
    missing = missing_keys(values) if complete else []
    if missing:
        shown = " ".join(missing[:6]) + (
            f" and {len(missing) - 6} more" if len(missing) > 6 else ""
        )
        raise UsageError(
            f"{path} lacks {shown}: cut short, or written by another hintsjax version; "
            f"it cannot be resumed as it was trained (start a new run)"
        )
    return run_config(values, resolved=True)
