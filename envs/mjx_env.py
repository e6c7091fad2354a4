"""The base of every env whose physics is an MJCF model stepped by MuJoCo MJX."""

from __future__ import annotations

import mujoco
from mujoco import mjx

from hintsjax.envs.core import Env


class MjxEnv(Env):
    """An Env built from the MJCF string `mjcf`: `mj_model` (MuJoCo C, for reference and names),
    `model` (its MJX copy, what the jitted step uses) and `site_ids` (site name -> index)."""

    mjcf: str = ""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.mj_model = mujoco.MjModel.from_xml_string(self.mjcf)
        self.model = mjx.put_model(self.mj_model)
        self.site_ids = {self.mj_model.site(i).name: i for i in range(self.mj_model.nsite)}
