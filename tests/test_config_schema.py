"""One settings schema: the command line's keys (hintsjax/conf/config.yaml) are the dataclasses'
fields (RunConfig and its sections), each with no default of its own or the dataclass's, so every
setting can be given on the command line and the command line resolves what `run_config` does.

Which default wins, later winning: the dataclass's (hintsjax/settings/config.py, hintsjax/settings/algorithm_settings.py),
the env's (`TRAINING` beside it, envs/<env>.py, read into hintsjax.settings.env_defaults.ENV_DEFAULTS), the
env's for the agent (its `learners` and `references`), then the command line. config.yaml's null
gives no value, so the layers below decide: ppo.num_envs is 16 (PPOConfig) unless the env sets
its own (256 for ant's learners, 1024 for its references)."""

from __future__ import annotations

import pytest
from test_cli import SHIPPED_ENVS

from hintsjax.system.errors import UsageError
from hintsjax.models.agents import AGENTS
from hintsjax.settings.config import RunConfig, SECTIONS
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.settings.layers import run_config, to_dict
from hintsjax.cli import overrides
from hintsjax.training import request

RUN_ONLY = {"out_dir", "name", "resume", "compilation_cache"}  # the command's own keys, not a RunConfig's


def schema_defaults() -> dict[str, object]:
    """Every setting of the dataclasses as the command line names it (section.key), with its
    default as config.yaml would write it (tuples as lists)."""
    flat = {k: v for k, v in to_dict(RunConfig()).items() if k not in SECTIONS}
    flat.update({f"{name}.{k}": v for name in SECTIONS for k, v in to_dict(RunConfig())[name].items()})
    return flat


def yaml_values() -> dict[str, object]:
    """config.yaml's keys (section.key for a section's) and their values."""
    conf = overrides.defaults()
    flat = {k: v for k, v in conf.items() if not isinstance(v, dict)}
    flat.update({f"{name}.{k}": v for name, section in conf.items() if isinstance(section, dict) for k, v in section.items()})
    return flat


def mismatches(schema: dict[str, object], written: dict[str, object]) -> list[str]:
    """What keeps config.yaml (`written`) from being the dataclasses' schema: a setting it lacks,
    a key that is no setting, or a default that is neither null nor the dataclass's."""
    found = [f"{k} missing" for k in schema if k not in written]
    found += [f"{k} is no setting" for k in written if k not in schema and k not in RUN_ONLY]
    found += [f"{k}: {written[k]!r}, the dataclass says {schema[k]!r}" for k in schema
              if k in written and written[k] is not None and written[k] != schema[k]]
    return found


def test_config_yaml_holds_every_setting_with_no_default_or_the_dataclasses():
    schema = schema_defaults()
    assert {"ppo.starts_per_rollout", "ppo.num_envs", "gail.grad_penalty", "warp_capacity"} <= set(schema)
    assert mismatches(schema, yaml_values()) == []
    assert set(overrides.config_keys()) - set(RUN_ONLY) - set(SECTIONS) == set(schema)


def test_a_drifted_config_yaml_is_caught():
    schema = schema_defaults()
    drifted = {k: v for k, v in yaml_values().items() if k != "ppo.starts_per_rollout"}
    drifted.update({"seeds": 7, "ppo.num_env": None})
    assert mismatches(schema, drifted) == ["ppo.starts_per_rollout missing", "ppo.num_env is no setting",
                                           "seeds: 7, the dataclass says 5"]


def _keys(layer: dict) -> set[str]:
    return {f"{k}.{sk}" if isinstance(v, dict) else k for k, v in layer.items() if k != "agents"
            for sk in (v if isinstance(v, dict) else [None])}


@pytest.mark.parametrize("env", SHIPPED_ENVS)
def test_no_env_sets_a_key_that_config_yaml_gives_a_value(env):
    """A value in config.yaml would override the env's default on the command line but not in
    `run_config`, so the keys an env sets are null there."""
    defaults = ENV_DEFAULTS[env]
    set_by_env = _keys(defaults).union(*(_keys(layer) for layer in defaults["agents"].values()))
    valued = {k for k, v in yaml_values().items() if v is not None}
    assert set_by_env and not set_by_env & valued, set_by_env & valued


@pytest.mark.parametrize("env", SHIPPED_ENVS)
def test_the_command_line_resolves_every_agent_as_run_config_does(env):
    """What `request.request` makes of Hydra's values for a new run (its own keys taken out first; the
    packaged expert it then looks for is not there for every env, e.g. ant_fast)."""
    for agent in AGENTS:
        values = {**overrides.defaults(), "env": env, "agent": agent}
        values.pop("compilation_cache")
        request.places(values)
        assert run_config(values) == run_config({"env": env, "agent": agent}), agent


def test_every_setting_can_be_given_on_the_command_line():
    """Each dataclass field, as a key=value argument, passes the command line's checks, and a value
    for ppo.starts_per_rollout reaches the run's config (it was once refused as unknown)."""
    for key, value in schema_defaults().items():
        text = "null" if value is None else str(value).lower() if isinstance(value, bool) else str(value).replace(" ", "")
        overrides.check_overrides([f"{key}={text}"])
    asked = request.request({**overrides.defaults(), "ppo": {**overrides.defaults()["ppo"], "starts_per_rollout": True}})
    assert asked.cfg.ppo.starts_per_rollout and not run_config({}).ppo.starts_per_rollout
    with pytest.raises(UsageError, match="starts_per_rollout must be bool, got 2"):
        request.request({**overrides.defaults(), "ppo": {"starts_per_rollout": 2}})

