"""The base of every env whose physics is an MJCF model stepped by MuJoCo MJX."""

from __future__ import annotations

from importlib import resources
from typing import Any

import jax
import mujoco

from hintsjax.envs.core import OBS_KEYS, Env
from hintsjax.envs.hints import Hint
from hintsjax.envs.physics import (
    AUTO,
    DEFAULT_CAPACITY,
    WARP,
    JaxPhysics,
    PhysicsKey,
    WarpPhysics,
    make_physics,
    resolve,
)


# an env class's physics, made once per implementation (and Warp's capacity)
_PER_CLASS: dict[tuple[type, PhysicsKey], JaxPhysics | WarpPhysics] = {}


def load_asset(name: str) -> str:
    """The text of `envs/assets/<name>`: the Gymnasium models we build on, kept verbatim."""
    return resources.files("hintsjax.envs").joinpath("assets", name).read_text()


class MjxEnv(Env):
    """An Env built from the MJCF string `mjcf` (or the packaged file `asset`), with the
    `mj_model.opt` fields in `options` overridden: `mj_model` (MuJoCo C, for reference and
    names), `physics` (MJX's JAX solver or MJX-Warp on it: `physics`, envs/physics.py) and
    `site_ids` (site name -> index)."""

    mjcf: str = ""
    asset: str = ""
    options: dict[str, Any] = {}

    # Whether physics=auto picks MJX-Warp for this env on an NVIDIA GPU (with warp-lang). The
    # locomotion envs do (envs/locomotion.py); the small classic-control models keep MJX's JAX
    # solver, where Warp was never measured faster and Table 2's rows stay bit-reproducible
    # (docs/environments.md, "Physics").
    warp_by_default: bool = False

    def __init__(
        self,
        hint: Hint,
        observe: tuple[str, ...] = OBS_KEYS,
        physics: str = AUTO,
        warp_capacity: float = DEFAULT_CAPACITY,
        image_size: int | None = None,
    ):
        super().__init__(hint, observe, image_size)
        self.mj_model = self.make_mj_model()
        impl = resolve(physics, jax.default_backend(), self.warp_by_default, jax.device_count())
        key = PhysicsKey(impl, float(warp_capacity) if impl == WARP else 0.0)
        # the model depends on the class alone (its MJCF and options)
        if (type(self), key) not in _PER_CLASS:
            _PER_CLASS[type(self), key] = make_physics(self.mj_model, key)
        self.physics = _PER_CLASS[type(self), key]
        self.site_ids = {self.mj_model.site(i).name: i for i in range(self.mj_model.nsite)}

    @classmethod
    def with_options(cls, **options: Any) -> type[MjxEnv]:
        """This env's class with more `mj_model.opt` fields overridden (e.g. fewer solver
        iterations): what a benchmark compares. The registered envs keep their documented
        options."""
        return type(cls.__name__, (cls,), {"options": {**cls.options, **options}})

    @classmethod
    def make_mj_model(cls) -> mujoco.MjModel:
        """The MuJoCo C model with this env's changes (`adapt`): what a parity test steps as the
        reference."""
        return cls.adapt(mujoco.MjModel.from_xml_string(cls.mjcf or load_asset(cls.asset)))

    @classmethod
    def adapt(cls, model: mujoco.MjModel) -> mujoco.MjModel:
        """`model` (changed in place) with this env's changes to its file: the `options`; an env
        that changes more extends this, so that a test can make the same changes to a reference."""
        for field, value in cls.options.items():
            setattr(model.opt, field, value)
        return model
