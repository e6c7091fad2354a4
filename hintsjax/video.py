"""A short GIF of a trained agent: one episode, with its hint drawn beside the picture.

    python -m hintsjax.video runs/<run folder> [--seed 0] [--variant swingto] [--steps 300]
                             [--scale 4] [--out v.gif] [--fps 25]

One seed's params act as the run is evaluated; the episode and its frames are
hintsjax/evaluation/recording.py.
"""

from __future__ import annotations

import argparse
import functools
import sys
from pathlib import Path

import jax

from hintsjax import envs
from hintsjax.system import checkpoint, folder_lock, memory, paths
from hintsjax.cli.arguments import ArgumentParser, int32_arg
from hintsjax.system.errors import UsageError, command
from hintsjax.system.refusals import sized_by
from hintsjax.settings.config import env_params
from hintsjax.settings.layers import load_run_config
from hintsjax.cli import choices
from hintsjax.algorithms.registry import make_trainer
from hintsjax.evaluation.evaluator import eval_keys
from hintsjax.evaluation.recording import (
    MAX_STEPS,
    compose_frames,
    frame_shape,
    hint_labels,
    rollout,
    write_gif,
)


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(
        prog="python -m hintsjax.video",
        description=__doc__.splitlines()[0],
        epilog=choices.text(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run", type=Path, help="a run folder written by python -m hintsjax.run")
    parser.add_argument(
        "--seed", type=int32_arg, default=0, help="which of the run's seeds acts (default: 0)"
    )
    parser.add_argument("--variant", default=None, help="env variant (default: the training one)")
    parser.add_argument(
        "--steps",
        type=int32_arg,
        default=None,
        help=f"at most this many steps (default: the episode, at most {MAX_STEPS})",
    )
    parser.add_argument(
        "--scale",
        type=int32_arg,
        default=4,
        help="picture upscaling, nearest neighbour (default: 4)",
    )
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help="GIF path (default: RUN/video-<variant>-seed<seed>.gif)",
    )
    parser.add_argument("--fps", type=int32_arg, default=25, help="frames per second (default: 25)")
    args = parser.parse_args(argv)
    cfg = load_run_config(args.run)
    folder_lock.say_if_training(args.run)
    variant = args.variant or cfg.variant or envs.variant_names(cfg.env)[0]
    env_params(cfg.env, variant)
    if not 0 <= args.seed < cfg.seeds:
        raise UsageError(
            f"--seed must be in [0, {cfg.seeds}) for this run of {cfg.seeds} seeds, got {args.seed}"
        )
    env = cfg.make_env(deploy=True)
    steps = min(env.max_steps, MAX_STEPS) if args.steps is None else args.steps
    for name, value in (("--steps", steps), ("--scale", args.scale), ("--fps", args.fps)):
        if value <= 0:
            raise UsageError(f"{name} must be positive, got {value}")
    memory.check_video(args.scale, steps, functools.partial(frame_shape, env.image_size))
    out = args.out or args.run / f"video-{variant}-seed{args.seed}.gif"
    paths.check_file(out, "--out")
    state, _ = checkpoint.restore_latest(args.run, make_trainer(cfg).abstract_state())
    params = jax.tree.map(lambda x: x[args.seed], state.params)
    with sized_by("--steps or --scale"):  # an allocation that fails anyway: one line naming them
        episode = rollout(cfg, params, variant, steps, eval_keys(cfg)[args.seed]).cut()
        frames = compose_frames(episode, hint_labels(env.hint), args.scale, env.max_steps)
    out.parent.mkdir(parents=True, exist_ok=True)
    paths.write_whole(out, lambda part: write_gif(frames, part, args.fps))
    ended = "episode ended" if episode.done.any() else f"cut at {steps} steps"
    print(
        f"{out}: {len(frames)} frames, return {float(episode.rewards.sum()):.2f} "
        f"({cfg.label} on {cfg.env}/{variant}, seed {args.seed}, {ended})"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
