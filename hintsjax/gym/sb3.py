"""A hintsjax vector env as a Stable-Baselines3 `VecEnv` (the `gym` extra), so SB3's algorithms take
it as they take their own `DummyVecEnv`:

    venv = hintsjax.gym.sb3.VecEnv(gymnasium.make_vec("hintsjax/pendulum-v0", num_envs=16))
    PPO("MultiInputPolicy", venv).learn(100_000)

SB3 resets where an episode ends in the same step, as the vector env does
(`AutoresetMode.SAME_STEP`), so this only renames: `terminated | truncated` is SB3's `done`, an
ended episode's last observation its info's `terminal_observation`, and a time limit
`TimeLimit.truncated`. The batch is stepped in one call, not env by env.
"""

from __future__ import annotations

from typing import Any

import gymnasium
import numpy as np

try:
    from stable_baselines3.common import vec_env as _sb3
except ImportError:  # one line, not the import's traceback
    raise ImportError("hintsjax.gym.sb3 needs Stable-Baselines3: pip install -e '.[gym]'") from None


class VecEnv(_sb3.VecEnv):
    """SB3's view of a Gymnasium vector env whose autoreset mode is SAME_STEP (hintsjax.gym's)."""

    def __init__(self, venv: gymnasium.vector.VectorEnv):
        mode = venv.metadata.get("autoreset_mode")
        if mode != gymnasium.vector.AutoresetMode.SAME_STEP:
            raise ValueError(
                "SB3 resets in the step an episode ends (autoreset_mode SAME_STEP); this env's is "
                f"{mode}"
            )
        self.venv = venv
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None

    def reset(self) -> Any:
        """The first observations; seeds set by `seed(s)` (env i gets s + i) are used once."""
        seeds = None if self._seeds[0] is None else list(self._seeds)
        obs, _ = self.venv.reset(seed=seeds)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> tuple[Any, np.ndarray, np.ndarray, list[dict[str, Any]]]:
        obs, reward, terminated, truncated, info = self.venv.step(self._actions)
        done = terminated | truncated
        infos: list[dict[str, Any]] = [
            {"TimeLimit.truncated": bool(truncated[i] and not terminated[i])}
            for i in range(self.num_envs)
        ]
        for i in np.flatnonzero(done):
            infos[i]["terminal_observation"] = info["final_obs"][i]
        return obs, reward.astype(np.float32), done, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        """The vector env's attribute, once per env asked for (`render_mode` is None)."""
        value = None if attr_name == "render_mode" else getattr(self.venv, attr_name)
        return [value for _ in self._get_indices(indices)]

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(
        self, method_name: str, *method_args, indices: Any = None, **method_kwargs
    ) -> list[Any]:
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result for _ in self._get_indices(indices)]

    def env_is_wrapped(
        self, wrapper_class: type[gymnasium.Wrapper], indices: Any = None
    ) -> list[bool]:
        return [False for _ in self._get_indices(indices)]
