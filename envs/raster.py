"""Pure-JAX 2D rasteriser primitives: signed distances to shapes, painted with anti-aliasing.

A picture is built as a float32[S, S, 3] canvas in [0, 1] from a background colour, then shapes
are painted over it in order; `to_uint8` gives the observation. Everything is elementwise over
the pixel grid, so it jits, vmaps, and costs a few hundred flops per pixel.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def pixel_centres(
    size: int, half_extent: float, centre: tuple[float, float] = (0.0, 0.0)
) -> jax.Array:
    """float32[S, S, 2] world (x, y) of each pixel centre of a square view of half-width
    `half_extent` around `centre`; row 0 is the top (largest y)."""
    edge = jnp.linspace(-half_extent, half_extent, size + 1, dtype=jnp.float32)
    mid = 0.5 * (edge[1:] + edge[:-1])
    x = jnp.broadcast_to(centre[0] + mid[None, :], (size, size))
    y = jnp.broadcast_to(centre[1] + mid[::-1, None], (size, size))
    return jnp.stack([x, y], axis=-1)


def segment_distance(points: jax.Array, a: jax.Array, b: jax.Array) -> jax.Array:
    """float32[...] distance from points [..., 2] to the segment from a[2] to b[2]."""
    ab = b - a
    ap = points - a
    s = jnp.clip(jnp.sum(ap * ab, -1) / jnp.maximum(jnp.sum(ab * ab), 1e-12), 0.0, 1.0)
    closest = a + s[..., None] * ab
    return jnp.linalg.norm(points - closest, axis=-1)


def point_distance(points: jax.Array, c: jax.Array) -> jax.Array:
    """float32[...] distance from points [..., 2] to the point c[2]."""
    return jnp.linalg.norm(points - c, axis=-1)


def coverage(distance: jax.Array, radius: float | jax.Array, pixel: float) -> jax.Array:
    """float32[...] in [0, 1]: how much of a pixel of width `pixel` lies within `radius`."""
    return jnp.clip(0.5 - (distance - radius) / pixel, 0.0, 1.0)


def canvas(size: int, colour: tuple[float, float, float]) -> jax.Array:
    """float32[S, S, 3] filled with `colour` (RGB in [0, 1])."""
    return jnp.broadcast_to(jnp.asarray(colour, jnp.float32), (size, size, 3))


def paint(image: jax.Array, cover: jax.Array, colour: tuple[float, float, float]) -> jax.Array:
    """Blend `colour` over image [S, S, 3] with per-pixel weights `cover` [S, S]."""
    c = jnp.asarray(colour, jnp.float32)
    return image + cover[..., None] * (c - image)


def to_uint8(image: jax.Array) -> jax.Array:
    """uint8[S, S, 3] from a float canvas in [0, 1]."""
    return jnp.round(jnp.clip(image, 0.0, 1.0) * 255.0).astype(jnp.uint8)
