"""MuJoCo Playground's vision tasks on a CPU: their renderer (MuJoCo Warp's batch ray tracer, CUDA
only) replaced by blank pictures, so that the rest of Playground's vision pipeline (its physics,
reward and ends, Brax's vision PPO around it) runs as shipped. Used by tests/envs/test_adapter.py
and tests/test_playground_vision.py."""

from __future__ import annotations

import jax.numpy as jnp
from mujoco import mjx


class _Context:
    def pytree(self):
        return None


def blank_renderer(monkeypatch) -> None:
    """mjx's render context, refit, render and RGB read as stand-ins: every picture is black."""
    monkeypatch.setattr(mjx, "create_render_context", lambda **kwargs: _Context())
    monkeypatch.setattr(mjx, "refit_bvh", lambda model, data, context: None)
    monkeypatch.setattr(mjx, "render", lambda model, data, context: (None,))
    monkeypatch.setattr(mjx, "get_rgb", lambda context, camera, out: jnp.zeros((64, 64, 3)))
