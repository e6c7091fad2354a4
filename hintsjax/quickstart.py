"""`make run`: a first agent that learns on a laptop's CPU in under three minutes.

    python -m hintsjax.quickstart [--updates 32] [--epochs 10] [--seed 0] [--out-dir runs]

The paper's main agent (pictures, the composite hint, FiLM) on the pendulum, one seed, at 36x36
pictures and PPO settings for short runs (QUICK_PPO); then an evaluation beside a random policy,
a GIF of one episode with its hint, and where the run folder is.

More of what it owns and why: docs/design.md, "Module notes", hintsjax/quickstart.py.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jax

from hintsjax.system import checkpoint, compilation_cache, paths
from hintsjax.cli.arguments import ArgumentParser, int32_arg
from hintsjax.system.errors import command
from hintsjax.system.refusals import writing_to
from hintsjax.cli import choices
from hintsjax.settings.config import RunConfig
from hintsjax.settings.layers import run_config, save_run_config
from hintsjax.algorithms.registry import make_trainer
from hintsjax.evaluation import recording
from hintsjax.evaluation.evaluator import eval_keys, evaluate_params
from hintsjax.training import outputs, pipeline, runlog

QUICK_PPO = {
    "batch_size": 3200,
    "minibatch_size": 200,
    "epochs": 6,
    "gamma": 0.95,
    "actor_lr": 3e-4,
    "starts_per_rollout": True,
}
SETTINGS = {
    "env": "pendulum",
    "agent": "hints",
    "hint": "composite",
    "scheme": "fc",
    "seeds": 1,
    "eval_episodes": 20,
    "eval_variants": (),
    "checkpoint_every": 8,
    "image_size": 36,
    "ppo": QUICK_PPO,
}
MAX_SEED = 2**31 - 1  # jax.random.key takes an int32-range seed here
BASELINE_JSON = "random_policy.json"


def random_policy(cfg: RunConfig, variant: str | None) -> dict:
    """The run's agent before training (its seeds' initial params), sampling its actions: a
    Gaussian random policy, evaluated on the same episodes as the trained agent."""
    initial = jax.jit(jax.vmap(make_trainer(cfg).init))(cfg.seed_keys())
    return evaluate_params(cfg, initial.params, variant, cfg.eval_episodes, stochastic=True)


def swing_up_gif(cfg: RunConfig, run_dir: Path, candidates: int = 8) -> Path:
    """A GIF of seed 0's trained agent on the episode, of `candidates` evaluation starts, that
    begins farthest from upright (its first reward the lowest): the one with the most to show."""
    state, _ = checkpoint.restore_latest(run_dir, make_trainer(cfg).abstract_state())
    params = jax.tree.map(lambda x: x[0], state.params)
    env = cfg.make_env()
    steps = min(env.max_steps, recording.MAX_STEPS)
    key = eval_keys(cfg)[0]
    episodes = [
        recording.rollout(cfg, params, cfg.variant, steps, jax.random.fold_in(key, i))
        for i in range(candidates)
    ]
    episode = min(episodes, key=lambda e: float(e.rewards[0])).cut()
    out = run_dir / "swing-up.gif"
    recording.write_gif(
        recording.compose_frames(episode, recording.hint_labels(env.hint), 4, env.max_steps),
        out,
        25,
    )
    print(f"{out}: {int(episode.valid.sum())} frames, return {float(episode.rewards.sum()):.2f}")
    return out


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(
        prog="python -m hintsjax.quickstart",
        description=__doc__.splitlines()[0],
        epilog="After it, python -m hintsjax.run trains any of these:\n\n" + choices.text(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    batch = SETTINGS["ppo"]["batch_size"]
    parser.add_argument(
        "--updates", type=int32_arg, default=32, help=f"updates of {batch} env steps (default: 32)"
    )
    parser.add_argument(
        "--out-dir",
        type=Path,
        default=Path("runs"),
        help="where the run folder goes (default: runs)",
    )
    parser.add_argument(
        "--epochs",
        type=int32_arg,
        default=SETTINGS["ppo"]["epochs"],
        help=f"PPO's epochs over each update's batch (default: {SETTINGS['ppo']['epochs']})",
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=0,
        help=f"the run's seed, 0 to {MAX_SEED} (default: 0, what the README shows)",
    )
    args = parser.parse_args(argv)
    if args.updates < 1:
        parser.exit(2, f"error: --updates must be at least 1, got {args.updates}\n")
    if args.epochs < 1:
        parser.exit(2, f"error: --epochs must be at least 1, got {args.epochs}\n")
    if not 0 <= args.seed <= MAX_SEED:
        parser.exit(2, f"error: --seed must be 0 to {MAX_SEED}, got {args.seed}\n")
    paths.check_folder(args.out_dir, "--out-dir")
    t = time.perf_counter()
    cfg = run_config(
        {
            **SETTINGS,
            "seed": args.seed,
            "ppo": {
                **SETTINGS["ppo"],
                "epochs": args.epochs,
                "total_env_steps": batch * args.updates,
            },
        }
    )
    compilation_cache.enable(compilation_cache.folder(True))
    with writing_to(args.out_dir):  # a full disk or read-only folder: one line naming it
        run_dir = outputs.new_run_dir(
            str(args.out_dir), f"quickstart-{time.strftime('%Y%m%d-%H%M%S')}", cfg
        )
        save_run_config(run_dir, cfg)
        trained = pipeline.train(cfg, run_dir)["evaluations"][0]
        # each is mostly a compile, one core's work: side by side
        with ThreadPoolExecutor(max_workers=2) as pool:
            baseline_done, gif_done = (
                pool.submit(random_policy, cfg, cfg.variant),
                pool.submit(swing_up_gif, cfg, run_dir),
            )
            baseline, gif = baseline_done.result(), gif_done.result()
        paths.write_text_whole(run_dir / BASELINE_JSON, json.dumps(baseline, indent=1))
    print(
        f"\n{cfg.env}/{trained['variant']}, {cfg.eval_episodes} episodes each "
        f"({time.perf_counter() - t:.0f} s in all):\n"
        f"  trained agent ({cfg.label}, {cfg.ppo.total_env_steps} env steps): "
        f"{trained['mean']:8.1f} +- {trained['std']:.1f}\n"
        f"  random policy (the agent before training, sampling its actions): "
        f"{baseline['mean']:8.1f} +- {baseline['std']:.1f}\n"
        f"run folder:     {run_dir}\n"
        f"learning curve: {run_dir / runlog.CURVE_PNG}\n"
        f"one episode:    {gif}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
