"""Importing this registers every MuJoCo Playground task with Gymnasium as
`hintsjax/playground.<task>-v0` (the `playground` extra; its import takes seconds, so
`import hintsjax.gym` leaves it out). Gymnasium imports it for an id written with its prefix:
`gymnasium.make_vec("hintsjax.gym.playground:hintsjax/playground.CartpoleSwingup-v0", num_envs=8)`.
"""

from __future__ import annotations

from hintsjax.envs import playground
from hintsjax.gym import register_all

PLAYGROUND_IDS = register_all([f"{playground.SOURCE}:{name}" for name in playground.names()])
