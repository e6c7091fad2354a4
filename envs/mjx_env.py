"""The base of every env whose physics is an MJCF model stepped by MuJoCo MJX."""

from __future__ import annotations

from dataclasses import dataclass
from importlib import resources
from typing import Any, Callable

import jax
import mujoco
from mujoco import mjx

from hintsjax.envs.core import Env


_PER_CLASS: dict[type, tuple[Any, Physics]] = {}  # an env class's MJX model and Physics, made once


def load_asset(name: str) -> str:
    """The text of `envs/assets/<name>`: the Gymnasium models we build on, kept verbatim."""
    return resources.files("hintsjax.envs").joinpath("assets", name).read_text()


@dataclass(frozen=True)
class Physics:
    """MJX's functions on one env class's model, each a `jax.jit` made once per class: every
    call with the same shapes, in any program of the process (training's init, rollout and reset,
    evaluation), reuses one trace of MJX's Python instead of tracing it again (the tracing, not
    XLA's compile, was most of a warm start's compile time)."""

    forward: Callable[[mjx.Data], mjx.Data]
    step: Callable[[mjx.Data], mjx.Data]
    rne_postconstraint: Callable[[mjx.Data], mjx.Data]


def physics_of(model: Any) -> Physics:
    """MJX's functions on `model`, jitted."""
    return Physics(jax.jit(lambda d: mjx.forward(model, d)), jax.jit(lambda d: mjx.step(model, d)),
                   jax.jit(lambda d: mjx.rne_postconstraint(model, d)))


class MjxEnv(Env):
    """An Env built from the MJCF string `mjcf` (or the packaged file `asset`), with the
    `mj_model.opt` fields in `options` overridden: `mj_model` (MuJoCo C, for reference and
    names), `model` (its MJX copy, what the jitted step uses) and `site_ids` (site name ->
    index)."""

    mjcf: str = ""
    asset: str = ""
    options: dict[str, Any] = {}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.mj_model = self.make_mj_model()
        if type(self) not in _PER_CLASS:  # the model depends on the class alone (its MJCF and options)
            model = mjx.put_model(self.mj_model)
            _PER_CLASS[type(self)] = model, physics_of(model)
        self.model, self.physics = _PER_CLASS[type(self)]
        self.site_ids = {self.mj_model.site(i).name: i for i in range(self.mj_model.nsite)}

    @classmethod
    def with_options(cls, **options: Any) -> type[MjxEnv]:
        """This env's class with more `mj_model.opt` fields overridden (e.g. fewer solver
        iterations): what a benchmark compares. The registered envs keep their documented options."""
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
