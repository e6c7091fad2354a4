"""Pictures at another side than the env's own (`image_size=`): what `make run` uses (40x40).

The pendulum drawn at 40 pixels a side shows the same scene as at 64: the rod's pixels lie where
the 64-pixel picture puts them, scaled. The setting reaches the env a run builds and the memory
bound; the car, whose picture is a precomputed 96x96 grid, and sides the encoder cannot take are
refused (their one-line messages: tests/data/bad_inputs.yaml)."""

from __future__ import annotations

import jax
import numpy as np
import pytest

from hintsjax import envs
from hintsjax.system import memory
from hintsjax.system.errors import UsageError
from hintsjax.settings.layers import run_config


def rod_centre(picture: np.ndarray) -> np.ndarray:
    """The (row, column) centroid of the red rod's pixels, as fractions of the side."""
    red = (picture[..., 0] > 150) & (picture[..., 1] < 100) & (picture[..., 2] < 100)
    assert red.sum() > 0
    return np.argwhere(red).mean(axis=0) / picture.shape[0]


@pytest.mark.parametrize("theta", [0.0, 1.0, 2.5])
def test_the_pendulum_at_40_pixels_draws_the_64_pixel_scene_scaled(theta):
    small, large = envs.make("pendulum", image_size=40), envs.make("pendulum")
    params = small.default_params()
    state = small.initial_state(jax.random.key(0), params).replace(
        theta=np.float32(theta), dtheta=np.float32(0)
    )
    picture = np.asarray(small.render(state, params))
    assert picture.shape == (40, 40, 3) and picture.dtype == np.uint8
    assert np.asarray(large.render(state, params)).shape == (64, 64, 3)
    # the centroid of the rod within half a pixel of the 40-pixel grid
    np.testing.assert_allclose(
        rod_centre(picture), rod_centre(np.asarray(large.render(state, params))), atol=0.5 / 40
    )


def test_a_runs_image_size_reaches_its_env_and_memory_bound():
    cfg = run_config({"env": "pendulum", "image_size": 40})
    assert cfg.make_env().image_size == 40 and cfg.make_env(deploy=True).image_size == 40
    assert memory.picture_bytes(cfg) == 3 * 40 * 40
    default = run_config({"env": "pendulum"})
    assert (
        default.image_size is None
        and default.make_env().image_size == 64
        and memory.picture_bytes(default) == 3 * 64 * 64
    )


@pytest.mark.parametrize(
    "values",
    [
        {"image_size": 35},
        {"image_size": 257},
        {"image_size": 40.5},
        {"image_size": True},
        {"env": "car_racing", "image_size": 64},
    ],
)
def test_sides_the_encoder_or_the_env_cannot_take_are_refused(values):
    with pytest.raises(UsageError, match="image_size"):
        run_config({"env": "pendulum", **values})


def test_the_car_keeps_its_own_side():
    assert run_config({"env": "car_racing", "image_size": 96}).make_env().image_size == 96
    with pytest.raises(ValueError, match="96x96 pictures only"):
        envs.make("car_racing", image_size=64)
