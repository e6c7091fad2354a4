"""Evaluation: every training seed times N fresh episodes in one jitted call.

    python -m hintsjax.evaluate runs/<run folder> [--variant swingto] [--episodes 50]
                                [--stochastic | --deterministic]
                                [--hint-source runs/<generator folder>]

(by default sampled or not as the run's `stochastic_eval`: the car samples, the others take the
mean). Writes eval-<variant>-<mode>-<episodes>.json into the run folder; the evaluation itself is
hintsjax/evaluation/evaluator.py.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path


from hintsjax.system import checkpoint, folder_lock, memory, paths
from hintsjax.system.devices import SeedLayout
from hintsjax.cli.arguments import ArgumentParser, int32_arg
from hintsjax.system.errors import UsageError, command
from hintsjax.system.refusals import sized_by
from hintsjax.settings.config import env_params
from hintsjax.settings.hint_sources import PROGRAMMATIC
from hintsjax.settings.layers import load_run_config
from hintsjax.cli import choices
from hintsjax.algorithms.registry import make_trainer
from hintsjax.evaluation.evaluator import evaluate_variants, metrics_text
from hintsjax.evaluation.outliers import far_below_text


@command
def main(argv: list[str] | None = None) -> int:
    parser = ArgumentParser(
        prog="python -m hintsjax.evaluate",
        description=__doc__.splitlines()[0],
        epilog=choices.text(),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("run", type=Path, help="a run folder written by python -m hintsjax.run")
    parser.add_argument(
        "--variant",
        default=None,
        help="env variant(s) to evaluate on, comma-separated, all by one compiled program "
        "(default: the training one)",
    )
    parser.add_argument(
        "--episodes", type=int32_arg, default=None, help="episodes per seed (default: the run's)"
    )
    mode = parser.add_mutually_exclusive_group()
    mode.add_argument(
        "--stochastic",
        action="store_true",
        help="sample actions (default: as the run's stochastic_eval)",
    )
    mode.add_argument(
        "--deterministic",
        action="store_true",
        help="the mean action (default: as the run's stochastic_eval)",
    )
    parser.add_argument(
        "--hint-source",
        default=None,
        help="the agent's hints at deploy: programmatic, or a generator folder "
        "(hintsjax.generator); default: the run's eval_hint_source",
    )
    args = parser.parse_args(argv)
    cfg = load_run_config(args.run)
    folder_lock.say_if_training(args.run)
    if args.hint_source is not None:
        cfg = dataclasses.replace(cfg, eval_hint_source=args.hint_source).validate()
    variants = tuple(v.strip() for v in args.variant.split(",")) if args.variant else (cfg.variant,)
    for variant in variants:
        env_params(cfg.env, variant)
    episodes = cfg.eval_episodes if args.episodes is None else args.episodes
    if episodes <= 0:
        raise UsageError(f"--episodes must be positive, got {episodes}")
    memory.check_episodes(cfg, SeedLayout.of(cfg.seeds).per_device, episodes, "--episodes")
    state, _ = checkpoint.restore_latest(args.run, make_trainer(cfg).abstract_state())
    stochastic = args.stochastic or (cfg.stochastic_eval and not args.deterministic)
    with sized_by("--episodes"):  # an allocation that fails anyway: one line naming it
        results, _ = evaluate_variants(cfg, state.params, variants, episodes, stochastic)
    mode = "stochastic" if stochastic else "deterministic"
    source = cfg.hint_source_for(deploy=True)
    tag = "" if source == PROGRAMMATIC else f"-hints-{Path(source).name}"
    for result in results:
        out = args.run / f"eval-{result['variant']}-{mode}-{episodes}{tag}.json"
        text = json.dumps(
            {"label": cfg.label, "env": cfg.env, "hint_source": source, **result}, indent=1
        )
        paths.write_text_whole(out, text)
        print(
            f"{cfg.label} on {cfg.env}/{result['variant']} ({mode}, {cfg.seeds} seeds x {episodes} "
            "episodes"
            f"{'' if not tag else ', hints from ' + source}): "
            f"{result['mean']:.2f} +- {result['std']:.2f}{metrics_text(result)}  -> {out}"
        )
        if outliers := far_below_text(result, args.run):
            print(f"{cfg.label} on {cfg.env}/{result['variant']}: {outliers}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
