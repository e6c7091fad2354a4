"""The two implementations of MuJoCo MJX's physics that an MJCF env can step: `jax` (MJX's own
JAX solver: any platform, bit-reproducible with deterministic GPU ops) and `warp` (MJX-Warp,
MuJoCo Warp's kernels called from the jitted graph: NVIDIA GPUs, several times faster, and not
bit-deterministic on a GPU), with `auto` choosing between them.

An env asks for one thing, `run(qpos, qvel, ctrl, substeps, contact_forces)`: a fresh
`mjx.Data` at (qpos, qvel) with `ctrl` applied, stepped `substeps` times (0: MuJoCo's forward
pass only), and, with `contact_forces`, the external forces `cfrc_ext` filled in as
`mj_rnePostConstraint` leaves them. What comes back is a `Readout`: the data fields the suite's
tasks read, with MuJoCo C's staleness (kinematic fields from the last physics stage).

More of what it owns and why: docs/design.md, "Module notes", envs/physics.py.
"""

from __future__ import annotations

import contextlib
import functools
import importlib.util
import io
import math
import os
import sys
from dataclasses import dataclass
from functools import partial
from typing import Any, Callable

import jax
import jax.numpy as jnp
import mujoco
import numpy as np
from flax import struct

from hintsjax.envs.errors import choose


def _import_mjx_without_warp() -> Any:
    """`mujoco.mjx`, with its optional Warp backend left unbound. MJX 3.17 imports warp-lang and
    MuJoCo Warp as soon as it is imported, if they are installed: 4.5 s more per process on 2
    cores (hintsjax.envs imported in 7.2 s against 2.8 s), which every command paid although only
    physics=warp uses them. `enable_warp` binds them in when a WarpPhysics is made."""
    if "mujoco.mjx" not in sys.modules:
        saved = sys.modules.get("warp")
        sys.modules["warp"] = None  # mjx's own `try: import warp` fails at once
        try:
            with contextlib.redirect_stdout(io.StringIO()):  # mjx prints a line when warp is absent
                import mujoco.mjx  # noqa: F401
        finally:
            if saved is None:
                del sys.modules["warp"]
            else:
                sys.modules["warp"] = saved
    return sys.modules["mujoco.mjx"]


mjx = _import_mjx_without_warp()


# hintsjax/system/errors.py's DEBUG, read here because envs/ imports nothing of the learner
DEBUG = "HINTSJAX_DEBUG"


def debugging() -> bool:
    """Whether HINTSJAX_DEBUG is set (to anything but 0): then Warp's and MJX's own lines are
    kept."""
    return os.environ.get(DEBUG, "0") not in ("", "0")


def quiet() -> contextlib.AbstractContextManager:
    """Swallows what MJX and MuJoCo Warp print on stdout while building a model or data, unless
    debugging."""
    return contextlib.nullcontext() if debugging() else contextlib.redirect_stdout(io.StringIO())


def enable_warp() -> None:
    """Bind warp-lang and MuJoCo Warp into MJX (what its import does when warp-lang is installed,
    done here when physics=warp first needs it; mujoco-mjx 3.17.0's module layout), with Warp's
    informational lines off unless debugging."""
    import mujoco.mjx.warp as mjxw
    import warp

    # warp-lang 1.18 logs its init banner and a line per kernel module loaded ("Module ... load on
    # device 'cuda:0' took ... (compiled)", 34 for the ant) at LOG_INFO on stdout; it has no
    # `config.quiet` any more (setting it did nothing). Warnings and errors still come through.
    warp.config.log_level = warp.LOG_INFO if debugging() else warp.LOG_WARNING
    if mjxw.WARP_INSTALLED:
        return
    from mujoco.mjx._src import io as mjx_io
    from mujoco.mjx.third_party import mujoco_warp
    from mujoco.mjx.third_party.mujoco_warp._src import io as mjwp_io
    from mujoco.mjx.third_party.mujoco_warp._src import types as mjwp_types

    mjxw.warp, mjxw.mujoco_warp, mjxw.mjwp_types, mjxw.mjwp_io = (
        warp,
        mujoco_warp,
        mjwp_types,
        mjwp_io,
    )
    mjxw.types.GraphMode, mjxw.types.Callback = warp.JaxCallableGraphMode, mjwp_types.Callback
    mjx_io.wp, mjx_io.mjwp, mjx_io.mjwp_types = warp, mujoco_warp, mjwp_types
    mjxw.WARP_INSTALLED = True


AUTO, JAX, WARP = "auto", "jax", "warp"
CHOICES = (AUTO, JAX, WARP)
# Warp's buffers: this many times the model's most contacts and constraint rows per world
DEFAULT_CAPACITY = 2.0


class PhysicsUnavailable(ValueError):
    """physics=warp where MJX-Warp cannot run (no warp-lang, or no NVIDIA GPU and no Warp CPU
    path)."""


def warp_installed() -> bool:
    """Whether warp-lang (MJX-Warp's one extra dependency) is installed (found, not imported)."""
    return importlib.util.find_spec("warp") is not None


def gpu_likely() -> bool:
    """Whether JAX will start on one NVIDIA GPU (what `auto` gives Warp), read without starting it
    (XLA's flags are read once, when it starts): JAX_PLATFORMS allows one, a CUDA plugin of jax is
    installed, and one GPU is visible (the driver's device nodes, or CUDA_VISIBLE_DEVICES). A guess
    for choosing flags early; a run's config resolves `auto` from the backend JAX really started."""
    import glob

    platforms = {
        p.strip() for p in os.environ.get("JAX_PLATFORMS", "").lower().split(",") if p.strip()
    }
    if platforms and not platforms & {"cuda", "gpu"}:
        return False
    visible = os.environ.get("CUDA_VISIBLE_DEVICES")
    count = (
        len([d for d in visible.split(",") if d.strip()])
        if visible is not None
        else len(glob.glob("/dev/nvidia[0-9]*"))
    )
    return _cuda_plugin_installed() and os.path.exists("/dev/nvidiactl") and count == 1


@functools.cache
def _cuda_plugin_installed() -> bool:
    """Whether a CUDA plugin of jax is installed (a scan of every distribution: once a process,
    not once for each job of a sweep that gpu_likely is asked about)."""
    from importlib import metadata

    return any(
        (d.metadata["Name"] or "").lower().replace("_", "-").startswith("jax-cuda")
        for d in metadata.distributions()
    )


def resolve(choice: str, platform: str, warp_by_default: bool = True, devices: int = 1) -> str:
    """`jax` or `warp` for a run on `platform` (jax.default_backend(): cpu, gpu, tpu) with `devices`
    devices (jax.device_count(), every process's).

    auto: Warp on one NVIDIA GPU with warp-lang installed (for an env that prefers it), else JAX,
    so CPU runs, the tests and CPU sweeps stay bit-reproducible, and a run on several GPUs or
    processes spreads its seeds over them (physics=warp runs on one). warp: on a GPU or a CPU
    (Warp's CPU path, for tests: slow), with warp-lang installed; PhysicsUnavailable otherwise."""
    choose("physics", choice, dict.fromkeys(CHOICES))
    if choice == AUTO:
        return (
            WARP
            if warp_by_default and platform == "gpu" and devices == 1 and warp_installed()
            else JAX
        )
    if choice == WARP:
        if not warp_installed():
            raise PhysicsUnavailable(
                "physics=warp needs warp-lang: pip install -e '.[gpu]' (make setup-gpu); "
                "or physics=jax"
            )
        if platform not in ("gpu", "cpu"):
            raise PhysicsUnavailable(
                f"physics=warp runs on NVIDIA GPUs (and slowly on CPUs), not on {platform}; use "
                "physics=jax"
            )
    return choice


@struct.dataclass
class Readout:
    """What the tasks read of a stepped `mjx.Data` (MuJoCo's names and shapes); `overflow` is
    MuJoCo Warp's per-world bitmask of capacities exceeded (always 0 for JAX)."""

    qpos: jax.Array
    qvel: jax.Array
    qacc: jax.Array
    xpos: jax.Array
    xipos: jax.Array
    geom_xpos: jax.Array
    geom_xmat: jax.Array
    site_xpos: jax.Array
    cvel: jax.Array
    cinert: jax.Array
    qfrc_actuator: jax.Array
    qfrc_constraint: jax.Array
    cfrc_ext: jax.Array
    overflow: jax.Array


def readout(data: mjx.Data, overflow: jax.Array) -> Readout:
    impl = data._impl
    return Readout(
        data.qpos,
        data.qvel,
        data.qacc,
        data.xpos,
        data.xipos,
        data.geom_xpos,
        data.geom_xmat,
        data.site_xpos,
        data.cvel,
        impl.cinert,
        data.qfrc_actuator,
        data.qfrc_constraint,
        impl.cfrc_ext,
        jnp.asarray(overflow, jnp.int32),
    )


class JaxPhysics:
    """MJX's JAX solver. Its forward pass, step and `rne_postconstraint` are each a `jax.jit`
    made once per model: every program of the process that steps the model (training's init,
    rollout and reset, evaluation) reuses one trace of MJX's Python."""

    impl = JAX

    def __init__(self, mj_model: mujoco.MjModel):
        self.model = model = mjx.put_model(mj_model)
        self.forward = jax.jit(lambda d: mjx.forward(model, d))
        self.step = jax.jit(lambda d: mjx.step(model, d))
        self.rne_postconstraint = jax.jit(lambda d: mjx.rne_postconstraint(model, d))

    def run(self, qpos, qvel, ctrl, substeps: int, contact_forces: bool) -> Readout:
        data = mjx.make_data(self.model).replace(qpos=qpos, qvel=qvel, ctrl=ctrl)
        if substeps == 0:
            data = self.forward(data)
        elif substeps == 1:
            data = self.step(data)
        else:
            data = jax.lax.fori_loop(0, substeps, lambda _, d: self.step(d), data)
        if contact_forces:
            data = self.rne_postconstraint(data)
        return readout(data, 0)


def capacities(mj_model: mujoco.MjModel) -> tuple[int, int]:
    """(contacts, constraint rows) per world at most: what MJX's JAX collision driver allocates
    for the model's collision pairs (a static bound: every pair's most contact points)."""
    data = mjx.make_data(mjx.put_model(mj_model))
    return int(data._impl.contact.dist.shape[0]), int(data._impl.efc_J.shape[0])


def per_world(mj_model: mujoco.MjModel, capacity: float) -> tuple[int, int]:
    """(contacts, constraint rows) MuJoCo Warp gets per world at `capacity` (warp_capacity) times
    the model's `capacities`: naconmax per world and njmax, which its kernels are built for."""
    contacts, rows = capacities(mj_model)
    return max(1, math.ceil(capacity * contacts)), max(1, math.ceil(capacity * rows))


# MuJoCo Warp's overflow bits (mujoco_warp OverflowType) that mean lost contacts or constraints.
# The solver's iteration limits (bits 9 and 10) are not among them: the suite caps Newton's
# iterations on purpose (envs/locomotion.py).
LOST = {
    1 << 0: "constraint rows (njmax)",
    1 << 1: "constraint nonzeros",
    1 << 2: "collision pairs (naconmax)",
    1 << 3: "contacts (naconmax)",
    1 << 4: "CCD contacts",
    1 << 5: "height-field contacts",
    1 << 7: "islands",
    1 << 8: "EPA horizon",
}
LOST_MASK = sum(LOST)
_seen = {"bits": 0}


def overflow_seen() -> str | None:
    """What MuJoCo Warp ran out of in this process so far ("contacts (naconmax)", ...), or None."""
    bits = _seen["bits"]
    return ", ".join(name for bit, name in LOST.items() if bits & bit) or None


def clear_overflow() -> None:
    """Forget the overflows seen so far (a run starting in a process that ran another)."""
    _seen["bits"] = 0


_LOST_SHIFTS = np.array([bit.bit_length() - 1 for bit in LOST], np.int32)


def _record_overflow(seen) -> None:
    """`seen[i]`: whether a world set LOST's i-th bit."""
    _seen["bits"] |= sum(bit for bit, flag in zip(LOST, np.asarray(seen)) if flag)


def collapse_vmaps(fn: Callable[..., Any]) -> Callable[..., Any]:
    """`fn` (a function of arrays with any leading batch shape, the same for all) evaluated once
    at the outermost level: every `jax.vmap` above a call is folded into the arguments' leading
    axes instead of being applied to `fn`'s body."""

    @jax.custom_batching.custom_vmap
    def collapsed(*args):
        return fn(*args)

    @collapsed.def_vmap
    def rule(axis_size, in_batched, *args):
        args = [
            a if batched else jnp.broadcast_to(a, (axis_size, *a.shape))
            for a, batched in zip(args, in_batched)
        ]
        # under an outer vmap, that one's rule folds its axis in the same way
        out = collapsed(*args)
        return out, jax.tree.map(lambda _: True, out)

    return collapsed


def _as_traced(x: Any) -> Any:
    """A template array as a program computes it: a uniform one as a fill (no constant in the
    program), any other as a constant."""
    x = np.asarray(x)
    if x.size and np.all(x == x.flat[0]):
        return jnp.full(x.shape, x.flat[0], x.dtype)
    return jnp.asarray(x)


class WarpPhysics:
    """MJX-Warp: MuJoCo Warp's kernels, the whole batch of worlds in one call per substep."""

    impl = WARP

    def __init__(
        self,
        mj_model: mujoco.MjModel,
        capacity: float = DEFAULT_CAPACITY,
        graph_mode: str | None = None,
        report_overflow: bool = True,
    ):
        enable_warp()  # warp-lang: checked by `resolve`
        import warp

        if not capacity >= 1:
            raise ValueError(f"warp_capacity must be 1 or more, got {capacity}")
        self.mj_model, self.capacity, self.report_overflow = mj_model, capacity, report_overflow
        self.contacts_per_world, self.rows_per_world = per_world(mj_model, capacity)
        mode = None if graph_mode is None else warp.JaxCallableGraphMode[graph_mode.upper()]
        with quiet():
            model = mjx.put_model(mj_model, impl="warp", graph_mode=mode)
        # warn_overflow 0: MuJoCo Warp prints no line per world and substep (the overflow bits are
        # still set, and checked here); the solver's iteration cap would print thousands.
        options = model.opt._impl.replace(warn_overflow=0)
        self.model = model.replace(opt=model.opt.replace(_impl=options))
        # the same model computing the contact forces (mj_rnePostConstraint) after its solve
        self.model_rne = self.model.replace(
            opt=model.opt.replace(_impl=options.replace(run_rne_postconstraint=True))
        )
        self._templates: dict[int, mjx.Data] = {}
        self._runs: dict[tuple[int, bool], Callable[..., Readout]] = {}

    def template(self, worlds: int) -> mjx.Data:
        """A fresh data of one world, its shared buffers sized for `worlds` worlds (numpy
        arrays)."""
        if worlds not in self._templates:
            with quiet(), jax.ensure_compile_time_eval():  # host arrays, also mid-trace
                data = mjx.make_data(
                    self.mj_model,
                    impl="warp",
                    naconmax=worlds * self.contacts_per_world,
                    njmax=self.rows_per_world,
                    device=jax.devices("cpu")[0],
                )
                self._templates[worlds] = jax.tree.map(np.asarray, data)
        return self._templates[worlds]

    def run(self, qpos, qvel, ctrl, substeps: int, contact_forces: bool) -> Readout:
        key = (substeps, contact_forces)
        if key not in self._runs:
            self._runs[key] = collapse_vmaps(
                partial(self._run_batch, substeps=substeps, contact_forces=contact_forces)
            )
        return self._runs[key](qpos, qvel, ctrl)

    def _run_batch(self, qpos, qvel, ctrl, substeps: int, contact_forces: bool) -> Readout:
        lead = qpos.shape[:-1]
        worlds = math.prod(lead)
        flat = lambda x: jnp.reshape(x, (worlds, x.shape[-1]))  # noqa: E731
        template = jax.tree.map(_as_traced, self.template(worlds))
        last = self.model_rne if contact_forces else self.model

        def one(qpos, qvel, ctrl) -> Readout:  # vmapped over the N worlds: MJX-Warp's batching rule
            data = template.replace(qpos=qpos, qvel=qvel, ctrl=ctrl)
            if substeps == 0:
                data = mjx.forward(last, data)
            else:
                data = jax.lax.fori_loop(
                    0, substeps - 1, lambda _, d: mjx.step(self.model, d), data
                )
                data = mjx.step(last, data)
            return readout(data, data._impl.overflow)

        out = jax.vmap(one)(flat(qpos), flat(qvel), flat(ctrl))
        lost = out.overflow & LOST_MASK
        # which bits any world set (max, not a bitwise or: reductions every backend has)
        if self.report_overflow:
            seen = jnp.max((lost[:, None] >> _LOST_SHIFTS) & 1, axis=0)
            jax.lax.cond(
                jnp.max(seen) > 0,
                lambda b: jax.debug.callback(_record_overflow, b),
                lambda b: None,
                seen,
            )

        def poisoned(x):
            return jnp.where(jnp.reshape(lost != 0, (worlds,) + (1,) * (x.ndim - 1)), jnp.nan, x)

        out = out.replace(
            **{
                f: poisoned(getattr(out, f))
                for f in Readout.__dataclass_fields__
                if f != "overflow"
            }
        )
        return jax.tree.map(lambda x: jnp.reshape(x, (*lead, *x.shape[1:])), out)


@dataclass(frozen=True)
class PhysicsKey:
    """What a model's physics object depends on besides the model."""

    impl: str
    capacity: float


def make_physics(mj_model: mujoco.MjModel, key: PhysicsKey) -> JaxPhysics | WarpPhysics:
    return JaxPhysics(mj_model) if key.impl == JAX else WarpPhysics(mj_model, key.capacity)
