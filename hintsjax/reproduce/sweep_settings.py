"""--set KEY=VALUE: the top-level run settings a sweep gives every run (e.g. physics, the first
seed).

A table script reads and checks them before it plans its runs (hintsjax.reproduce.table_script), and
each worker reads them again from its own command line (`worker_settings`, python -m
hintsjax.reproduce.sweep --one ...), before JAX's backend starts.
"""

from __future__ import annotations

import argparse


def add_settings(parser: argparse.ArgumentParser) -> None:
    """The --set option (a table script's and a worker's)."""
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="KEY=VALUE",
        dest="settings",
        help="a top-level run setting for every run, e.g. --set physics=warp --set seed=10 "
        "(give each part of a row's seeds its own --runs folder)",
    )


def parsed_settings(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict:
    """--set's KEY=VALUE pairs, values as YAML reads them; exit 2 on one that is not KEY=VALUE.
    Starts nothing (a worker reads them before JAX's backend starts)."""
    import yaml

    settings = {}
    for item in args.settings:
        key, sep, value = item.partition("=")
        if not sep or not key:
            parser.exit(2, f"error: --set takes KEY=VALUE, got {item!r}\n")
        settings[key] = yaml.safe_load(value)
    return settings


def check_settings(parser: argparse.ArgumentParser, settings: dict) -> dict:
    """`settings`, or exit 2 in one line on one that RunConfig refuses (this starts JAX's backend:
    resolving the physics asks it for the platform)."""
    from hintsjax.system.errors import UsageError
    from hintsjax.settings.layers import run_config

    try:
        run_config({"env": "pendulum", **settings})
    except UsageError as e:
        parser.exit(2, f"error: --set: {e}\n")
    return settings


def chosen_settings(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict:
    """--set's settings, read and checked (a table script's, before it plans its runs)."""
    return check_settings(parser, parsed_settings(parser, args))


def worker_settings(parser: argparse.ArgumentParser, args: argparse.Namespace) -> dict:
    """A worker's --set settings, read and checked. Where every run it trains gets MJX-Warp
    (physics=warp, or auto for envs that prefer Warp on this machine's NVIDIA GPU) it trains without
    deterministic GPU ops (nothing repeats bit for bit under Warp's atomics), which it must say
    before the check starts JAX's backend."""
    from hintsjax import envs  # jax imported, its backend not started

    settings = parsed_settings(parser, args)
    physics = settings.get("physics", envs.AUTO)
    env_names = [run.split("/")[0] for run in getattr(args, "one", "").split(",") if run]
    if physics == envs.WARP or (env_names and all(envs.likely_warp(n, physics) for n in env_names)):
        from hintsjax.system import xla_flags

        xla_flags.drop_determinism()
    return check_settings(parser, settings)
