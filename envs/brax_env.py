"""Brax's environments as hintsjax envs: `env=brax:<name>` (docs/playground.md).

A `brax.envs.Env` is made by `brax.envs.get_environment` on Brax's MJX backend (its state's
`pipeline_state` is then an `mjx.Data`, which the picture and the hints read), stepped by its
own `step` and adapted by envs/adapter.py, with Brax's training episode length, 1000 steps.
Brax's own registry lists the names; those without an MJX model (`fast`, and `swimmer`, which
Brax 0.14 runs on its other backends only) do not load.
"""

from __future__ import annotations

import warnings
from typing import Any

import brax.envs

from hintsjax.envs.adapter import EnvUnavailable, Task
from hintsjax.envs.errors import ChoiceError

SOURCE = "brax"
EPISODE_LENGTH = 1000  # brax.training's default episode_length (its EpisodeWrapper's time limit)
TRAINING: dict[str, Any] = dict(
    hint="reward", ppo=dict(total_env_steps=1_000_000, num_envs=128, encoder_lr=3e-4, epochs=4)
)


def names() -> list[str]:
    """Every env Brax registers (brax.envs keeps them in `_envs`: it has no public list)."""
    return sorted(brax.envs._envs)


def load(name: str) -> Task:
    """Brax's env `name` on its MJX backend; ChoiceError naming Brax's envs for an unknown one,
    EnvUnavailable for one without an MJX model."""
    if name not in brax.envs._envs:
        raise ChoiceError("Brax env", name, names())
    try:
        with warnings.catch_warnings():
            # Brax's note that its own pipelines are unmaintained (we use MJX's)
            warnings.simplefilter("ignore")
            env = brax.envs.get_environment(name, backend="mjx")
        mj_model = env.sys.mj_model
    except Exception as e:  # noqa: BLE001  Brax's own failure, in one line
        raise EnvUnavailable(
            f"brax:{name} does not load on Brax's MJX backend: {type(e).__name__}: "
            f"{str(e).splitlines()[0][:200] if str(e) else ''}"
        ) from None
    return Task(f"{SOURCE}:{name}", env, mj_model, "pipeline_state", EPISODE_LENGTH)


def training(name: str) -> dict[str, Any]:
    """Every Brax env's training defaults: the generic `reward` hint, the DeepMind Control tasks'
    PPO."""
    return dict(hint=TRAINING["hint"], ppo=dict(TRAINING["ppo"]))
