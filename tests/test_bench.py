"""experiments/bench.py's command-line parsing of physics options (its timings run on the GPU)."""

from __future__ import annotations


import mujoco
import pytest

import bench  # experiments/bench.py: experiments/ is on pytest's path (pyproject's pythonpath)


def test_model_options_parse_enums_by_name_and_numbers():
    options = bench.model_options(["integrator=euler", "iterations=1", "tolerance=1e-6", "cone=ELLIPTIC"])
    assert options == {"integrator": mujoco.mjtIntegrator.mjINT_EULER, "iterations": 1, "tolerance": 1e-6,
                       "cone": mujoco.mjtCone.mjCONE_ELLIPTIC}


@pytest.mark.parametrize("item, names", [("integrater=EULER", "integrator"), ("integrator=RK5", "RK4"),
                                         ("iterations", "iterations")])
def test_bad_model_options_name_the_valid_ones(item, names):
    with pytest.raises(ValueError, match=names):
        bench.model_options([item])
