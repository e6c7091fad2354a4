"""Training from a config to a finished run folder: `train` for one run (all its seeds), and
`train_group` for configurations trained as one program (hintsjax.algorithms.group), each member
then getting the folder its own run would have written."""

from __future__ import annotations

import contextlib
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any, Callable

import jax
import numpy as np

from hintsjax.envs import physics, warp_kernels
from hintsjax.system import checkpoint, compilation_cache, devices
from hintsjax.system.devices import SeedLayout
from hintsjax.system.refusals import sized_by
from hintsjax.system.signals import raise_stop_asked
from hintsjax.system.wall import Laps
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms.group import cell_state, make_group, make_group_trainer
from hintsjax.algorithms.registry import make_trainer
from hintsjax.algorithms.trainer import Trainer
from hintsjax.evaluation.evaluator import compile_evaluator, evaluate_group, evaluate_variants
from hintsjax.training.compilation import TRAINING_SIZES, seed_layout
from hintsjax.training.guards import check_physics
from hintsjax.training.loop import Training, start_training, train_in_chunks
from hintsjax.training.outputs import write_results
from hintsjax.training.runlog import RunLog


def evaluation_compiles_first(cfg: RunConfig) -> bool:
    """Whether the evaluation program's compile must end before training starts rather than run
    beside it: under physics=warp. MuJoCo Warp captures CUDA graphs and launches its kernels from
    a Python callback, so a compile in another thread slows every physics call (the ant's first 100
    updates: 40.4 K env steps/s beside, 56.4 K first) and, with deterministic ops off (XLA's
    autotuner then runs kernels on the GPU while it compiles), broke the capture: a segfault, and
    earlier "Warp CUDA error 904", in 3 of 4 runs beside, none of 3 first
    (experiments/results/warp_det_off_h100.json). It still compiles beside the training program's
    compile and Warp's kernel builds (nothing is captured yet), with `FIRST_COMPILE_OPTIONS`."""
    return cfg.physics == physics.WARP


# XLA's options for an evaluation program that compiles beside the training program's compile
# (`evaluation_compiles_first`): no autotuning, so that it runs no kernels on the GPU while the
# training program's autotuner times its own, and compiles sooner.
FIRST_COMPILE_OPTIONS = {"xla_gpu_autotune_level": 0}


def say_compiling(cfg: RunConfig, label: str) -> None:
    """The run's first line, before its programs compile (the longest silence of a first run on a
    fresh machine: a minute or more for the ant under Warp, its kernel builds included)."""
    cached = (
        " (later runs on this machine load most of them from the cache)"
        if compilation_cache.in_use()
        else ""
    )
    print(f"{cfg.env} {label}: compiling its programs{cached}", flush=True)


# The settings that size evaluation, named where an allocation fails
# (hintsjax.system.refusals.sized_by); training's are compilation.TRAINING_SIZES.
EVALUATION_SIZES = "eval_episodes (or seeds)"


class Unlogged:
    """What a process other than the main one logs: nothing (process 0 writes metrics.csv and
    tb/)."""

    def write(self, metrics: dict[str, np.ndarray], after: int) -> None:
        pass

    def close(self) -> None:
        pass


def run_log(run_dir: Path, resume_update: int) -> RunLog | Unlogged:
    return RunLog(run_dir, resume_update=resume_update) if devices.is_main() else Unlogged()


def params_shapes(trainer: Trainer, layout: SeedLayout) -> Any:
    """The seed-batched params as training will hold them ([padded seeds, ...], placed by
    `layout`), as jax.ShapeDtypeStructs: known before anything is compiled or computed."""
    return jax.tree.map(
        lambda x: jax.ShapeDtypeStruct(
            (layout.padded, *x.shape[1:]), x.dtype, sharding=layout.sharding
        ),
        trainer.abstract_state().params,
    )


def compile_evaluation(
    pool: ThreadPoolExecutor, cfg: RunConfig, trainer: Trainer, layout: SeedLayout
) -> Callable[[], Any]:
    """The evaluation program compiling on the host in `pool`'s thread from the start: it needs only
    the params' shapes, so it compiles beside the training program's compile (mostly one core's
    work) and then while the device trains, adding nothing to the wall-clock of a run that trains
    longer; under physics=warp (`evaluation_compiles_first`) without autotuning, waited for before
    the first state. Returns the function that waits for it."""
    options = FIRST_COMPILE_OPTIONS if evaluation_compiles_first(cfg) else None

    def compile_it() -> Any:
        shapes = params_shapes(trainer, layout)
        return compile_evaluator(
            cfg, shapes, cfg.variant, cfg.eval_episodes, layout=layout, compiler_options=options
        )

    future = pool.submit(compile_it)

    def compiled() -> Any:
        with sized_by(EVALUATION_SIZES):
            return future.result()

    return compiled


def train_logged(training: Training, cfg: RunConfig, run_dir: Path, progress: bool) -> Training:
    """`train_in_chunks` writing each chunk's metrics to the run folder (metrics.csv, tb/)."""
    with contextlib.closing(run_log(run_dir, training.done)) as log:
        return train_in_chunks(training, cfg, run_dir, log.write, progress, cfg.label)


def train(
    cfg: RunConfig, run_dir: Path, resume: bool = False, progress: bool = True
) -> dict[str, Any]:
    """Train all seeds (in chunks, with checkpoints: loop.py), evaluate, plot; returns eval results.
    A child process builds MuJoCo Warp's kernels (envs/warp_kernels.py) beside the compiles,
    waited for before the first state; the evaluation compiles in a thread
    (`compile_evaluation`), under Warp waited for there too."""
    laps = Laps()  # eval.json's wall_split_seconds: where this call's wall-clock went
    say_compiling(cfg, cfg.label)
    trainer, layout = make_trainer(cfg), seed_layout(cfg)
    backend = jax.default_backend()
    # leaving it (even by an error) ends the kernels' child first, then waits for the compile
    with (
        ThreadPoolExecutor(max_workers=1) as pool,
        warp_kernels.start(cfg.env, cfg.physics, cfg.warp_capacity, backend) as kernel_builds,
    ):
        evaluation_program = compile_evaluation(pool, cfg, trainer, layout)

        def before_first_state() -> None:
            kernel_builds.wait()
            if evaluation_compiles_first(cfg):
                evaluation_program()

        with sized_by(TRAINING_SIZES):
            training = start_training(
                trainer, cfg, run_dir, resume, cfg.label, before_first_state=before_first_state
            )
            # compiles, the first state (and MuJoCo Warp's kernel builds), a restore
            laps.mark("before_training")
            training = train_logged(training, cfg, run_dir, progress)
            laps.mark("training")  # the chunks, logs and checkpoints, the last one written
        compiled = evaluation_program()
    raise_stop_asked()  # a Ctrl-C Python dropped since the last save: the end is saved
    with sized_by(EVALUATION_SIZES):
        variants = (cfg.variant, *cfg.eval_variants)
        params, placed = training.state.params, training.compiled.layout
        evaluations, eval_compile = evaluate_variants(
            cfg, params, variants, cfg.eval_episodes, cfg.stochastic_eval, compiled, placed
        )
    laps.mark("evaluation")  # waiting on its compile, if still going, and the episodes
    check_physics(cfg, cfg.label)
    extra = {"wall_split_seconds": laps.seconds}
    return write_results(cfg, run_dir, training, evaluations, eval_compile, extra)


def train_group(
    group_cfgs: list[RunConfig],
    group_dir: Path,
    cell_dirs: list[Path],
    resume: bool = False,
    progress: bool = True,
) -> list[dict[str, Any]]:
    """Train configurations that share a network's shapes together (hintsjax.algorithms.group),
    all seeds of all of them in one compiled program; checkpoints of the group go to group_dir.
    Each member then gets what its own run would have written in its folder (cell_dirs, each
    holding its config.yaml): metrics.csv, its final state as a checkpoint, eval.json,
    learning_curve.png.
    GroupTooBig if the group's program would not fit on the device (before anything is written)."""
    laps = Laps()
    group = make_group(group_cfgs)
    cfg = group.cfgs[0]
    label = f"group of {len(group.cfgs)} ({', '.join(c.label for c in group.cfgs)})"
    say_compiling(cfg, label)
    training = start_training(
        make_group_trainer(group), cfg, group_dir, resume, label, check_memory=len(group.cfgs) > 1
    )
    laps.mark("before_training")
    logs = [run_log(d, training.done) for d in cell_dirs]

    def write(metrics: dict[str, np.ndarray], after: int) -> None:  # [S, n, K]: one log per member
        for k, log in enumerate(logs):
            log.write({name: v[..., k] for name, v in metrics.items()}, after)

    try:
        training = train_in_chunks(training, cfg, group_dir, write, progress, label)
    finally:
        for log in logs:
            log.close()
    for k, cell_dir in enumerate(cell_dirs):
        if checkpoint.latest_update(cell_dir) != training.done:
            checkpoint.save(
                cell_dir,
                cell_state(group, training.compiled.layout.crop(training.state), k),
                training.done,
            )
    laps.mark("training")  # with each member's final state saved in its folder
    evaluations, eval_compile = evaluate_group(group, training.state, training.compiled.layout)
    laps.mark("evaluation")
    rate = (
        (training.done - training.first)
        * cfg.ppo.batch_size
        * cfg.seeds
        * len(group.cfgs)
        / max(training.seconds, 1e-9)
    )
    extra = {
        "group": [c.label for c in group.cfgs],
        "group_dir": str(group_dir),
        "group_env_steps_per_s": rate,
        "wall_split_seconds": laps.seconds,
    }
    return [
        write_results(member, cell_dir, training, member_evaluations, eval_compile, extra)
        for member, cell_dir, member_evaluations in zip(group.cfgs, cell_dirs, evaluations)
    ]
