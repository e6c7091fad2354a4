"""Frozen configuration: PPO's settings, one run's choices, and their validation.

Choices (env, agent, scheme, hint, variants) are validated against the registries here, so a
bad name fails before anything is built or written, with a one-line message that lists the
valid choices. Per-env defaults (budget, actor learning rate, default hint, deploy variants)
live beside each env (`TRAINING` in envs/<env>.py) and are gathered in `ENV_DEFAULTS`; a config
value of `None` means "the env's default".
"""

from __future__ import annotations

import dataclasses
import sys
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import jax
import jax.numpy as jnp
import yaml

from hintsjax import envs
from hintsjax.agents import AGENTS, AgentSpec
from hintsjax.conditioning import SCHEMES
from hintsjax.envs.errors import ChoiceError, choose


CONFIG_YAML = "config.yaml"  # a run folder's resolved config


class UsageError(ValueError):
    """Bad input from the user: reported in one line, exit status 2."""


def require_positive(obj: Any, names: tuple[str, ...], prefix: str = "") -> None:
    """UsageError naming the first of `names` (numbers, or tuples of widths) that is not positive."""
    for name in names:
        value = getattr(obj, name)
        if isinstance(value, tuple) and not all(w > 0 for w in value):
            raise UsageError(f"{prefix}{name} widths must be positive, got {list(value)}")
        if not isinstance(value, tuple) and value <= 0:
            raise UsageError(f"{prefix}{name} must be positive, got {value}")


@dataclass(frozen=True)
class PPOConfig:
    """PPO settings (SPEC section 5). The budget is counted in environment steps."""

    total_env_steps: int = 200_000
    num_envs: int = 16  # a speed choice: it does not change the budget
    batch_size: int = 1024  # transitions per update: num_envs * rollout length
    epochs: int = 8
    minibatch_size: int = 256
    gamma: float = 0.99
    gae_lambda: float = 0.95
    clip_eps: float = 0.2
    vf_coef: float = 0.5
    ent_coef: float = 0.01
    max_grad_norm: float = 0.5
    encoder_lr: float = 1e-3
    actor_lr: float = 3e-4
    critic_lr: float = 1e-3
    hint_width: int = 64
    hidden: tuple[int, ...] = (256, 256)
    reward_scale: float = 1.0  # rewards are multiplied by this for learning (not for logging)
    # Draw each env's next start once per rollout rather than on every step (AutoReset.step's
    # `fresh`): for envs whose reset is dear (the car's track is 800 sequential trace steps).
    starts_per_rollout: bool = False
    # KL early stop (as Stable-Baselines3's target_kl): within an update, once a minibatch's approx.
    # KL from the rollout policy exceeds 1.5 x target_kl, that minibatch and the rest of the
    # update's epochs take no step. None: off (Table 5 has none).
    target_kl: float | None = None
    # State agents: normalise the state by its running mean and std (hintsjax.normalization).
    normalize_state: bool = False

    @property
    def rollout_length(self) -> int:
        return self.batch_size // self.num_envs

    @property
    def num_updates(self) -> int:
        return self.total_env_steps // self.batch_size

    @property
    def num_minibatches(self) -> int:
        return self.batch_size // self.minibatch_size

    def validate(self) -> None:
        require_positive(self, ("total_env_steps", "num_envs", "batch_size", "epochs", "minibatch_size", "hint_width"), "ppo.")
        if self.batch_size % self.num_envs:
            raise UsageError(f"ppo.batch_size ({self.batch_size}) must be a multiple of ppo.num_envs ({self.num_envs})")
        if self.batch_size % self.minibatch_size:
            raise UsageError(
                f"ppo.batch_size ({self.batch_size}) must be a multiple of ppo.minibatch_size ({self.minibatch_size})"
            )
        if self.total_env_steps < self.batch_size:
            raise UsageError(
                f"ppo.total_env_steps ({self.total_env_steps}) is less than one update's batch ({self.batch_size})"
            )
        require_positive(self, ("hidden",), "ppo.")
        if self.target_kl is not None and not self.target_kl > 0:
            raise UsageError(f"ppo.target_kl ({self.target_kl}) must be positive, or null for no KL early stop")


@dataclass(frozen=True)
class DaggerConfig:
    """DAgger (Ross et al. 2011). Each round rolls out ppo.batch_size steps (ppo.num_envs envs)
    with the beta-mixture of expert and student, labels every visited state with the expert's
    action, adds them to the aggregated dataset and regresses the student on it."""

    beta_decay: float = 0.5  # beta_i = beta_decay ** i: round 0 acts as the expert alone
    buffer_size: int = 200_000  # the aggregated dataset's capacity; the oldest rows go first when full
    grad_steps: int = 32  # student minibatch steps per round (minibatches of ppo.minibatch_size)
    lr: float = 1e-3

    def validate(self) -> None:
        if not 0.0 <= self.beta_decay <= 1.0:
            raise UsageError(f"dagger.beta_decay must be in [0, 1], got {self.beta_decay}")
        require_positive(self, ("buffer_size", "grad_steps", "lr"), "dagger.")


GAIL_REWARDS = ("logit", "original")


@dataclass(frozen=True)
class GailConfig:
    """GAIL (Ho and Ermon 2016): PPO on the reward of a discriminator D(s, a) trained to tell
    the expert's (state, action) pairs from the policy's."""

    demonstrations: int = 16  # expert episodes, rolled out once at the start of training
    disc_hidden: tuple[int, ...] = (256, 256)
    disc_lr: float = 3e-4
    disc_steps: int = 4  # discriminator minibatch steps per PPO update (minibatches of ppo.minibatch_size)
    # "logit": log D - log(1 - D), the log odds; mostly negative while the discriminator wins, so
    # ending an episode early pays (idp's agents learn to fall).
    # "original": -log(1 - D) > 0, Ho and Ermon's, which pays for every step alive (an agent
    # then avoids a task's terminating goal, e.g. acrobot's).
    reward: str = "logit"
    # D reads the state standardised by the demonstrations' mean and variance (gail.py).
    normalize_state: bool = False
    grad_penalty: float = 0.0  # weight of D's R1 gradient penalty on the expert's pairs (gail.py)

    def validate(self) -> None:
        require_positive(self, ("demonstrations", "disc_steps", "disc_lr", "disc_hidden"), "gail.")
        if self.grad_penalty < 0:
            raise UsageError(f"gail.grad_penalty must be 0 or more, got {self.grad_penalty}")
        if self.reward not in GAIL_REWARDS:
            raise UsageError(f"unknown gail.reward {self.reward!r}; valid: {', '.join(GAIL_REWARDS)}")


def env_params(env: str, variant: str | None) -> Any:
    """The params of `env`'s `variant` (None: its default); UsageError naming the valid variants."""
    try:
        return envs.make_params(env, variant)
    except ChoiceError as e:
        raise UsageError(str(e)) from None


# "agents" holds per-agent overrides on top of an env's defaults, for the converged references
# (tier 3): the expert trains PPO on the state for 5x the hint agents' budget; DAgger's rounds of
# 1024 steps aggregate every visited state (buffer = budget); GAIL gets the expert's budget.
def _references(expert_steps: int, dagger_steps: int = 100_000, gail_reward: str = "logit",
                gail_normalize_state: bool = False, gail_grad_penalty: float = 0.0, **expert_ppo: Any) -> dict[str, Any]:
    return {
        "expert_ppo": dict(ppo=dict(total_env_steps=expert_steps, **expert_ppo)),
        "dagger": dict(ppo=dict(total_env_steps=dagger_steps), dagger=dict(buffer_size=dagger_steps)),
        "gail": dict(ppo=dict(total_env_steps=expert_steps, **expert_ppo),
                     gail=dict(reward=gail_reward, normalize_state=gail_normalize_state,
                               grad_penalty=gail_grad_penalty)),
    }


def _learners(**ppo: Any) -> dict[str, Any]:
    """PPO settings for every agent but the converged references (which `_references` sets)."""
    return {name: dict(ppo=ppo) for name in AGENTS if name not in _references(0)}




def _env_defaults(training: dict[str, Any]) -> dict[str, Any]:
    """An env's training defaults as RunConfig layers: its own settings, and per agent those of
    `learners` (every agent but the references) and of `references` (`_references`' arguments)."""
    training = dict(training)
    agents = _learners(**training.pop("learners")) if "learners" in training else {}
    if "references" in training:
        references = dict(training.pop("references"))
        agents.update(_references(references.pop("expert_steps"), **references))
    return {**training, "agents": agents}


# Per env, defaults over PPOConfig's: the paper's budgets and Table 5's actor rates, and why each
# deviates where it does, live beside the env (`TRAINING` in envs/<env>.py, the registry's `training`).
ENV_DEFAULTS: dict[str, dict[str, Any]] = {name: _env_defaults(entry.training) for name, entry in envs.REGISTRY.items()}


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
    checkpoint_seconds: float = 0.0  # at least this long between checkpoints (0: after every report)
    expert: str | None = None  # dagger/gail: an exported expert folder (None: the env's packaged one)
    ppo: PPOConfig = field(default_factory=PPOConfig)
    dagger: DaggerConfig = field(default_factory=DaggerConfig)
    gail: GailConfig = field(default_factory=GailConfig)

    @property
    def agent_spec(self) -> AgentSpec:
        return AGENTS[self.agent]

    @property
    def effective_hint(self) -> str:
        """The hint the env computes: none for agents without one, `state` for HINTS-x."""
        spec = self.agent_spec
        if not spec.hint:
            return envs.NO_HINT
        return spec.hint_override or self.hint

    @property
    def label(self) -> str:
        """Short name for tables: agent[-scheme][-hint]."""
        spec = self.agent_spec
        parts = [self.agent]
        if spec.conditioned:
            parts.append(self.scheme)
        if spec.hint and not spec.hint_override:
            parts.append(self.hint)
        return "-".join(parts)

    def seed_keys(self) -> jax.Array:
        """[S] PRNG keys of the run's seeds: seed i is key(seed + i)."""
        return jnp.stack([jax.random.key(self.seed + i) for i in range(self.seeds)])

    def make_env(self, observe: tuple[str, ...] | None = None) -> envs.Env:
        return envs.make(self.env, self.effective_hint, self.agent_spec.observe if observe is None else observe)

    def validate(self) -> "RunConfig":
        try:
            choose("env", self.env, envs.REGISTRY)
            choose("agent", self.agent, AGENTS)
            choose("scheme", self.scheme, SCHEMES)
            envs.make_hint(self.env, self.effective_hint)
        except ChoiceError as e:
            raise UsageError(str(e)) from None
        for v in (self.variant, *self.eval_variants):
            env_params(self.env, v)
        require_positive(self, ("seeds", "eval_episodes", "checkpoint_every"))
        if self.checkpoint_seconds < 0:
            raise UsageError(f"checkpoint_seconds must be 0 or more, got {self.checkpoint_seconds}")
        for section in SECTIONS:
            getattr(self, section).validate()
        if self.agent_spec.algorithm == "dagger" and self.dagger.buffer_size < self.ppo.batch_size:
            raise UsageError(f"dagger.buffer_size ({self.dagger.buffer_size}) must hold one round, ppo.batch_size ({self.ppo.batch_size})")
        return self


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
    per_agent = defaults.pop("agents", {})
    if resolved:
        merged = {k: dict(v) if k in SECTIONS and isinstance(v, Mapping) else v for k, v in values.items()}
    else:
        merged = _merge(defaults, per_agent.get(values.get("agent") or RunConfig.agent, {}), values)
    unknown = {k for k in merged if k not in SECTIONS} - _fields(RunConfig)
    unknown |= {f"{name}.{k}" for name, cls in SECTIONS.items() for k in merged.get(name, {}) if k not in _fields(cls)}
    if unknown:
        raise UsageError(f"unknown config keys {sorted(unknown)}")
    try:
        for section in [merged, *(merged.get(name, {}) for name in SECTIONS)]:
            for k in TUPLES & set(section):
                section[k] = tuple(int(w) if k != "eval_variants" else w for w in section[k])
        sections = {name: cls(**merged.pop(name, {})) for name, cls in SECTIONS.items()}
        cfg = RunConfig(**merged, **sections)
        _check_types(cfg)
    except UsageError:
        raise
    except (TypeError, ValueError) as e:
        raise UsageError(f"bad config value: {e}") from None
    return cfg.validate()


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


def fail(error: Exception) -> int:
    """Report bad input in one line; the exit status for it."""
    print(f"error: {error}", file=sys.stderr)
    return 2


def save_run_config(run_dir: Path, cfg: RunConfig) -> None:
    """Write the resolved config into a run folder (what load_run_config reads back)."""
    (Path(run_dir) / CONFIG_YAML).write_text(yaml.safe_dump(to_dict(cfg), sort_keys=False))


def load_run_config(run_dir: Path) -> RunConfig:
    """The validated config a run folder was trained with."""
    path = Path(run_dir) / CONFIG_YAML
    if not Path(run_dir).is_dir():
        raise UsageError(f"no run folder at {run_dir}")
    try:
        values = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as e:
        raise UsageError(f"cannot read {path}: {type(e).__name__}") from None
    if not isinstance(values, dict):
        raise UsageError(f"{path} is not a run config")
    return run_config(values, resolved=True)
