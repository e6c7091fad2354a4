"""Each env's training defaults as RunConfig layers (`ENV_DEFAULTS`), read from the `TRAINING`
beside each env (envs/<env>.py, the registry's `training`), where the paper's budgets, Table 5's
actor rates and the reasons for each deviation are written. A config value of `None` means "the
env's default" (hintsjax.settings.layers.run_config stacks the layers)."""

from __future__ import annotations

from typing import Any

from hintsjax import envs
from hintsjax.models.agents import AGENTS


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


class EnvDefaults(dict):
    """ENV_DEFAULTS: the suite's envs' defaults, and those of any env the registry gained since
    (an adapted `playground:<task>` or `brax:<name>`, from its adapter's table, envs/playground.py;
    or an entry registered at run time, from its `training`), added when first looked up."""

    def __contains__(self, name: object) -> bool:
        if not dict.__contains__(self, name) and name in envs.REGISTRY:  # adapts a `<source>:<task>`
            self[name] = _env_defaults(envs.REGISTRY[name].training)
        return dict.__contains__(self, name)

    def __missing__(self, name: str) -> dict[str, Any]:
        if name in self:
            return dict.__getitem__(self, name)
        raise KeyError(name)

    def get(self, name: str, default: Any = None) -> Any:
        return self[name] if name in self else default

    def keys(self) -> list[str]:
        """The names an unknown env's error lists: the registry's (envs.EnvRegistry.keys)."""
        return envs.REGISTRY.keys()


# Per env, defaults over the dataclasses' (hintsjax.settings.algorithm_settings, hintsjax.settings.config.RunConfig).
ENV_DEFAULTS: EnvDefaults = EnvDefaults({name: _env_defaults(entry.training) for name, entry in envs.REGISTRY.items()})
