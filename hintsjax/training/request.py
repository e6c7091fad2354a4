"""What a run command asks for, checked: a new run (its config and folder) or a resumed one (its
folder's config, perhaps trained longer), refused in one line (UsageError) before any folder is made
or anything compiled."""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

from hintsjax.system import memory, paths
from hintsjax.system.errors import UsageError
from hintsjax.settings.config import RunConfig
from hintsjax.settings.layers import load_run_config, run_config, to_dict
from hintsjax.cli import overrides
from hintsjax.algorithms import experts
from hintsjax.training.compilation import seed_layout


def folder_settings(values: dict[str, Any]) -> tuple[str | None, str, str | None]:
    """(resume, out_dir, name) popped from `values` as strings, whatever YAML made of them
    (`name=2024` is a folder name, not a number); UsageError for a name that is not one folder's
    name inside out_dir (a path separator, `..`, or nothing)."""
    resume, out_dir, name = (
        values.pop(k, default)
        for k, default in (("resume", None), ("out_dir", "runs"), ("name", None))
    )
    resume, out_dir, name = (
        None if v is None else str(v).lower() if isinstance(v, bool) else str(v)
        for v in (resume, out_dir, name)
    )
    if name is not None and (
        not name.strip() or name in (".", "..") or any(sep in name for sep in ("/", "\\"))
    ):
        raise UsageError(
            f"name must be one folder's name inside out_dir (no '/', '\\' or '..'), got {name!r}"
        )
    return resume, out_dir or "runs", name


def refuse_overrides_on_resume(values: dict[str, Any]) -> None:
    """UsageError naming the settings given beside `resume` (a resumed run continues as it was
    configured: its config.yaml decides); values equal to the command line's defaults are none."""
    defaults = overrides.defaults()
    given = []
    for key, value in values.items():
        if key == "compilation_cache":
            continue
        default = defaults.get(key)
        if isinstance(value, dict):
            given += [f"{key}.{k}={v}" for k, v in value.items() if v != (default or {}).get(k)]
        elif value != default:
            given.append(f"{key}={value}")
    if given:
        raise UsageError(
            f"resume continues a run as its config.yaml says; drop {' '.join(given)} "
            "(or start a new run)"
        )


@dataclasses.dataclass(frozen=True)
class Request:
    """What a command line asks for, checked: a new run (`cfg`, to go in out_dir/name) or a
    resumed one (`run_dir`, its config read from there)."""

    cfg: RunConfig
    run_dir: Path | None
    out_dir: str
    name: str | None
    # a resumed run given a larger ppo.total_env_steps (its config.yaml is rewritten)
    longer: bool = False


def checked_request(values: dict[str, Any]) -> Request:
    """The run that plain config values (what Hydra resolved) ask for; UsageError for anything
    that cannot run, found before any folder is made or anything compiled."""
    values = dict(values)
    values.pop("compilation_cache", None)
    resume, out_dir, name = folder_settings(values)
    steps = None
    if resume is not None:
        values["ppo"] = dict(values.get("ppo") or {})
        # the one setting a resumed run may change
        steps = values["ppo"].pop("total_env_steps", None)
        refuse_overrides_on_resume(values)
        run_dir = Path(resume)
        # a missing or bad checkpoint is reported by train's restore
        cfg = load_run_config(run_dir, complete=True)
        if steps is not None:
            cfg = train_longer(cfg, steps)
    else:
        cfg, run_dir = run_config(values), None
        paths.check_folder(out_dir, "out_dir")
    if cfg.agent_spec.imitates:
        experts.describe(cfg.env, cfg.expert)  # a missing or foreign expert
    # seed_layout refuses a Warp run it cannot place; then sizes that cannot fit, before the seeds'
    # keys are drawn
    memory.check_run(cfg, seed_layout(cfg).per_device)
    return Request(cfg, run_dir, out_dir, name, longer=steps is not None)


def rounded_budget(cfg: RunConfig) -> str | None:
    """The one line saying what a budget that is not a whole number of updates was rounded down
    to (`ppo.total_env_steps=300` with batches of 64 trains 256 steps a seed); None where it is."""
    ppo = cfg.ppo
    if ppo.total_env_steps % ppo.batch_size == 0:
        return None
    return (
        f"note: ppo.total_env_steps={ppo.total_env_steps} is not a multiple of "
        f"ppo.batch_size={ppo.batch_size}: "
        f"trains {ppo.num_updates} updates, {ppo.num_updates * ppo.batch_size} env steps a seed"
    )


def train_longer(cfg: RunConfig, steps: Any) -> RunConfig:
    """cfg with a budget of `steps` env steps a seed, for a resumed run to train on to; UsageError
    for a budget smaller than the one it was started with. The learning rates are constant, so
    training on from the saved state is the longer run, update for update."""
    saved = to_dict(cfg)
    longer = run_config({**saved, "ppo": {**saved["ppo"], "total_env_steps": steps}}, resolved=True)
    if longer.ppo.num_updates < cfg.ppo.num_updates:
        raise UsageError(
            f"a resumed run can train longer, not shorter: ppo.total_env_steps must be at least "
            f"{cfg.ppo.total_env_steps} (its budget), got {steps}"
        )
    return longer
