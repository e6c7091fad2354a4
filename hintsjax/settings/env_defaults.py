"""Each env's training defaults as RunConfig layers (`ENV_DEFAULTS`), read from the `TRAINING`
beside each env (envs/<env>.py, the registry's `training`), where the paper's budgets, Table 5's
actor rates and the reasons for each deviation are written. A config value of `None` means "the
env's default" (hintsjax.settings.layers.run_config stacks the layers).

A `TRAINING` is plain layers: its settings (every agent's), `learners` (a layer for every agent but
the converged references, `agents.REFERENCES`) and `agents` (an agent's own layer)."""

from __future__ import annotations

from typing import Any, Mapping

from hintsjax import envs
from hintsjax.models.agents import AGENTS, REFERENCES


def stack_layers(*layers: Mapping[str, Any]) -> dict[str, Any]:
    """Later layers override earlier ones, key by key and a section's (a mapping's) setting by
    setting; None is no value (hintsjax.settings.layers.run_config stacks a run's layers with it
    too)."""
    merged: dict[str, Any] = {}
    for layer in layers:
        for k, v in layer.items():
            if v is None:
                continue
            if isinstance(v, Mapping):
                merged[k] = {
                    **merged.get(k, {}),
                    **{sk: sv for sk, sv in v.items() if sv is not None},
                }
            else:
                merged[k] = v
    return merged


def _env_defaults(training: Mapping[str, Any]) -> dict[str, Any]:
    """An env's training defaults as RunConfig layers: its own settings, and per agent its layer
    (`learners` for every agent but the references, then the agent's own from `agents`)."""
    training = dict(training)
    learners, own = training.pop("learners", {}), dict(training.pop("agents", {}))
    unknown = sorted(set(own) - set(AGENTS))
    if unknown:
        raise ValueError(
            f"TRAINING's agents names {', '.join(unknown)}; valid: {', '.join(AGENTS)}"
        )
    agents = {
        name: stack_layers(learners if name not in REFERENCES else {}, own.get(name, {}))
        for name in AGENTS
    }
    return {**training, "agents": {name: layer for name, layer in agents.items() if layer}}


class EnvDefaults(dict):
    """ENV_DEFAULTS: the suite's envs' defaults, and those of any env the registry gained since
    (an adapted `playground:<task>` or `brax:<name>`, from its adapter's table, envs/playground.py;
    or an entry registered at run time, from its `training`), added when first looked up."""

    def __contains__(self, name: object) -> bool:
        # adapts a `<source>:<task>`
        if not dict.__contains__(self, name) and name in envs.REGISTRY:
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


# Per env, defaults over the dataclasses' (hintsjax.settings.algorithm_settings,
# hintsjax.settings.config.RunConfig).
ENV_DEFAULTS: EnvDefaults = EnvDefaults(
    {name: _env_defaults(entry.training) for name, entry in envs.REGISTRY.items()}
)
