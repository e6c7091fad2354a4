"""No deadlock on a CPU (hintsjax/system/xla_flags.py).

jaxlib's batched LAPACK kernels split their batch over XLA's CPU thread pool and wait for the
pieces; when XLA's concurrency-optimised schedule runs two of them side by side on a 2-core
machine, both pool threads wait and the program never finishes. This program (two independent
batched Cholesky solves, the shape of MJX's constraint solves) stopped for good in 12 of 13 runs
on 2 cores without the scheduler flag hintsjax sets, and finished 300 calls in about a second in 6
of 6 with it (docs/throughput.md). On a machine with more cores it finishes either way, so there the
test cannot fail.
"""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

SCRIPT = """
import hintsjax  # sets XLA_FLAGS before jax starts
import jax
import jax.numpy as jnp

assert "--xla_cpu_enable_concurrency_optimized_scheduler=false" in hintsjax._os.environ["XLA_FLAGS"]


def solve(a):
    factor = jax.scipy.linalg.cho_factor(a)
    return jax.scipy.linalg.cho_solve(factor, jnp.ones(a.shape[:-1])[..., None]).sum()


@jax.jit
def two_solves(a, c):
    return solve(a) + solve(c)  # independent: a concurrency-minded schedule runs them at once


keys = jax.random.split(jax.random.key(0), 2)
m, n = jax.random.normal(keys[0], (1280, 14, 14)), jax.random.normal(keys[1], (1280, 14, 14))
a = m @ jnp.swapaxes(m, -1, -2) + 14 * jnp.eye(14)
c = n @ jnp.swapaxes(n, -1, -2) + 14 * jnp.eye(14)
for _ in range(300):
    two_solves(a, c).block_until_ready()
print("finished")
"""


def test_two_batched_cholesky_solves_side_by_side_finish():
    # the flags as hintsjax sets them
    env = {k: v for k, v in os.environ.items() if k != "XLA_FLAGS"}
    env["JAX_PLATFORMS"] = "cpu"
    try:
        done = subprocess.run(
            [sys.executable, "-c", SCRIPT], env=env, capture_output=True, text=True, timeout=300
        )
    except subprocess.TimeoutExpired:
        pytest.fail(
            "two batched Cholesky solves did not finish in 300 s (a few seconds when they do): "
            "deadlocked"
        )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().endswith("finished")
