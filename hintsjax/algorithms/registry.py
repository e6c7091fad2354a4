"""The training algorithms by name: an agent's `algorithm` (hintsjax.models.agents) picks its
trainer."""

from __future__ import annotations

from typing import Any, Callable

from hintsjax.settings.config import RunConfig
from hintsjax.algorithms import dagger, gail, ppo
from hintsjax.algorithms.trainer import Trainer

ALGORITHMS: dict[str, Callable[..., Trainer]] = {
    "ppo": ppo.make_trainer,
    "dagger": dagger.make_trainer,  # learns from an expert (hintsjax.expert)
    "gail": gail.make_trainer,  # learns from an expert (hintsjax.expert)
}


def make_trainer(cfg: RunConfig, expert: Any = None) -> Trainer:
    """The trainer of a validated RunConfig; `expert` replaces the packaged one for imitation
    agents."""
    build = ALGORITHMS[cfg.agent_spec.algorithm]
    return build(cfg, expert) if cfg.agent_spec.imitates else build(cfg)
