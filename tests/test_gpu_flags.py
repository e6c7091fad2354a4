"""The XLA flags hintsjax sets on import (hintsjax/__init__.py): deterministic GPU ops unless
XLA_FLAGS says otherwise, and with them off a persisted autotune folder beside the compilation
cache, so that compiles on one machine pick the same kernels (not where the user names a folder
or turns the cache off)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

FLAG = "--xla_gpu_per_fusion_autotune_cache_dir="
ADDED = "HINTSJAX_XLA_FLAGS_ADDED"  # what a parent hintsjax process added (this suite's own, here)


def flags_after_import(xla_flags: str | None, cache: str | None) -> list[str]:
    env = {
        k: v
        for k, v in os.environ.items()
        if k not in ("XLA_FLAGS", "HINTSJAX_COMPILATION_CACHE", ADDED)
    }
    env.update(
        {
            k: v
            for k, v in (("XLA_FLAGS", xla_flags), ("HINTSJAX_COMPILATION_CACHE", cache))
            if v is not None
        }
    )
    done = subprocess.run(
        [sys.executable, "-c", "import hintsjax, os; print(os.environ['XLA_FLAGS'])"],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    return done.stdout.split()


def test_deterministic_ops_by_default_and_no_autotune_folder(tmp_path):
    flags = flags_after_import(None, str(tmp_path))
    assert "--xla_gpu_deterministic_ops=true" in flags
    assert not any(f.startswith(FLAG) for f in flags)
    assert not list(tmp_path.iterdir())


def test_deterministic_ops_off_gets_an_autotune_folder_beside_the_cache(tmp_path):
    flags = flags_after_import("--xla_gpu_deterministic_ops=false", str(tmp_path))
    (folder,) = [f[len(FLAG) :] for f in flags if f.startswith(FLAG)]
    assert os.path.dirname(folder) == str(tmp_path) and os.path.basename(folder).startswith(
        "autotune-jaxlib-"
    )
    assert os.path.isdir(folder)  # XLA wants it made


@pytest.mark.parametrize(
    "xla_flags",
    ["--xla_gpu_deterministic_ops=false", f"--xla_gpu_deterministic_ops=false {FLAG}/mine"],
)
def test_no_autotune_folder_of_ours_with_the_cache_off_or_a_folder_named(xla_flags, tmp_path):
    flags = flags_after_import(xla_flags, "off" if FLAG not in xla_flags else str(tmp_path))
    assert [f for f in flags if f.startswith(FLAG)] == (
        [f"{FLAG}/mine"] if FLAG in xla_flags else []
    )


DROP = """
import os, sys
import hintsjax
from hintsjax.system import xla_flags
if sys.argv[1] == "started":
    import jax
    jax.devices()
print(xla_flags.drop_determinism())
print(os.environ["XLA_FLAGS"])
"""


@pytest.mark.parametrize("case", ["default", "chosen", "started"])
def test_deterministic_ops_drop_for_warp_only_where_the_user_left_them_and_jax_has_not_started(
    case, tmp_path
):
    # a fresh process's
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", ADDED)}
    env.update(HINTSJAX_COMPILATION_CACHE=str(tmp_path), JAX_PLATFORMS="cpu")
    if case == "chosen":
        env["XLA_FLAGS"] = "--xla_gpu_deterministic_ops=true"
    done = subprocess.run(
        [sys.executable, "-c", DROP, case], env=env, capture_output=True, text=True, check=True
    )
    dropped, flags = done.stdout.split("\n")[:2]
    if case == "default":
        assert dropped == "True" and "--xla_gpu_deterministic_ops=true" not in flags.split()
        assert (
            "--xla_gpu_deterministic_ops=false" in flags.split() and FLAG + str(tmp_path) in flags
        )
    else:  # the user's choice stands; flags read by a started backend are not changed under it
        assert (
            dropped == "False"
            and "--xla_gpu_deterministic_ops=true" in flags.split()
            and FLAG not in flags
        )


def test_a_command_asks_only_for_warp_when_every_job_does(tmp_path, monkeypatch):
    from hintsjax.cli.overrides import asks_only_for_warp
    from hintsjax.envs import physics

    warp_run = tmp_path / "warp_run"
    warp_run.mkdir()
    (warp_run / "config.yaml").write_text("env: ant\nphysics: warp\n")
    assert asks_only_for_warp(["env=ant", "physics=warp"])
    assert asks_only_for_warp(["-m", "env=ant", "physics=warp", "seeds=1,2"])
    assert asks_only_for_warp([f"resume={warp_run}"])
    assert not asks_only_for_warp(["env=ant"])  # physics=auto without an NVIDIA GPU: JAX's solver
    assert not asks_only_for_warp(["-m", "env=ant", "physics=warp,jax"])
    assert not asks_only_for_warp([f"resume={tmp_path / 'missing'}"])
    # where JAX will find an NVIDIA GPU, auto asks for Warp for the envs that prefer it
    monkeypatch.setattr(physics, "warp_installed", lambda: True)
    monkeypatch.setattr(physics, "gpu_likely", lambda: True)
    assert asks_only_for_warp(["env=ant", "hint=speed", "scheme=fc"])  # the design's command
    assert asks_only_for_warp(["-m", "env=ant,humanoid"])
    assert not asks_only_for_warp(["env=ant", "physics=jax"])
    assert not asks_only_for_warp(["-m", "env=ant,pendulum"])  # the pendulum keeps JAX's solver
    assert not asks_only_for_warp(["env=playground:CartpoleSwingup"])
    # run's check names these
    assert not asks_only_for_warp(["env=playground:Nope"]) and not asks_only_for_warp(["env=nope"])
    monkeypatch.setattr(physics, "warp_installed", lambda: False)
    assert not asks_only_for_warp(["env=ant"])


def test_a_gpu_is_guessed_only_where_jax_may_use_one(monkeypatch):
    """gpu_likely, read before JAX starts: never where JAX_PLATFORMS names no GPU, nor on this
    suite's machines (no CUDA plugin), whatever JAX_PLATFORMS says."""
    from hintsjax.envs import physics

    monkeypatch.setenv("JAX_PLATFORMS", "cpu")
    assert not physics.gpu_likely()
    monkeypatch.setenv("JAX_PLATFORMS", "cuda,cpu")
    import jax

    assert physics.gpu_likely() == (jax.default_backend() == "gpu" and jax.device_count() == 1)
    # two GPUs: auto keeps JAX, which spreads the seeds
    monkeypatch.setenv("CUDA_VISIBLE_DEVICES", "0,1")
    assert not physics.gpu_likely()


def test_a_child_of_a_hintsjax_process_tells_its_parents_flags_from_the_users(tmp_path):
    """run_path.py and the sweeps start `python -m hintsjax.run` from a process that imported
    hintsjax: the child inherits XLA_FLAGS with deterministic ops on, set by hintsjax, not by
    the user, so a Warp command there still turns them off; a flag the user set stays theirs."""
    # a fresh process's
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", ADDED)}
    env.update(HINTSJAX_COMPILATION_CACHE=str(tmp_path), JAX_PLATFORMS="cpu")
    parent = subprocess.run(
        [
            sys.executable,
            "-c",
            "import hintsjax, os; print(os.environ['XLA_FLAGS']); "
            "print(os.environ['HINTSJAX_XLA_FLAGS_ADDED'])",
        ],
        env=env,
        capture_output=True,
        text=True,
        check=True,
    )
    flags, added = parent.stdout.splitlines()
    for user in ("", "--xla_gpu_deterministic_ops=true"):
        inherited = {
            **env,
            "XLA_FLAGS": f"{user} {flags}".strip(),
            "HINTSJAX_XLA_FLAGS_ADDED": added,
        }
        child = subprocess.run(
            [sys.executable, "-c", DROP, "child"],
            env=inherited,
            capture_output=True,
            text=True,
            check=True,
        )
        dropped, child_flags = child.stdout.split("\n")[:2]
        assert dropped == str(not user), child_flags
        assert (
            child_flags.split().count("--xla_cpu_enable_concurrency_optimized_scheduler=false") == 1
        )


def test_a_sweep_worker_drops_determinism_only_when_all_its_runs_get_warp(monkeypatch):
    """A table script's worker (python -m hintsjax.reproduce.sweep --one env/label,...):
    physics=warp, or auto where every run's env prefers Warp on an NVIDIA GPU, drops deterministic
    GPU ops before its check starts JAX; a run that keeps JAX's solver keeps them for the whole
    worker."""
    import argparse

    from hintsjax.envs import physics
    from hintsjax.reproduce import sweep_settings
    from hintsjax.system import xla_flags

    dropped = []
    monkeypatch.setattr(xla_flags, "drop_determinism", lambda: dropped.append(True) or True)
    monkeypatch.setattr(physics, "warp_installed", lambda: True)
    monkeypatch.setattr(physics, "gpu_likely", lambda: True)
    parser = argparse.ArgumentParser()

    def worker(one: str, *settings: str) -> bool:
        dropped.clear()
        sweep_settings.worker_settings(parser, argparse.Namespace(settings=list(settings), one=one))
        return bool(dropped)

    assert worker("ant/hints-fc-speed,ant/ppo_rgb")
    assert worker("pendulum/hints-fc-composite", "physics=warp")
    assert not worker("ant/hints-fc-speed,pendulum/ppo_rgb")
    assert not worker("ant/hints-fc-speed", "physics=jax")
    monkeypatch.setattr(physics, "gpu_likely", lambda: False)
    assert not worker("ant/hints-fc-speed")
