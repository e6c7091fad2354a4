"""One settings schema: the command line's keys (Hydra's config, hintsjax.settings.schema) are the
dataclasses' fields (RunConfig and its sections), each with no default of its own or the
dataclass's, so every setting can be given on the command line and the command line resolves what
`run_config` does; and what else is read off the fields (Hyper, a group's shapes, the keys old
configs may lack, docs/settings.md, the README's key table) follows them.

Which default wins, later winning: the dataclass's (hintsjax/settings/config.py,
hintsjax/settings/algorithm_settings.py), the env's (`TRAINING` beside it, envs/<env>.py, read into
hintsjax.settings.env_defaults.ENV_DEFAULTS), the env's for the agent (its `learners` and
`references`), then the command line. config.yaml's null gives no value, so the layers below decide:
ppo.num_envs is 16 (PPOConfig) unless the env sets its own (256 for ant's learners, 1024 for its
references)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import jax
import pytest
import yaml
from test_cli import SHIPPED_ENVS

from hintsjax.system.errors import UsageError
from hintsjax.models.agents import AGENTS
from hintsjax.settings import fields, schema
from hintsjax.settings.algorithm_settings import PPOConfig
from hintsjax.settings.config import CommandSettings, RunConfig, SECTIONS
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.settings.layers import load_run_config, missing_keys, run_config, to_dict
from hintsjax.algorithms import group
from hintsjax.algorithms.ppo import Hyper
from hintsjax.cli import overrides
from hintsjax.training import request

# the command's own keys, not a RunConfig's
RUN_ONLY = {"out_dir", "name", "resume", "compilation_cache"}
ROOT = Path(__file__).resolve().parents[1]


def schema_defaults() -> dict[str, object]:
    """Every setting of the dataclasses as the command line names it (section.key), with its
    default as config.yaml would write it (tuples as lists)."""
    flat = {k: v for k, v in to_dict(RunConfig()).items() if k not in SECTIONS}
    flat.update(
        {f"{name}.{k}": v for name in SECTIONS for k, v in to_dict(RunConfig())[name].items()}
    )
    return flat


def yaml_values() -> dict[str, object]:
    """config.yaml's keys (section.key for a section's) and their values."""
    conf = overrides.defaults()
    flat = {k: v for k, v in conf.items() if not isinstance(v, dict)}
    flat.update(
        {
            f"{name}.{k}": v
            for name, section in conf.items()
            if isinstance(section, dict)
            for k, v in section.items()
        }
    )
    return flat


def mismatches(schema: dict[str, object], written: dict[str, object]) -> list[str]:
    """What keeps config.yaml (`written`) from being the dataclasses' schema: a setting it lacks,
    a key that is no setting, or a default that is neither null nor the dataclass's."""
    found = [f"{k} missing" for k in schema if k not in written]
    found += [f"{k} is no setting" for k in written if k not in schema and k not in RUN_ONLY]
    found += [
        f"{k}: {written[k]!r}, the dataclass says {schema[k]!r}"
        for k in schema
        if k in written and written[k] is not None and written[k] != schema[k]
    ]
    return found


def test_config_yaml_holds_every_setting_with_no_default_or_the_dataclasses():
    schema = schema_defaults()
    assert {"ppo.starts_per_rollout", "ppo.num_envs", "gail.grad_penalty", "warp_capacity"} <= set(
        schema
    )
    assert mismatches(schema, yaml_values()) == []
    assert set(overrides.config_keys()) - set(RUN_ONLY) - set(SECTIONS) == set(schema)


def test_a_drifted_config_yaml_is_caught():
    schema = schema_defaults()
    drifted = {k: v for k, v in yaml_values().items() if k != "ppo.starts_per_rollout"}
    drifted.update({"seeds": 7, "ppo.num_env": None})
    assert mismatches(schema, drifted) == [
        "ppo.starts_per_rollout missing",
        "ppo.num_env is no setting",
        "seeds: 7, the dataclass says 5",
    ]


def _keys(layer: dict) -> set[str]:
    return {
        f"{k}.{sk}" if isinstance(v, dict) else k
        for k, v in layer.items()
        if k != "agents"
        for sk in (v if isinstance(v, dict) else [None])
    }


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
    """What `request.checked_request` makes of Hydra's values for a new run (its own keys taken out
    first; the packaged expert it then looks for is not there for every env, e.g. ant_fast)."""
    for agent in AGENTS:
        values = {**overrides.defaults(), "env": env, "agent": agent}
        values.pop("compilation_cache")
        request.folder_settings(values)
        assert run_config(values) == run_config({"env": env, "agent": agent}), agent


def test_every_setting_can_be_given_on_the_command_line():
    """Each dataclass field, as a key=value argument, passes the command line's checks, and a value
    for ppo.starts_per_rollout reaches the run's config (it was once refused as unknown)."""
    for key, value in schema_defaults().items():
        text = (
            "null"
            if value is None
            else str(value).lower()
            if isinstance(value, bool)
            else str(value).replace(" ", "")
        )
        overrides.check_overrides([f"{key}={text}"])
    asked = request.checked_request(
        {**overrides.defaults(), "ppo": {**overrides.defaults()["ppo"], "starts_per_rollout": True}}
    )
    assert asked.cfg.ppo.starts_per_rollout and not run_config({}).ppo.starts_per_rollout
    with pytest.raises(UsageError, match="starts_per_rollout must be bool, got 2"):
        request.checked_request({**overrides.defaults(), "ppo": {"starts_per_rollout": 2}})


# --- Each setting declared once (hintsjax/settings/fields.py): what is read off the fields follows
# them.


def _other_value(cls, name: str):
    """A valid value of setting `name` other than its default (for a shape, one that changes it)."""
    f = next(f for f in fields.settings_of(cls) if f.name == name)
    value, choices = f.default, f.metadata[fields.CHOICES]
    if choices:
        return next(c for c in choices if c != value)
    if isinstance(value, bool):
        return not value
    if isinstance(value, tuple):
        return tuple(2 * w for w in value)
    if value is None:
        return 0.05
    if isinstance(value, float):
        return value / 2 or 0.5
    return value * 2 or 1


def test_hyper_holds_every_traced_ppo_setting_and_reads_its_value():
    cfg = run_config({})
    hyper = Hyper.of(cfg)
    leaves = [
        key.name for key, _ in jax.tree_util.tree_flatten_with_path(hyper)[0] for key in key[-1:]
    ]
    assert leaves == [
        *fields.names(PPOConfig, traced=True),
        "state_noise",
        "hint_take",
        "hint_keep",
    ]
    assert {"clip_eps", "encoder_lr", "target_kl"} <= set(leaves) and "epochs" not in leaves
    for name in fields.names(PPOConfig, traced=True):
        other = _other_value(PPOConfig, name)
        changed = dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, **{name: other}))
        assert float(getattr(Hyper.of(changed), name)) == pytest.approx(other), name


ALSO = {  # a setting that needs another to be valid
    "kl_adaptive_lr": {"target_kl": 0.05},
    "squashed_entropy": {"action_head": "tanh"},
}


@pytest.mark.parametrize("name", fields.names(PPOConfig))
def test_a_group_shares_the_traced_settings_and_splits_on_the_others(name):
    """Two configurations that differ only in one PPO setting train in one group if the field is
    declared `traced`, in two otherwise; so group.SHAPES cannot drift from the fields."""
    base = {
        "env": "pendulum",
        "agent": "hints",
        "ppo": {"total_env_steps": 4096, **ALSO.get(name, {})},
    }
    other = {**base, "ppo": {**base["ppo"], name: _other_value(PPOConfig, name)}}
    cfgs = [run_config(base), run_config(other)]
    assert cfgs[0] != cfgs[1]
    traced = name in fields.names(PPOConfig, traced=True) and name not in group.OPTIONAL_TRACED
    assert group.plan(cfgs) == ([[0, 1]] if traced else [[0], [1]])
    assert (name in group.SHAPES) != (name in fields.names(PPOConfig, traced=True))


def test_an_optional_traced_setting_shares_a_group_when_set_in_both():
    cfgs = [run_config({"ppo": {"target_kl": kl}}) for kl in (0.02, 0.05)]
    assert group.plan(cfgs) == [[0, 1]] and group.plan([run_config({}), cfgs[0]]) == [[0], [1]]


def test_a_saved_config_may_lack_exactly_the_settings_declared_so():
    """A config saved before a `saved_may_lack` setting existed is complete and resumes at its
    default; one without any other setting is refused (layers.missing_keys)."""
    saved = to_dict(run_config({}))
    declared = schema.saved_may_lack()
    assert {"ppo.reset_every_update", "hints_from", "image_size"} <= declared
    for key in schema.keys():
        if key in RUN_ONLY:
            continue
        section, _, name = key.rpartition(".")
        lacking = {
            k: ({kk: vv for kk, vv in v.items() if kk != name} if k == section else v)
            for k, v in saved.items()
            if k != key
        }
        assert missing_keys(lacking) == ([] if key in declared else [key]), key
        if key in declared:
            assert run_config(lacking, resolved=True) == run_config(saved, resolved=True), key


def test_every_committed_run_folder_of_every_earlier_layout_still_loads():
    """The run folders kept in experiments/results/runs were saved by hintsjax of many dates (some
    lack physics, warp_capacity, ppo.action_head, hint_source); each still loads (but those whose
    hints came from a generator folder, which is not kept)."""
    saved = {
        p.parent: yaml.safe_load(p.read_text()) or {}
        for p in (ROOT / "experiments" / "results" / "runs").rglob("config.yaml")
    }
    folders = sorted(
        folder
        for folder, values in saved.items()
        if "ppo" in values
        and {values.get("hint_source"), values.get("eval_hint_source")} <= {None, "programmatic"}
    )
    assert len(folders) > 100
    lacking = 0
    for folder in folders:
        values = yaml.safe_load((folder / "config.yaml").read_text())
        lacking += bool(missing_keys(values))
        assert load_run_config(folder).env == values["env"], folder
    assert lacking > 50  # older layouts among them


def test_every_setting_has_a_help_line_and_a_type_it_can_be_given_as():
    for cls in (RunConfig, CommandSettings, *SECTIONS.values()):
        declared = fields.settings_of(cls)
        assert [f.name for f in declared] == [
            f.name for f in dataclasses.fields(cls) if f.name not in SECTIONS
        ]
        for f in declared:
            assert f.metadata[fields.HELP] and "\n" not in f.metadata[fields.HELP], f.name
            if f.metadata[fields.TRACED]:
                assert str(f.type) in ("float", "float | None"), (
                    f"{f.name}: a traced setting is a number"
                )


def test_settings_md_is_written_from_the_fields():
    """docs/settings.md is what `python -m hintsjax.settings.schema` writes (regenerate it after a
    change)."""
    assert schema.SETTINGS_MD.read_text() == schema.markdown()
    page = schema.markdown()
    assert all(f"| `{key}` |" in page for key in schema.keys())


README_TABLE = re.compile(r"^\| key \| choices \|\n\|---\|---\|\n((?:\|.*\|\n)+)", re.M)


def readme_table_drift(readme: str) -> list[str]:
    """What keeps the README's key table from the fields: a name there that is no setting, a
    top-level setting it does not name, or a `section.key` anywhere in the README that is none."""
    rows = README_TABLE.search(readme).group(1).splitlines()
    named = {n for row in rows for n in re.findall(r"`([\w.*]+)`", row.split("|")[1])}
    top = [k for k in schema.keys() if "." not in k]
    found = [
        f"{n} is no setting"
        for n in sorted(named)
        if n not in top and n.removesuffix(".*") not in SECTIONS
    ]
    found += [f"{k} not in the table" for k in top if k not in named]
    dotted = set(re.findall(rf"`((?:{'|'.join(SECTIONS)})\.\w+)[`=]", readme))
    return found + [f"{k} is no setting" for k in sorted(dotted - set(schema.keys()))]


def test_the_readme_key_table_names_the_settings():
    readme = (ROOT / "README.md").read_text()
    assert readme_table_drift(readme) == []
    drifted = (
        readme.replace("`seed`, ", "")
        .replace("`ppo.num_envs`", "`ppo.num_env`")
        .replace("| `expert` |", "| `experts` |")
    )
    assert readme_table_drift(drifted) == [
        "experts is no setting",
        "seed not in the table",
        "expert not in the table",
        "ppo.num_env is no setting",
    ]


def test_an_env_that_sets_a_setting_the_command_line_gives_a_value_is_refused(monkeypatch):
    """An env registered with `seeds` in its TRAINING would train other seeds from the command line
    (which gives seeds=5) than from run_config: refused, naming the setting."""
    from hintsjax import envs

    entry = envs.REGISTRY["pendulum"]
    monkeypatch.setitem(
        envs.REGISTRY,
        "pendulum_seeds",
        envs.EnvEntry(entry.cls, entry.variants, {**entry.training, "seeds": 3}),
    )
    try:
        with pytest.raises(
            TypeError,
            match="pendulum_seeds's TRAINING sets seeds, which the command line gives a value",
        ):
            run_config({"env": "pendulum_seeds"})
    finally:
        dict.pop(ENV_DEFAULTS, "pendulum_seeds", None)  # added when first looked up


def test_ppo_encoder_picks_the_pixel_encoder_and_names_its_choices():
    """ppo.encoder=brax_vision gives the network Brax's two convolutions (16 5x5, then 32 3x3) in
    place of the paper's three; an unknown encoder is one line naming the valid ones."""
    from hintsjax.algorithms import ppo

    cfg = run_config({"agent": "ppo_rgb", "ppo": {"encoder": "brax_vision"}})
    obs = {"pixels": jax.numpy.zeros((1, 64, 64, 3), jax.numpy.uint8)}
    params = ppo.make_network(cfg, cfg.make_env()).init(jax.random.key(0), obs)
    params = params["params"]["encoder"]
    assert [p["kernel"].shape for p in params.values()] == [(5, 5, 3, 16), (3, 3, 16, 32)]
    with pytest.raises(UsageError, match="ppo.encoder 'resnet'; valid: nature, brax_vision"):
        run_config({"ppo": {"encoder": "resnet"}})


def test_the_network_takes_its_ppo_settings_by_name():
    """The network's fields named as PPO settings take their values (ppo.make_network names none of
    them); renaming one side alone would drop the setting, so the known ones are listed."""
    from hintsjax.algorithms import ppo

    assert {
        "hint_width",
        "hidden",
        "normalize_state",
        "action_head",
        "critic_trains_encoder",
        "encoder",
        "encoder_dtype",
        "critic_encoder",
        "pixel_scale",
        "activation",
        "std_head",
    } <= set(ppo.NETWORK_SETTINGS)
    cfg = run_config(
        {
            "agent": "ppo_state",
            "ppo": {"hidden": [8], "action_head": "sigmoid", "critic_trains_encoder": False},
        }
    )
    network = ppo.make_network(cfg, cfg.make_env())
    assert all(getattr(network, name) == getattr(cfg.ppo, name) for name in ppo.NETWORK_SETTINGS)
    assert (network.hidden, network.action_head, network.critic_trains_encoder) == (
        (8,),
        "sigmoid",
        False,
    )
