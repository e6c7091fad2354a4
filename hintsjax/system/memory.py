"""Memory a command must have, bounded from below before anything is compiled or written.

A size that cannot fit (`seeds=1000000000`, `eval_episodes=100000000`, `video --scale 3000`) is
one line naming the setting and the largest value the bound allows, instead of a host that fills
its memory for minutes or an out-of-memory error after training. The bounds count only what
must be held at once:

- training: a rollout's pictures (uint8), actions, rewards and values, for every seed a device
  holds;
- evaluation: the picture of every seed's every episode, all stepped in one call, and its
  policy's widest layer of activations;
- a video: its frames, upscaled, on the host.

More of what it owns and why: docs/design.md, "Module notes", hintsjax/system/memory.py.
"""

from __future__ import annotations

import os
from typing import Any, Callable

import jax

from hintsjax import envs
from hintsjax.envs.frames import GREY
from hintsjax.system.errors import UsageError


def sized(n: float) -> str:
    """Bytes as the largest unit that keeps the number at least 1 (binary units)."""
    for unit in ("B", "KiB", "MiB", "GiB", "TiB", "PiB"):
        if n < 1024 or unit == "PiB":
            return f"{n:.0f} {unit}" if unit == "B" else f"{n:.1f} {unit}"
        n /= 1024
    raise AssertionError  # the loop returns at PiB


def host_bytes() -> int:
    """The host's physical memory."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def device_bytes(device: Any = None) -> int:
    """What one device may hold: a GPU's allocator limit, else (the CPU) the host's memory."""
    device = device or jax.local_devices()[0]
    stats = device.memory_stats() if device.platform != "cpu" else None
    return int(stats["bytes_limit"]) if stats and "bytes_limit" in stats else host_bytes()


def picture_bytes(cfg: Any) -> int:
    """One observation's pictures (uint8 [S, S, C x frames], C 3 or 1 grey), or 0 for an agent
    that sees none."""
    if "pixels" not in cfg.agent_spec.observe:
        return 0
    channels = 1 if cfg.colour == GREY else 3
    return channels * cfg.frames * (cfg.image_size or envs.REGISTRY[cfg.env].cls.image_size) ** 2


def transition_bytes(cfg: Any) -> int:
    """What a rollout keeps of one step at least: its picture, action, reward, value, done flag."""
    return picture_bytes(cfg) + 4 * (envs.REGISTRY[cfg.env].cls.action_size + 3)


def check_run(cfg: Any, seeds_per_device: int) -> None:
    """UsageError where a run's rollouts or its evaluation cannot fit on a device holding
    `seeds_per_device` of its seeds."""
    have, step = device_bytes(), transition_bytes(cfg)
    seed = cfg.ppo.batch_size * step
    if seed > have:
        raise UsageError(
            f"ppo.batch_size={cfg.ppo.batch_size} cannot fit: one seed's rollout holds at least "
            f"{sized(seed)}, a device has {sized(have)} (at most {have // step} transitions a seed)"
        )
    if seeds_per_device * seed > have:
        raise UsageError(
            f"seeds={cfg.seeds} cannot fit: {seeds_per_device} seeds a device hold at least "
            f"{sized(seeds_per_device * seed)} of rollouts ({sized(seed)} a seed), a device has "
            f"{sized(have)} (at most {have // seed} seeds a device)"
        )
    check_episodes(cfg, seeds_per_device, cfg.eval_episodes, "eval_episodes")


def episode_bytes(cfg: Any) -> int:
    """What evaluating one episode holds at least at each step: a transition (`transition_bytes`)
    and the activations of the policy's widest hidden layer (float32), which every episode computes
    at once (pendulum's ppo_state asked for 446.5 GB for 10^8 episodes a seed, issue 62, where
    the transitions counted 8 GB)."""
    return transition_bytes(cfg) + 4 * max(cfg.ppo.hidden)


def check_episodes(cfg: Any, seeds_per_device: int, episodes: int, key: str) -> None:
    """UsageError where evaluating `episodes` episodes of each of `seeds_per_device` seeds at
    once cannot fit on a device (`key` names the setting in the message)."""
    # at least an action, reward, value and flag: never 0
    have, one = device_bytes(), episode_bytes(cfg)
    need = seeds_per_device * episodes * one
    if need > have:
        raise UsageError(
            f"{key}={episodes} cannot fit: evaluating {seeds_per_device} seeds x {episodes} "
            f"episodes at once holds at least {sized(need)} of pictures, actions and activations, "
            f"a device has {sized(have)} (at most {have // (seeds_per_device * one)} episodes)"
        )


def check_video(scale: int, frames: int, frame_shape: Callable[[int], tuple[int, int]]) -> None:
    """UsageError where a video's `frames` frames (uint8 RGB of `frame_shape(scale)`, on the host
    until written) cannot fit in the host's memory."""
    have = host_bytes()

    def need(s: int) -> int:
        height, width = frame_shape(s)
        return frames * 3 * height * width

    if need(scale) > have:
        most, over = 0, scale  # the largest scale that fits lies in [most, over)
        while over - most > 1:
            mid = (most + over) // 2
            most, over = (mid, over) if need(mid) <= have else (most, mid)
        raise UsageError(
            f"--scale {scale} cannot fit: {frames} frames hold {sized(need(scale))}, the host has "
            f"{sized(have)} (at most --scale {most})"
        )
