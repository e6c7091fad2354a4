"""A run's seeds over several devices (hintsjax/system/devices.py), on CPU devices that XLA splits
the host into: any seed count spreads (the padding is dropped from every result), the numbers
match one device's to float32 rounding, and a checkpoint written on 4 devices resumes on 1.
One run over two processes (JAX's multi-controller runtime, CPU collectives through gloo)
equals one process with the same 4 devices, bit for bit, and resumes as it would."""

from __future__ import annotations

import json
import os
import shutil
import socket
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import linear_env  # noqa: F401  (registers the test env "linear")
from process_run import HUNG_MARK, HUNG_SECONDS
from test_cli import with_xla_flag
from hintsjax.system import checkpoint
from hintsjax.system.devices import SeedLayout
from hintsjax.settings.layers import load_run_config
from hintsjax.algorithms.registry import make_trainer
from hintsjax.training import compilation, pipeline
from hintsjax import run

HERE = Path(__file__).parent


class FakeDevice:
    pass


def test_a_layout_pads_seeds_to_a_multiple_of_the_devices():
    four = (FakeDevice(),) * 4
    assert [
        (SeedLayout(s, four).padded, SeedLayout(s, four).per_device) for s in (1, 3, 4, 5, 20)
    ] == [(4, 1), (4, 1), (4, 1), (8, 2), (20, 5)]
    assert SeedLayout(5, four[:1]).padded == 5 and SeedLayout(5, four[:1]).sharding is None


def _layout_run(folder: Path, devices: int) -> dict:
    env = {
        **os.environ,
        "XLA_FLAGS": with_xla_flag(f"--xla_force_host_platform_device_count={devices}"),
        "JAX_PLATFORMS": "cpu",
        "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]),
    }
    proc = subprocess.run(
        [sys.executable, str(HERE / "layout_run.py"), str(folder)],
        env=env,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    base = tmp_path_factory.mktemp("layouts")
    return {n: (base / f"d{n}", _layout_run(base / f"d{n}", n)) for n in (1, 4)}


# with the next: 50 s of the suite; two devices: test_cli's test_seeds_sharded_over_two_devices
@pytest.mark.slow
def test_three_seeds_on_four_devices_match_one_device(runs):
    (_, one), (folder, four) = runs[1], runs[4]
    assert (one["devices"], four["devices"]) == (1, 4)
    np.testing.assert_allclose(four["alone"], one["alone"], rtol=1e-4)
    np.testing.assert_allclose(four["group"], one["group"], rtol=1e-4)
    metrics = (folder / "alone" / "metrics.csv").read_text().splitlines()
    # the padding seed is not logged
    assert sorted({line.split(",")[1] for line in metrics[1:]}) == ["0", "1", "2"]
    eval_json = json.loads((folder / "alone" / "eval.json").read_text())
    assert eval_json["devices"] == 4 and eval_json["evaluations"][0]["seeds"] == 3


@pytest.mark.slow
def test_a_checkpoint_written_on_four_devices_resumes_on_one(runs, tmp_path):
    folder, four = runs[4]
    run_dir = tmp_path / "alone"
    shutil.copytree(folder / "alone", run_dir)
    cfg = load_run_config(run_dir)
    state, done = checkpoint.restore_latest(run_dir, make_trainer(cfg).abstract_state())
    # the run's own seeds, no padding
    assert done == cfg.ppo.num_updates and state.update.shape == (3,)
    last = run_dir / "checkpoints" / str(done)
    # an earlier one to go on from
    assert len([p for p in (run_dir / "checkpoints").iterdir() if p.name.isdigit()]) >= 2
    shutil.rmtree(last)  # as if stopped before the last update: this process (1 device) trains it
    (run_dir / "eval.json").unlink()
    assert run.main_from_values({"resume": str(run_dir)}) == 0
    resumed = json.loads((run_dir / "eval.json").read_text())
    assert resumed["devices"] == 1
    np.testing.assert_allclose(resumed["evaluations"][0]["seed_means"], four["alone"], rtol=1e-4)


def _processes(folder: Path, count: int, devices_each: int, *args: str, tries: int = 2) -> None:
    """tests/process_run.py in `count` processes joined into one run, each with `devices_each` CPU
    devices.

    A run that hangs (each process dumps its stacks and exits after process_run.HUNG_SECONDS) is
    started once more, on a fresh coordinator port and from an empty folder (a resume from the
    same checkpoint), and the hang is reported as a warning with the stacks: CI saw two hangs
    where hundreds of runs here had none, the second (2026-11-27) with both processes in a
    checkpoint's eager per-leaf slicing, which SeedLayout.crop now does in one program. Wrong
    results, a crash or a second hang fail."""
    with socket.socket() as s:
        s.bind(("localhost", 0))
        port = s.getsockname()[1]
    base = {
        **os.environ,
        "XLA_FLAGS": f"--xla_force_host_platform_device_count={devices_each}",
        "JAX_PLATFORMS": "cpu",
        "PYTHONPATH": os.pathsep.join([str(HERE), os.environ.get("PYTHONPATH", "")]),
    }
    if count > 1:
        base.update(JAX_NUM_PROCESSES=str(count), JAX_COORDINATOR_ADDRESS=f"localhost:{port}")
    logs = [
        folder.parent / f"{folder.name}-process{i}{''.join(args)}-try{tries}.log"
        for i in range(count)
    ]
    procs = []
    for i, log in enumerate(logs):
        # a file, not a pipe: a process blocked on a full pipe would stall the others
        with log.open("w") as out:
            procs.append(
                subprocess.Popen(
                    [sys.executable, str(HERE / "process_run.py"), str(folder), *args],
                    env={**base, "JAX_PROCESS_ID": str(i)},
                    stdout=out,
                    stderr=subprocess.STDOUT,
                )
            )
    for proc in procs:
        try:
            proc.wait(timeout=HUNG_SECONDS + 100)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    texts = [log.read_text() for log in logs]
    if tries > 1 and any(p.returncode != 0 for p in procs) and any(HUNG_MARK in t for t in texts):
        warnings.warn(
            f"a {count}-process run hung and was started again; its stacks:\n"
            + "\n".join(t[-6000:] for t in texts)
        )
        if "--resume" not in args:
            # the hung run's folder (if it got that far): the retry makes it again, not run-1 beside
            # it
            shutil.rmtree(folder, ignore_errors=True)
        return _processes(folder, count, devices_each, *args, tries=tries - 1)
    assert all(p.returncode == 0 for p in procs), "\n".join(t[-6000:] for t in texts)


@pytest.mark.slow  # two processes of 2 devices on 2 cores: 160 s, and 460 s when a hang is retried
def test_one_run_over_two_processes_equals_one_process_and_resumes(tmp_path):
    _processes(tmp_path / "one", 1, 4)
    _processes(tmp_path / "two", 2, 2)
    one, two = tmp_path / "one" / "run", tmp_path / "two" / "run"
    # process 0 made the one folder
    assert sorted(p.name for p in (tmp_path / "two").iterdir()) == ["run"]
    evals = [json.loads((d / "eval.json").read_text()) for d in (one, two)]
    assert [e["devices"] for e in evals] == [4, 4]
    assert evals[1]["evaluations"][0]["seed_means"] == evals[0]["evaluations"][0]["seed_means"]
    assert (two / "metrics.csv").read_text() == (one / "metrics.csv").read_text()
    updates = sorted(int(p.name) for p in (two / "checkpoints").iterdir() if p.name.isdigit())
    assert len(updates) == 2  # the last and one before it, written by both processes
    shutil.rmtree(two / "checkpoints" / str(updates[-1]))
    (two / "eval.json").unlink()
    _processes(tmp_path / "two", 2, 2, "--resume")
    resumed = json.loads((two / "eval.json").read_text())
    assert resumed["evaluations"][0]["seed_means"] == evals[0]["evaluations"][0]["seed_means"]


def test_physics_warp_stays_on_one_device_and_in_one_process(monkeypatch):
    """jit's partitioner cannot split MJX-Warp's custom call (every device would step every
    world), so a Warp run keeps to this process's first device, and several processes are
    refused."""
    import jax

    from hintsjax.system.errors import UsageError
    from hintsjax.settings.layers import run_config

    cfg = run_config({"env": "ant", "physics": "warp"})
    assert compilation.seed_layout(cfg).devices == tuple(jax.local_devices()[:1])
    assert compilation.seed_layout(run_config({"env": "ant", "physics": "jax"})).devices == tuple(
        jax.devices()
    )
    monkeypatch.setattr(jax, "process_count", lambda: 2)
    with pytest.raises(UsageError, match="physics=warp runs in one process"):
        compilation.seed_layout(cfg)


def test_under_warp_the_evaluation_compiles_before_training_beside_its_compile(
    monkeypatch, tmp_path
):
    """MuJoCo Warp's CUDA graph capture broke while XLA compiled beside it with deterministic ops
    off, and its Python callbacks slow down while another thread compiles, so a Warp run's
    evaluation program finishes compiling before training
    (experiments/results/warp_det_off_h100.json), though beside the training program's compile,
    with no autotuning of its own: here a run told
    to, on the linear env, compiles it (with those options) while the training program compiles
    and before its first chunk; told not to, it trains while the compile runs (which waits until
    training has started), with XLA's default options."""
    import threading

    from hintsjax.settings.layers import run_config
    from hintsjax.training import loop

    assert pipeline.evaluation_compiles_first(run_config({"env": "ant", "physics": "warp"}))
    assert not pipeline.evaluation_compiles_first(run_config({"env": "ant", "physics": "jax"}))
    compile_evaluator, advance = pipeline.compile_evaluator, pipeline.train_in_chunks
    compile_training = loop.compile_training
    for first in (True, False):
        events, options = [], []
        training, training_compiles = threading.Event(), threading.Event()

        def compiled(*args, **kwargs):
            if first:  # beside the training program's compile: it has begun
                events.append(f"training compile began: {training_compiles.wait(timeout=30)}")
            else:  # beside training: training starts without this compile
                training.wait(timeout=120)
            options.append(kwargs.get("compiler_options"))
            result = compile_evaluator(*args, **kwargs)
            events.append("compiled")
            return result

        def compiles(*args, **kwargs):
            training_compiles.set()
            return compile_training(*args, **kwargs)

        def advanced(*args, **kwargs):
            events.append("training")
            training.set()
            return advance(*args, **kwargs)

        monkeypatch.setattr(pipeline, "compile_evaluator", compiled)
        monkeypatch.setattr(loop, "compile_training", compiles)
        monkeypatch.setattr(pipeline, "train_in_chunks", advanced)
        monkeypatch.setattr(pipeline, "evaluation_compiles_first", lambda cfg: first)
        values = {
            "env": "linear",
            "agent": "ppo_state",
            "seeds": 2,
            "eval_episodes": 2,
            "checkpoint_every": 2,
            "ppo": {
                "total_env_steps": 128,
                "num_envs": 4,
                "batch_size": 64,
                "minibatch_size": 32,
                "epochs": 1,
            },
            "out_dir": str(tmp_path),
            "name": f"first-{first}",
        }
        assert run.main_from_values(values) == 0
        if first:
            assert events == ["training compile began: True", "compiled", "training"]
            assert options == [{"xla_gpu_autotune_level": 0}]
        else:
            assert events == ["training", "compiled"]
            assert options == [None]


def test_a_runs_first_state_waits_for_warp_kernels_built_beside_its_compiles(monkeypatch, tmp_path):
    """pipeline.train starts the child that builds MuJoCo Warp's kernels (envs/warp_kernels.py)
    before anything compiles, with the run's env, physics and capacity, and waits for it before
    the first state, not after training began; the child is ended on the way out."""
    from hintsjax.envs import warp_kernels

    events = []

    class Build(warp_kernels.KernelBuild):
        def wait(self):
            events.append("kernels")

        def __exit__(self, *exc):
            events.append("ended")

    def started(env, physics_choice, capacity, backend):
        events.append(("start", env, physics_choice, capacity, backend))
        return Build(None)

    advance = pipeline.train_in_chunks
    monkeypatch.setattr(pipeline.warp_kernels, "start", started)
    monkeypatch.setattr(
        pipeline,
        "train_in_chunks",
        lambda *a, **k: (events.append("training"), advance(*a, **k))[1],
    )
    values = {
        "env": "linear",
        "agent": "ppo_state",
        "seeds": 2,
        "eval_episodes": 2,
        "checkpoint_every": 2,
        "warp_capacity": 3.0,
        "ppo": {
            "total_env_steps": 128,
            "num_envs": 4,
            "batch_size": 64,
            "minibatch_size": 32,
            "epochs": 1,
        },
        "out_dir": str(tmp_path),
        "name": "kernels",
    }
    assert run.main_from_values(values) == 0
    assert events[0] == ("start", "linear", "jax", 3.0, "cpu")
    assert events.index("kernels") < events.index("training") < events.index("ended")
