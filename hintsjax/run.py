"""Train from the command line (Hydra), evaluate, and write one run folder.

    python -m hintsjax.run env=pendulum agent=hints hint=composite scheme=fc seeds=5
    python -m hintsjax.run -m scheme=lc,ac,fc,mc          # a sweep, one folder per run
    python -m hintsjax.run resume=runs/<folder>           # continue from the last checkpoint

A run folder holds config.yaml (resolved), metrics.csv, TensorBoard events (tb/), orbax
checkpoints of the full train state (checkpoints/), eval.json and learning_curve.png.
Bad input is reported in one line with the valid choices, exit status 2, nothing written.
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

import hydra
import jax
import numpy as np
from omegaconf import DictConfig, OmegaConf

from hintsjax import checkpoint, expert
from hintsjax.config import RunConfig, UsageError, fail, load_run_config, run_config, save_run_config
from hintsjax.evaluate import evaluate_params, metrics_text
from hintsjax.algorithms import make_trainer
from hintsjax.runlog import CURVE_PNG, METRICS_CSV, RunLog, plot_curves, read_curves

EVAL_JSON = "eval.json"


def seed_keys(cfg: RunConfig) -> tuple[jax.Array, int]:
    """[S] training keys, sharded over the seed axis when several devices divide it; and how many devices."""
    keys = cfg.seed_keys()
    devices = jax.devices()
    if len(devices) > 1 and cfg.seeds % len(devices) == 0:
        mesh = jax.sharding.Mesh(np.array(devices), ("seeds",))
        return jax.device_put(keys, jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("seeds"))), len(devices)
    return keys, 1


def new_run_dir(out_dir: str, name: str | None, cfg: RunConfig) -> Path:
    """A fresh folder; never an existing one."""
    base = Path(out_dir) / (name or f"{cfg.env}-{cfg.label}-{time.strftime('%Y%m%d-%H%M%S')}")
    run_dir, i = base, 1
    while run_dir.exists():
        run_dir, i = base.with_name(f"{base.name}-{i}"), i + 1
    run_dir.mkdir(parents=True)
    return run_dir


SECONDS_JSON = "seconds.json"  # training seconds up to the newest checkpoint, summed over resumed calls


def seconds_trained(run_dir: Path) -> float:
    """Training seconds that the newest checkpoint of `run_dir` holds (0 for a fresh folder)."""
    path = Path(run_dir) / SECONDS_JSON
    return json.loads(path.read_text())["seconds"] if path.exists() else 0.0


def train(cfg: RunConfig, run_dir: Path, resume: bool = False, progress: bool = True) -> dict[str, Any]:
    """Train all seeds (in chunks, with checkpoints), evaluate, plot; returns eval results."""
    from tqdm import tqdm

    trainer = make_trainer(cfg)
    keys, num_devices = seed_keys(cfg)
    total = cfg.ppo.num_updates
    if resume:
        state, done = checkpoint.restore_latest(run_dir, cfg, trainer)
    else:
        state, done = jax.jit(jax.vmap(trainer.init))(keys), 0
    print(f"{cfg.env} {cfg.label}: {cfg.seeds} seeds x {total} updates of {cfg.ppo.batch_size} env steps "
          f"on {num_devices} {jax.default_backend()} device(s) -> {run_dir}", flush=True)
    run_chunk = jax.jit(jax.vmap(trainer.run, in_axes=(0, None)), static_argnums=1)
    log = RunLog(run_dir, resume_update=done)
    before = seconds_trained(run_dir) if resume else 0.0  # kept work of earlier calls
    bar = tqdm(total=total, initial=done, unit="upd", disable=not progress, desc=f"{cfg.env} {cfg.label}")
    t0 = saved = time.time()
    while done < total:
        n = min(cfg.checkpoint_every, total - done)
        state, metrics = run_chunk(state, n)
        metrics = jax.tree.map(np.asarray, metrics)
        log.write(metrics, done)
        done += n
        if done == total or time.time() - saved >= cfg.checkpoint_seconds:
            checkpoint.save(run_dir, state, done)
            saved = time.time()
            (run_dir / SECONDS_JSON).write_text(json.dumps({"update": done, "seconds": before + saved - t0}))
        returns = metrics["episode_return"][:, -1]
        bar.set_postfix(steps=int(metrics["env_steps"][0, -1]), ret=f"{np.nanmean(returns):.1f}" if not np.all(np.isnan(returns)) else "-")
        bar.update(n)
    bar.close()
    log.close()
    train_seconds = time.time() - t0
    results = {"label": cfg.label, "env": cfg.env, "train_seconds_this_call": train_seconds,
               "train_seconds": before + train_seconds,
               "env_steps": total * cfg.ppo.batch_size, "evaluations": []}
    for variant in (cfg.variant, *cfg.eval_variants):
        results["evaluations"].append(evaluate_params(cfg, state.params, variant, cfg.eval_episodes, cfg.stochastic_eval))
    (run_dir / EVAL_JSON).write_text(json.dumps(results, indent=1))
    if (run_dir / METRICS_CSV).exists():
        plot_curves({cfg.label: read_curves(run_dir / METRICS_CSV)}, run_dir / CURVE_PNG, f"{cfg.env}: {cfg.label}")
    for ev in results["evaluations"]:
        print(f"{cfg.env}/{ev['variant']} {cfg.label}: {ev['mean']:.2f} +- {ev['std']:.2f}{metrics_text(ev)} "
              f"({ev['seeds']} seeds x {ev['episodes_per_seed']} episodes)  -> {run_dir}")
    return results


def main_from_values(values: dict[str, Any]) -> int:
    """Run from plain config values (what Hydra resolved); returns the exit status."""
    values = dict(values)
    try:
        resume = values.pop("resume", None)
        out_dir, name = values.pop("out_dir", "runs"), values.pop("name", None)
        if resume is not None:
            run_dir = Path(resume)
            cfg = load_run_config(run_dir)  # a missing or bad checkpoint is reported by train's restore
        else:
            cfg = run_config(values)
            run_dir = None
        if cfg.agent_spec.imitates:
            expert.describe(cfg.env, cfg.expert)  # a missing or foreign expert fails before any folder is made
    except UsageError as e:
        return fail(e)
    if run_dir is None:
        run_dir = new_run_dir(out_dir, name, cfg)
        save_run_config(run_dir, cfg)
    try:
        train(cfg, run_dir, resume=resume is not None)
    except UsageError as e:
        return fail(e)
    return 0


@hydra.main(version_base=None, config_path="conf", config_name="config")
def _hydra_main(cfg: DictConfig) -> None:
    status = main_from_values(OmegaConf.to_container(cfg, resolve=True))
    if status:
        sys.exit(status)  # SystemExit passes through Hydra's exception reporting


def main() -> None:
    _hydra_main()


if __name__ == "__main__":
    main()
