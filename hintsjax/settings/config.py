"""One run's configuration: the schema (RunConfig and its sections), its layers and validation.

Choices (env, agent, scheme, hint, variants) are validated against the registries here, so a
bad name fails before anything is built or written, with a one-line message that lists the
valid choices. A config value of `None` means "the env's default" (hintsjax.settings.env_defaults).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import jax
import jax.numpy as jnp
import yaml

from hintsjax import envs
from hintsjax.models.agents import AGENTS, EXPERT_AGENT, AgentSpec
from hintsjax.settings.algorithm_settings import DaggerConfig, GailConfig, PPOConfig
from hintsjax.models.conditioning import SCHEMES
from hintsjax.settings.env_defaults import ENV_DEFAULTS
from hintsjax.envs.errors import ChoiceError, choose
from hintsjax.system.errors import UsageError, require_positive
from hintsjax.settings.hint_sources import PROGRAMMATIC, check_matches, hinted_env, hinted_params


CONFIG_YAML = "config.yaml"  # a run folder's resolved config


def env_params(env: str, variant: str | None) -> Any:
    """The params of `env`'s `variant` (None: its default); UsageError naming the valid variants."""
    try:
        return envs.make_params(env, variant)
    except ChoiceError as e:
        raise UsageError(str(e)) from None


@dataclass(frozen=True)
class RunConfig:
    """One training run: what to train, on what, for how many seeds, and how to evaluate it."""

    env: str = "pendulum"
    agent: str = "hints"
    scheme: str = "fc"
    hint: str = "composite"
    variant: str | None = None  # training variant of the env (None: its default)
    seeds: int = 5
    seed: int = 0  # seed i of the run is PRNGKey(seed + i)
    eval_episodes: int = 50
    eval_variants: tuple[str, ...] = ()  # deploy variants evaluated after training
    stochastic_eval: bool = False
    checkpoint_every: int = 10  # updates between progress reports and checkpoints
    checkpoint_seconds: float = 30.0  # at least this long between checkpoints (0: after every report)
    expert: str | None = None  # dagger/gail: an exported expert folder (None: the env's packaged one)
    hints_from: str | None = None  # a Python file or module whose register_hint calls add hints (docs/playground.md)
    hint_source: str = "programmatic"  # where training's hint comes from: programmatic, or a generator folder
    eval_hint_source: str | None = None  # the same at deploy (None: as hint_source)
    # What steps an MJX env: auto (resolved when the config is built: Warp on an NVIDIA GPU with
    # warp-lang, else JAX), jax (bit-reproducible) or warp (envs/physics.py)
    physics: str = "auto"
    warp_capacity: float = 2.0  # MJX-Warp's contact and constraint buffers: this many times the model's most per world
    ppo: PPOConfig = field(default_factory=PPOConfig)
    dagger: DaggerConfig = field(default_factory=DaggerConfig)
    gail: GailConfig = field(default_factory=GailConfig)

    @property
    def agent_spec(self) -> AgentSpec:
        return AGENTS[self.agent]

    @property
    def effective_hint(self) -> str:
        """The hint the env computes: none for agents without one, `state` for HINTS-x."""
        return self.agent_spec.hint_for(self.hint)

    @property
    def label(self) -> str:
        """Short name for tables: agent[-scheme][-hint]."""
        return self.agent_spec.label(self.agent, self.scheme, self.hint)

    def seed_keys(self) -> jax.Array:
        """[S] PRNG keys of the run's seeds: seed i is key(seed + i)."""
        return jnp.stack([jax.random.key(self.seed + i) for i in range(self.seeds)])

    def hint_source_for(self, deploy: bool) -> str:
        """The hint source of training, or of deployment (evaluation, videos) with `deploy`."""
        return (self.eval_hint_source or self.hint_source) if deploy else self.hint_source

    def make_env(self, observe: tuple[str, ...] | None = None, hint: str | None = None, deploy: bool = False) -> envs.Env:
        """The env the agent acts in (its hint `hint`, default its own, from the hint source of
        training or of deployment); its params are `task_params`'."""
        observe = self.agent_spec.observe if observe is None else observe
        env = hinted_env(self.env, self.effective_hint if hint is None else hint, observe, self.hint_source_for(deploy),
                         physics=self.physics, warp_capacity=self.warp_capacity)
        return envs.SquashedActions(env) if self.ppo.action_head == "tanh" else env

    def task_params(self, variant: str | None, deploy: bool = False) -> Any:
        """The params of `make_env(deploy=deploy)`'s env on `variant` (None: the training variant's default)."""
        return hinted_params(self.env, env_params(self.env, variant), self.agent_spec.observe, self.hint_source_for(deploy))

    def validate(self) -> "RunConfig":
        try:
            choose("env", self.env, envs.REGISTRY)
            choose("agent", self.agent, AGENTS)
            if self.agent_spec.pixels:
                envs.check_drawable(self.env)
            choose("scheme", self.scheme, SCHEMES)
            if self.hint not in (RunConfig.hint, ENV_DEFAULTS.get(self.env, {}).get("hint")):
                envs.make_hint(self.env, self.hint)  # a hint asked for is named right, even where the agent sees none
            hint = envs.make_hint(self.env, self.effective_hint)
            envs.resolve_physics(self.env, self.physics)
        except (ChoiceError, envs.PhysicsUnavailable) as e:
            raise UsageError(str(e)) from None
        names = [part.name for part in hint.parts]
        twice = sorted({name for name in names if names.count(name) > 1})
        if twice:
            raise UsageError(f"hint '{self.hint}' gives {', '.join(twice)} more than once; name each hint once")
        if self.agent_spec.hint and not names:
            raise UsageError(f"agent={self.agent} sees a hint, so hint=none leaves it nothing; valid for {self.env}: "
                             f"{', '.join(envs.hint_names(self.env))} (or agent=ppo_rgb, which sees none)")
        if self.hints_from is not None:
            self._check_hint_widths(hint)
        if not 1 <= self.warp_capacity < float("inf"):
            raise UsageError(f"warp_capacity must be a number of at least 1, got {self.warp_capacity}")
        for v in (self.variant, *self.eval_variants):
            env_params(self.env, v)
        self._check_hint_sources()
        require_positive(self, ("seeds", "eval_episodes", "checkpoint_every"))
        if not self.checkpoint_seconds >= 0:  # NaN too
            raise UsageError(f"checkpoint_seconds must be 0 or more, got {self.checkpoint_seconds}")
        for section in SECTIONS:
            getattr(self, section).validate()
        if self.ppo.action_head != "gaussian" and (self.agent_spec.imitates or self.agent == EXPERT_AGENT):
            raise UsageError(f"ppo.action_head={self.ppo.action_head} is for PPO's learners; {self.agent} keeps the "
                             "gaussian head (an expert's policy drives dagger and gail as a Gaussian's mean)")
        if self.agent_spec.algorithm == "dagger" and self.dagger.buffer_size < self.ppo.batch_size:
            raise UsageError(f"dagger.buffer_size ({self.dagger.buffer_size}) must hold one round, ppo.batch_size ({self.ppo.batch_size})")
        return self

    def _check_hint_widths(self, hint: envs.Hint) -> None:
        """UsageError naming a hint (of a hint file) that returns another width than it registered."""
        env = envs.make(self.env, envs.NO_HINT, ("state",))
        params = env_params(self.env, self.variant)
        state = jax.eval_shape(env.initial_state, jax.random.key(0), params)
        try:
            envs.check_hint_shapes(hint, state, params)
        except envs.HintFileError as e:
            raise UsageError(f"hints_from={self.hints_from}: {e}") from None

    def _check_hint_sources(self) -> None:
        for name in ("hint_source", "eval_hint_source"):
            source = getattr(self, name)
            if source in (None, PROGRAMMATIC):
                continue
            if not self.agent_spec.hint:
                raise UsageError(f"{name} applies to agents that see a hint "
                                 f"({', '.join(a for a, s in AGENTS.items() if s.hint)}), not {self.agent}")
            check_matches(source, self.env, self.effective_hint)


def _fields(cls) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


SECTIONS = {"ppo": PPOConfig, "dagger": DaggerConfig, "gail": GailConfig}  # RunConfig's nested settings
TUPLES = {"hidden", "disc_hidden", "eval_variants"}  # list-valued keys (YAML and Hydra give lists)


def _merge(*layers: Mapping[str, Any]) -> dict[str, Any]:
    """Later layers override earlier ones, key by key and section by section; None is no value."""
    merged: dict[str, Any] = {}
    for layer in layers:
        for k, v in layer.items():
            if v is None:
                continue
            if k in SECTIONS:
                merged[k] = {**merged.get(k, {}), **{sk: sv for sk, sv in dict(v).items() if sv is not None}}
            else:
                merged[k] = v
    return merged


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
    if resolved:
        merged = {k: dict(v) if k in SECTIONS and isinstance(v, Mapping) else v for k, v in values.items()}
        merged.setdefault("physics", envs.JAX)  # a run saved before the setting was stepped by MJX's JAX solver
    else:
        merged = _merge(defaults, per_agent.get(values.get("agent") or RunConfig.agent, {}), values)
    unknown = {k for k in merged if k not in SECTIONS} - _fields(RunConfig)
    unknown |= {f"{name}.{k}" for name, cls in SECTIONS.items() for k in merged.get(name, {}) if k not in _fields(cls)}
    if unknown:
        raise UsageError(f"unknown config keys {sorted(unknown)}")
    try:
        for prefix, section in [("", merged), *((f"{name}.", merged.get(name, {})) for name in SECTIONS)]:
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
    return dataclasses.replace(cfg, physics=envs.resolve_physics(cfg.env, cfg.physics))  # what the run steps with, kept


def hint_file(source: str) -> str:
    """`hints_from`'s file or module loaded (its registered hints added): the absolute path of a
    file, so that a run folder's config finds it from elsewhere; UsageError if it does not import."""
    try:
        envs.load_hints(source)
    except envs.HintFileError as e:
        raise UsageError(str(e)) from None
    path = Path(source).expanduser()
    return str(path.resolve()) if source.endswith(".py") or path.exists() else source


def _check_types(cfg: RunConfig) -> None:
    for obj in (cfg, *(getattr(cfg, name) for name in SECTIONS)):
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            kind = {"int": int, "float": (int, float), "bool": bool, "str": str}.get(str(f.type))
            if kind is not None and (not isinstance(value, kind) or (kind is int and isinstance(value, bool))):
                raise UsageError(f"{f.name} must be {f.type}, got {value!r}")


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
    part = Path(run_dir) / f".{CONFIG_YAML}.part"
    part.write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))
    part.replace(Path(run_dir) / CONFIG_YAML)


# Settings added since runs were first saved whose absence means their default (a run saved before
# hints_from had no hint file), so a saved config without them is complete.
OPTIONAL_IN_SAVED = {"hints_from"}


def missing_keys(values: Mapping[str, Any]) -> list[str]:
    """The settings of today's RunConfig that a saved config (to_dict's layout) lacks."""
    missing = sorted(_fields(RunConfig) - set(SECTIONS) - OPTIONAL_IN_SAVED - set(values))
    return missing + [f"{name}.{k}" for name, cls in SECTIONS.items()
                      for k in sorted(_fields(cls) - set(values.get(name) or {}))]


def load_run_config(run_dir: Path, complete: bool = False) -> RunConfig:
    """The validated config a run folder was trained with. With `complete` (a run to go on with),
    a config that lacks any of today's settings is refused, not filled in with defaults: it was
    cut short, or written by an older hintsjax whose run would continue under other settings."""
    path = Path(run_dir) / CONFIG_YAML
    if not Path(run_dir).is_dir():
        raise UsageError(f"no run folder at {run_dir}")
    try:
        values = yaml.safe_load(path.read_text())
    except (OSError, UnicodeDecodeError, yaml.YAMLError) as e:  # missing, unreadable, not UTF-8, not YAML
        raise UsageError(f"cannot read {path}: {type(e).__name__}") from None
    if not isinstance(values, dict):
        raise UsageError(f"{path} is not a run config")
    missing = missing_keys(values) if complete else []
    if missing:
        shown = " ".join(missing[:6]) + (f" and {len(missing) - 6} more" if len(missing) > 6 else "")
        raise UsageError(f"{path} lacks {shown}: cut short, or written by another hintsjax version; "
                         f"it cannot be resumed as it was trained (start a new run)")
    return run_config(values, resolved=True)
