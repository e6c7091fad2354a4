"""MuJoCo Warp's kernels built ahead, beside a run's XLA compiles.

On a machine whose Warp kernel cache is empty (WARP_CACHE_PATH, or Warp's default folder), the
first physics call of a `physics=warp` run builds about 33 kernel modules (code generation, then
NVRTC or clang): about as long as the run's XLA compiles for the ant (docs/throughput.md), and one
after the other with them. `start` builds them in a child process from the run's first moment
instead, with MuJoCo Warp's own API on one world of the env's model (the same options, contact and
constraint capacities, and overflow warnings off, as `physics.WarpPhysics`), so that they land in
the kernel cache while the run's programs compile; `KernelBuild.wait` is called before the run's
first state. The modules' names and hashes match the ones the run's first call loads (the study
behind this: docs/throughput.md), except the module of MJX's own FFI callables, built while tracing.

More of what it owns and why: docs/design.md, "Module notes", envs/warp_kernels.py.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass

import mujoco

from hintsjax import envs
from hintsjax.envs import physics

JAX_ON_CPU = {"JAX_PLATFORMS": "cpu"}  # the child's JAX: no GPU memory taken beside the run's


def build(mj_model: mujoco.MjModel, capacity: float, device: str) -> float:
    """Build (or load from the kernel cache) the kernels that `physics.WarpPhysics` launches for
    `mj_model` at `capacity`, on Warp device `device`: one world's forward pass with contact
    forces, a step without them and one with them. The seconds it took."""
    physics.enable_warp()
    import warp
    from mujoco.mjx.third_party import mujoco_warp

    start = time.perf_counter()
    contacts, rows = physics.per_world(mj_model, capacity)
    with warp.ScopedDevice(device), physics.quiet():
        model = mujoco_warp.put_model(mj_model)
        # as WarpPhysics: warn_overflow is built into the solver's kernels
        model.opt.warn_overflow = 0
        data = mujoco_warp.make_data(mj_model, nworld=1, naconmax=contacts, njmax=rows)
        model.opt.run_rne_postconstraint = True
        mujoco_warp.forward(model, data)  # an env's reset: a forward pass with contact forces
        model.opt.run_rne_postconstraint = False
        mujoco_warp.step(model, data)  # a substep
        model.opt.run_rne_postconstraint = True
        mujoco_warp.step(model, data)  # a step's last substep, with contact forces
        warp.synchronize_device(device)
    return time.perf_counter() - start


@dataclass
class KernelBuild:
    """A child process building an env's Warp kernels (`start`); None where nothing was started."""

    process: subprocess.Popen | None

    def wait(self) -> None:
        """Until the child is done (its outcome is not checked: see the module's docstring)."""
        if self.process is not None:
            self.process.wait()

    def __enter__(self) -> KernelBuild:
        return self

    def __exit__(self, *exc: object) -> None:
        """End the child if it still runs (the run stopped before its first state)."""
        if self.process is not None and self.process.poll() is None:
            self.process.kill()
            self.process.wait()


def start(env: str, physics_choice: str, capacity: float, backend: str) -> KernelBuild:
    """Start building `env`'s Warp kernels in a child process, when the run steps `env` with
    MJX-Warp (`physics_choice` as resolved); its output is kept only under HINTSJAX_DEBUG."""
    if physics_choice != physics.WARP or env not in envs.mjx_env_names():
        return KernelBuild(None)
    device = "cuda:0" if backend == "gpu" else "cpu"
    out = None if physics.debugging() else subprocess.DEVNULL
    try:
        process = subprocess.Popen(
            [sys.executable, "-m", "hintsjax.envs.warp_kernels", env, repr(capacity), device],
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=out,
            env={**os.environ, **JAX_ON_CPU},
        )
    except OSError:  # no process to spare (best effort: the run builds its kernels itself)
        return KernelBuild(None)
    return KernelBuild(process)


def main() -> None:
    env, capacity, device = sys.argv[1], float(sys.argv[2]), sys.argv[3]
    seconds = build(envs.REGISTRY[env].cls.make_mj_model(), capacity, device)
    print(
        f"{env}: MuJoCo Warp's kernels built or loaded on {device} in {seconds:.1f} s", flush=True
    )


if __name__ == "__main__":
    main()
