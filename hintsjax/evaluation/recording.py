"""A short GIF of a trained agent: one episode, with its hint drawn beside the picture.

One seed's params act as the run is evaluated (the policy mean, or sampled actions where the
run's `stochastic_eval` is on: the car's default) for up to `steps` steps in a single jitted scan
(frames stop where the episode ends). Each frame is the env's picture, upscaled by `scale`
(nearest neighbour), beside the agent's hint as labelled bars (none for an agent without a
hint), the step and the return so far. The command is `python -m hintsjax.video`
(hintsjax/video.py).
"""

from __future__ import annotations

import functools
from pathlib import Path
from typing import Any, Callable, Sequence

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from hintsjax import envs
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms.ppo import deploy_view, make_network
from hintsjax.algorithms.ppo_math import gaussian_sample

MAX_STEPS = 300  # the default --steps: the env's episode, capped here
PANEL_WIDTH = 240  # pixels of the text-and-bars panel right of the picture
MIN_HEIGHT = 176  # pixels: a small picture is padded to this height, so the text still fits
DPI = 80
MIN_ROWS = 5  # rows of bars a panel has room for, so that a short hint's bars stay slim
MAX_BARS = 12  # hint values drawn as bars; a longer hint (e.g. a locomotion state) is cut here
BAR_COLOR = "#1f77b4"


@struct.dataclass
class Rollout:
    """One episode's fixed-size record, [T] steps; only the steps where `valid` belong to it.

    Step t's entries describe the state reached by step t's action: its picture, its hint, the
    reward of that step and whether the episode ended there.
    """

    frames: jax.Array  # uint8[T, S, S, 3]
    hints: jax.Array  # float32[T, d] (d = 0 for an agent without a hint)
    rewards: jax.Array  # float32[T]
    done: jax.Array  # bool[T]: terminated | truncated on this step
    valid: jax.Array  # bool[T]: the step is part of the episode (it started before the end)

    def cut(self) -> "Rollout":
        """The episode's steps only, as numpy arrays on the host."""
        host = jax.tree.map(np.asarray, self)
        n = int(host.valid.sum())
        return jax.tree.map(lambda x: x[:n], host)


def step_keys(key: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(reset key, run key) of a rollout; step t's env key is `fold_in(run key, t)`."""
    k_reset, k_run = jax.random.split(key)
    return k_reset, k_run


def policy_action(
    network: Any, params: Any, obs: dict[str, jax.Array], key: jax.Array | None = None
) -> jax.Array:
    """The policy mean for one unbatched observation, or with `key` an action sampled around it."""
    mean, log_std, _ = network.apply(params, jax.tree.map(lambda x: x[None], obs))
    if key is None:
        return mean[0]
    return gaussian_sample(key, mean[0], jnp.broadcast_to(log_std, mean.shape)[0])


def rollout(
    cfg: RunConfig, params: Any, variant: str | None, steps: int, key: jax.Array
) -> Rollout:
    """One episode of one seed's `params` on `variant`, `steps` steps long at most, acting as the
    run is evaluated (sampled actions where `cfg.stochastic_eval`)."""
    variant = envs.variant_names(cfg.env)[0] if variant is None else variant
    return make_rollout(cfg, variant, steps)(params, key)


@functools.lru_cache(maxsize=8)
def make_rollout(cfg: RunConfig, variant: str, steps: int) -> Callable[[Any, jax.Array], Rollout]:
    """The jitted `run(params, key) -> Rollout` behind `rollout`, kept: seeds share one compile."""
    env = cfg.make_env(deploy=True)
    task_params = cfg.task_params(variant, deploy=True)
    network = make_network(cfg, env)

    @jax.jit
    def run(params: Any, key: jax.Array) -> Rollout:
        k_reset, k_run = step_keys(key)
        ts = env.reset(k_reset, task_params)

        def step(carry, t):
            state, obs, alive = carry
            k_env = jax.random.fold_in(k_run, t)
            # its privileged inputs (a baseline's hint) are zeros
            seen = deploy_view(obs, cfg.agent_spec)
            action = policy_action(
                network, params, seen, jax.random.fold_in(k_env, 1) if cfg.stochastic_eval else None
            )
            ts = env.step(k_env, state, action, task_params)
            done = ts.terminated | ts.truncated
            record = Rollout(
                frames=env.render(ts.state, task_params),
                hints=env.hint(ts.state, task_params),
                rewards=ts.reward,
                done=done,
                valid=alive,
            )
            return (ts.state, ts.obs, alive & ~done), record

        _, records = jax.lax.scan(step, (ts.state, ts.obs, jnp.ones((), bool)), jnp.arange(steps))
        return records

    return run


def hint_labels(hint: envs.Hint) -> list[str]:
    """`name[i] (unit)` for every value of `hint`, in order; a unit listed per value
    (e.g. "1, 1, rad/s") goes to its own value."""
    labels = []
    for part in hint.parts:
        units = [u.strip() for u in part.unit.split(",")]
        if len(units) != part.dim:
            units = [part.unit] * part.dim
        labels.extend(f"{part.name}[{i}] ({u})" for i, u in enumerate(units))
    return labels


def hint_limits(hints: np.ndarray) -> np.ndarray:
    """Each hint value's bar scale: its largest magnitude over the episode (a full bar)."""
    if hints.shape[0] == 0:
        return np.ones(hints.shape[1], np.float32)
    return np.maximum(np.abs(hints).max(axis=0), 1e-6)


def frame_shape(image_size: int, scale: int) -> tuple[int, int]:
    """(height, width) in pixels of a composed frame."""
    side = image_size * scale
    return max(side, MIN_HEIGHT), side + PANEL_WIDTH


class FrameComposer:
    """Draws frames of one video: a matplotlib figure (Agg, no pyplot) built once, updated per
    frame."""

    def __init__(
        self,
        labels: Sequence[str],
        limits: np.ndarray,
        image_size: int,
        scale: int,
        max_steps: int | None = None,
    ):
        # here: matplotlib takes about a second to import, and only a video draws with it
        from matplotlib.backends.backend_agg import FigureCanvasAgg
        from matplotlib.figure import Figure

        self.scale, self.max_steps = scale, max_steps
        self.height, _ = frame_shape(image_size, scale)
        self.labels = list(labels)[:MAX_BARS]
        self.limits = np.asarray(limits, np.float32)[:MAX_BARS]
        self.fig = Figure(
            figsize=(PANEL_WIDTH / DPI, self.height / DPI), dpi=DPI, facecolor="white"
        )
        self.canvas = FigureCanvasAgg(self.fig)
        top = 1.0 - 42.0 / self.height  # two text lines at the top
        self.step_text = self.fig.text(
            0.04, 1.0 - 6.0 / self.height, "", fontsize=9, va="top", family="monospace"
        )
        self.return_text = self.fig.text(
            0.04, 1.0 - 22.0 / self.height, "", fontsize=9, va="top", family="monospace"
        )
        self.bars, self.bar_texts = [], []
        n = len(self.labels)
        if not n:
            self.fig.text(
                0.04,
                1.0 - 44.0 / self.height,
                "(the agent sees no hint)",
                fontsize=7,
                va="top",
                color="0.4",
            )
        else:
            ax = self.fig.add_axes((0.04, 0.03, 0.92, top - 0.05))
            ax.set_xlim(-1.0, 1.0)
            ax.set_ylim(max(n, MIN_ROWS) - 0.4, -0.9)  # row 0 at the top, its label above its bar
            ax.axvline(0.0, color="0.6", lw=0.8)
            ax.set_xticks([])
            ax.set_yticks([])
            for spine in ax.spines.values():
                spine.set_visible(False)
            self.bars = list(ax.barh(np.arange(n), np.zeros(n), height=0.35, color=BAR_COLOR))
            self.bar_texts = [ax.text(-1.0, i - 0.3, "", fontsize=7, va="bottom") for i in range(n)]
            if len(labels) > MAX_BARS:
                self.fig.text(
                    0.96,
                    0.01,
                    f"+{len(labels) - MAX_BARS} more",
                    fontsize=6,
                    ha="right",
                    color="0.4",
                )

    def __call__(
        self, picture: np.ndarray, hint: np.ndarray, step: int, episode_return: float
    ) -> np.ndarray:
        """uint8[H, W, 3]: the upscaled `picture` beside the panel for this step."""
        total = f"/{self.max_steps}" if self.max_steps else ""
        self.step_text.set_text(f"step {step}{total}")
        self.return_text.set_text(f"return {episode_return:.2f}")
        for bar, text, label, value, limit in zip(
            self.bars, self.bar_texts, self.labels, hint, self.limits
        ):
            bar.set_width(float(np.clip(value / limit, -1.0, 1.0)))
            text.set_text(f"{label}: {value:+.3f}")
        self.canvas.draw()
        panel = np.asarray(self.canvas.buffer_rgba())[..., :3]
        panel = _fit(panel, self.height, PANEL_WIDTH)
        big = np.repeat(
            np.repeat(np.asarray(picture, np.uint8), self.scale, axis=0), self.scale, axis=1
        )
        return np.concatenate([_fit(big, self.height, big.shape[1]), panel], axis=1)


def _fit(image: np.ndarray, height: int, width: int) -> np.ndarray:
    """`image` cropped or padded with white (kept at the top left) to exactly height x width."""
    out = np.full((height, width, 3), 255, np.uint8)
    h, w = min(height, image.shape[0]), min(width, image.shape[1])
    out[:h, :w] = image[:h, :w]
    return out


def compose_frame(
    picture: np.ndarray,
    hint: np.ndarray,
    labels: Sequence[str],
    step: int,
    episode_return: float,
    scale: int = 4,
    limits: np.ndarray | None = None,
) -> np.ndarray:
    """One frame on its own (a video reuses a FrameComposer instead): uint8[H, W, 3].

    `limits` are the magnitudes that fill a bar (default: each value's own, a full bar).
    """
    hint = np.asarray(hint, np.float32)
    limits = np.maximum(np.abs(hint), 1e-6) if limits is None else limits
    return FrameComposer(labels, limits, picture.shape[0], scale)(
        picture, hint, step, episode_return
    )


def compose_frames(
    episode: Rollout, labels: Sequence[str], scale: int, max_steps: int | None = None
) -> list[np.ndarray]:
    """Every frame of a cut rollout (host arrays); frame t shows the state after step t + 1."""
    composer = FrameComposer(
        labels, hint_limits(episode.hints), episode.frames.shape[1], scale, max_steps
    )
    returns = np.cumsum(episode.rewards, dtype=np.float64)
    return [
        composer(episode.frames[t], episode.hints[t], t + 1, float(returns[t]))
        for t in range(len(episode.frames))
    ]


def write_gif(frames: Sequence[np.ndarray], path: Path, fps: int = 25) -> None:
    """Write uint8[H, W, 3] frames as a looping GIF."""
    from PIL import Image  # here, as matplotlib above: only writing a GIF needs it

    images = [Image.fromarray(np.asarray(f, np.uint8)) for f in frames]
    images[0].save(
        path,
        format="GIF",
        save_all=True,
        append_images=images[1:],
        duration=max(1, round(1000 / fps)),
        loop=0,
    )
