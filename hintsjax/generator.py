"""A learned hint generator: the hint read off the agent's own pictures instead of the simulator.

    python -m hintsjax.generator env=pendulum hint=composite seeds=5     # -> runs/generator-...
    python -m hintsjax.run env=pendulum hint=composite hint_source=runs/generator-...

The training and the folder it writes are hintsjax/hints/generators.py; the network, the env that
shows its hints and a folder's loading are hintsjax/settings/hint_sources.py.
"""

from __future__ import annotations

import sys


from hintsjax.system import paths
from hintsjax.system.errors import command
from hintsjax.system.refusals import writing_to
from hintsjax.cli.arguments import parse_key_values
from hintsjax.hints.generators import GeneratorConfig, train_folder


def parse(argv: list[str]) -> GeneratorConfig:
    """GeneratorConfig from `key=value` arguments; UsageError naming the valid keys."""
    cfg = parse_key_values(
        GeneratorConfig, argv, "python -m hintsjax.generator", __doc__.splitlines()[0]
    ).validate()
    # before the pictures are drawn and the generator trained
    paths.check_folder(cfg.out_dir, "out_dir")
    return cfg


@command
def main(argv: list[str] | None = None) -> int:
    cfg = parse(sys.argv[1:] if argv is None else argv)
    print(
        f"generator of {cfg.env}/{cfg.hint} from {cfg.frames} pictures: {cfg.seeds} seed(s), "
        f"{cfg.num_envs} x {cfg.steps} steps of {cfg.policy} rollouts, {cfg.epochs} epochs",
        flush=True,
    )
    with writing_to(cfg.out_dir):  # a full disk or read-only folder: one line naming it
        folder, meta = train_folder(cfg)
    r2 = ", ".join(f"{n} {v:.3f}" for n, v in zip(meta["dimensions"], meta["heldout_r2_mean"]))
    print(
        f"held-out R^2 (mean over seeds): {r2}; compile {meta['seconds']['compile']:.0f} s, "
        f"train {meta['seconds']['train']:.0f} s -> {folder}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
