"""Frozen configuration: PPO's settings, one run's choices, and their validation.

Choices (env, agent, scheme, hint, variants) are validated against the registries here, so a
bad name fails before anything is built or written, with a one-line message that lists the
valid choices. Per-env defaults (budget, actor learning rate, default hint, deploy variants)
live in `ENV_DEFAULTS`; a config value of `None` means "the env's default".
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
        for name in ("total_env_steps", "num_envs", "batch_size", "epochs", "minibatch_size", "hint_width"):
            if getattr(self, name) <= 0:
                raise UsageError(f"ppo.{name} must be positive, got {getattr(self, name)}")
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
        if not all(w > 0 for w in self.hidden):
            raise UsageError(f"ppo.hidden widths must be positive, got {list(self.hidden)}")


def env_params(env: str, variant: str | None) -> Any:
    """The params of `env`'s `variant` (None: its default); UsageError naming the valid variants."""
    try:
        return envs.make_params(env, variant)
    except ChoiceError as e:
        raise UsageError(str(e)) from None


# Per-env defaults, overriding PPOConfig's: the paper's budgets and Table 5's actor rates.
ENV_DEFAULTS: dict[str, dict[str, Any]] = {
    "pendulum": dict(
        hint="composite",
        eval_variants=("swingto",),
        ppo=dict(total_env_steps=200_000, actor_lr=1e-3, reward_scale=0.1),
    ),
    # 700 episodes of at most 500 steps (the paper's 700 episodes, counted at their length).
    "acrobot": dict(hint="composite", ppo=dict(total_env_steps=350_000, reward_scale=0.1)),
    # Early IDP episodes last ~10 steps, so an episode count would be a tiny budget: we count
    # 200 full-length episodes (200 K steps), the pendulum's budget. 128 envs per seed (rollouts
    # of 8 steps per 1024-transition batch): MJX's RK4 with the rail's constraint solver is
    # kernel-launch bound at small batches on a GPU (16 envs x 5 seeds ran ~6 K steps/s).
    "idp": dict(hint="composite", ppo=dict(total_env_steps=200_000, num_envs=128, reward_scale=0.1)),
}


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
    ppo: PPOConfig = field(default_factory=PPOConfig)

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
        for name in ("seeds", "eval_episodes", "checkpoint_every"):
            if getattr(self, name) <= 0:
                raise UsageError(f"{name} must be positive, got {getattr(self, name)}")
        self.ppo.validate()
        return self


def _fields(cls) -> set[str]:
    return {f.name for f in dataclasses.fields(cls)}


def run_config(values: Mapping[str, Any]) -> RunConfig:
    """Build and validate a RunConfig from plain values (e.g. Hydra's), applying env defaults.

    Keys whose value is None take the env's default, then the dataclass default.
    """
    values = {k: v for k, v in values.items() if v is not None}
    env = values.get("env", RunConfig.env)
    try:
        defaults = choose("env", env, ENV_DEFAULTS)
    except ChoiceError as e:
        raise UsageError(str(e)) from None
    ppo_values = {**defaults.get("ppo", {}), **{k: v for k, v in dict(values.get("ppo", {})).items() if v is not None}}
    top = {**{k: v for k, v in defaults.items() if k != "ppo"}, **values}
    unknown = (set(top) - _fields(RunConfig)) | (set(ppo_values) - _fields(PPOConfig))
    if unknown:
        raise UsageError(f"unknown config keys {sorted(unknown)}")
    try:
        if "hidden" in ppo_values:
            ppo_values["hidden"] = tuple(int(w) for w in ppo_values["hidden"])
        for k in ("eval_variants",):
            if k in top:
                top[k] = tuple(top[k])
        ppo = PPOConfig(**ppo_values)
        cfg = RunConfig(**{**top, "ppo": ppo})
        _check_types(cfg)
    except UsageError:
        raise
    except (TypeError, ValueError) as e:
        raise UsageError(f"bad config value: {e}") from None
    return cfg.validate()


def _check_types(cfg: RunConfig) -> None:
    for obj in (cfg, cfg.ppo):
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
    return run_config(values)
