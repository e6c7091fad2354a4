"""A run's folder and what it holds at the end: eval.json (its evaluations and timings) and the
learning curve."""

from __future__ import annotations

import json
import time
from pathlib import Path
from typing import Any

import jax

from hintsjax.system import devices, paths, xla_flags
from hintsjax.settings.config import RunConfig
from hintsjax.evaluation.evaluator import metrics_text
from hintsjax.evaluation.outliers import far_below_text
from hintsjax.training.loop import Training, chunks_rate
from hintsjax.training.runlog import (
    CURVE_PNG,
    METRICS_CSV,
    fresh_folder,
    kl_storms,
    plot_curves,
    read_curves,
    storms_text,
)


EVAL_JSON = "eval.json"


def new_run_dir(out_dir: str, name: str | None, cfg: RunConfig) -> Path:
    """A fresh folder; never an existing one."""
    return fresh_folder(
        Path(out_dir) / (name or f"{cfg.env}-{cfg.label}-{time.strftime('%Y%m%d-%H%M%S')}")
    )


def write_results(
    cfg: RunConfig,
    run_dir: Path,
    training: Training,
    evaluations: list[dict],
    eval_compile: float,
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """Write a run's eval.json (its evaluations, timings and each seed's KL storms) and learning
    curve; print the results, a line naming any seeds that ended far below the others, and one
    saying which of them had a KL storm."""
    compiled = training.compiled
    results = {
        "label": cfg.label,
        "env": cfg.env,
        "seen_at_deploy": list(cfg.agent_spec.deploy_sees),
        "train_seconds_this_call": training.seconds,
        "train_seconds": training.before + training.seconds,
        "compile_seconds": {"train": compiled.seconds, "eval": eval_compile},
        "trace_seconds": {"train": compiled.trace_seconds},
        "traced_programs_loaded": compiled.loaded,
        "train_env_steps_per_s": (training.done - training.first)
        * cfg.ppo.batch_size
        * cfg.seeds
        / max(training.seconds, 1e-9),
        "chunks_env_steps_per_s": chunks_rate(training, cfg.ppo.batch_size * cfg.seeds),
        "env_steps": cfg.ppo.num_updates * cfg.ppo.batch_size,
        "physics": cfg.physics,
        "devices": compiled.layout.count,
        "device": jax.devices()[0].device_kind,
        "deterministic": jax.default_backend() == "cpu" or xla_flags.deterministic_gpu_ops(),
        **(extra or {}),
        "evaluations": evaluations,
    }
    if not devices.is_main():  # process 0 writes the run folder
        return results
    # per seed; None where PPO logged no KL
    results["kl_storms"] = storms = kl_storms(run_dir / METRICS_CSV)
    paths.write_text_whole(run_dir / EVAL_JSON, json.dumps(results, indent=1))
    if (run_dir / METRICS_CSV).exists():
        plot_curves(
            {cfg.label: read_curves(run_dir / METRICS_CSV)},
            run_dir / CURVE_PNG,
            f"{cfg.env}: {cfg.label}",
        )
    for ev in results["evaluations"]:
        print(
            f"{cfg.env}/{ev['variant']} {cfg.label}: {ev['mean']:.2f} +- {ev['std']:.2f}"
            f"{metrics_text(ev)} "
            f"({ev['seeds']} seeds x {ev['episodes_per_seed']} episodes)  -> {run_dir}"
        )
        if outliers := far_below_text(ev, run_dir):
            print(f"{cfg.env}/{ev['variant']} {cfg.label}: {outliers}")
            if storm := storms_text(ev["outlier_seeds"], storms):
                print(f"{cfg.env}/{ev['variant']} {cfg.label}: {storm}")
    return results
