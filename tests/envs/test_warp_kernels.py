"""MuJoCo Warp's kernels built ahead in a child process (envs/warp_kernels.py): started only for
a physics=warp run of an MJX env, with JAX kept on the CPU; a child still running when the run
stops is ended; and the modules it builds are the ones an env's first call loads, so that call
builds none but MJX's own FFI module (on Warp's CPU path here; on a GPU the same code saved 47 s
of a cold ant run, docs/throughput.md)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest

from hintsjax.envs import physics, warp_kernels

warp_lang = pytest.mark.skipif(
    not physics.warp_installed(), reason="warp-lang not installed (pip install -e '.[gpu]')"
)


def test_a_build_starts_only_for_a_warp_run_of_an_mjx_env(monkeypatch):
    started = []

    class Recorded:
        def __init__(self, args, **kwargs):
            started.append((args, kwargs["env"]))

    monkeypatch.setattr(warp_kernels.subprocess, "Popen", Recorded)
    assert warp_kernels.start("idp", physics.JAX, 2.0, "gpu").process is None
    # no MJCF model
    assert warp_kernels.start("car_racing", physics.WARP, 2.0, "gpu").process is None
    assert started == []
    warp_kernels.start("ant", physics.WARP, 1.5, "gpu")
    warp_kernels.start("idp", physics.WARP, 2.0, "cpu")
    (gpu_args, gpu_env), (cpu_args, _) = started
    assert gpu_args == [sys.executable, "-m", "hintsjax.envs.warp_kernels", "ant", "1.5", "cuda:0"]
    assert cpu_args[-3:] == ["idp", "2.0", "cpu"]
    assert gpu_env["JAX_PLATFORMS"] == "cpu"  # the child takes no GPU memory for JAX

    def refused(args, **kwargs):
        raise OSError(11, "Resource temporarily unavailable")

    # no child: the run goes on without one
    monkeypatch.setattr(warp_kernels.subprocess, "Popen", refused)
    assert warp_kernels.start("ant", physics.WARP, 2.0, "gpu").process is None


def test_a_child_still_building_when_the_run_stops_is_ended():
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(120)"])
    with warp_kernels.KernelBuild(child):
        assert child.poll() is None
    assert child.returncode is not None
    with warp_kernels.KernelBuild(None) as nothing:  # nothing started: nothing to wait for or end
        nothing.wait()


_FIRST_ENV_CALL = """
import jax, jax.numpy as jnp
from hintsjax import envs
env = envs.make("idp", observe=("state",), physics="warp")
params = env.default_params()
keys = jax.random.split(jax.random.key(0), 2)
def first(keys):
    ts = jax.vmap(env.reset, in_axes=(0, None))(keys, params)
    return jax.vmap(env.step, in_axes=(0, 0, 0, None))(keys, ts.state, jnp.zeros((2, env.action_size)), params)
out = jax.jit(first)(keys)
print("stepped", bool(jnp.isfinite(out.obs["state"]).all()))
"""  # noqa: E501


# Warp's CPU kernels for the idp built twice into empty caches: about 2 minutes on 2 cores
@pytest.mark.slow
@warp_lang
def test_the_child_builds_what_an_envs_first_call_loads(tmp_path):
    """In an empty kernel cache, the child's build leaves an env's first reset and step nothing to
    build but MJX's FFI module (built while tracing, before any kernel runs); without it that call
    builds the solver's modules itself."""
    built = re.compile(r"Module (\S+) .*load on device 'cpu'.*\(compiled\)")

    def first_call_builds(cache: str) -> list[str]:
        env = {
            **os.environ,
            "WARP_CACHE_PATH": cache,
            "HINTSJAX_DEBUG": "1",
            "JAX_PLATFORMS": "cpu",
        }
        done = subprocess.run(
            [sys.executable, "-c", _FIRST_ENV_CALL],
            env=env,
            capture_output=True,
            text=True,
            timeout=900,
        )
        assert done.returncode == 0 and "stepped True" in done.stdout, done.stderr[-2000:]
        return sorted(m.group(1) for m in built.finditer(done.stdout + done.stderr))

    ahead = str(tmp_path / "ahead")
    env = {**os.environ, "WARP_CACHE_PATH": ahead, "HINTSJAX_DEBUG": "1"}
    done = subprocess.run(
        [sys.executable, "-m", "hintsjax.envs.warp_kernels", "idp", "2.0", "cpu"],
        env=env,
        capture_output=True,
        text=True,
        timeout=900,
    )
    assert done.returncode == 0 and "kernels built or loaded on cpu" in done.stdout, done.stderr[
        -2000:
    ]
    assert first_call_builds(ahead) == ["mujoco.mjx.warp.ffi"]
    # the check can fail: a cold first call builds them
    assert len(first_call_builds(str(tmp_path / "cold"))) > 10
