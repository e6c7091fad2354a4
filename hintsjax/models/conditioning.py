"""The four conditioning schemes: how the hint h enters the features z' of a pixel agent.

Each scheme is a Flax module called as `scheme(encoder, x, h)` with x = pixels in [-1, 1]
[B, H, W, C] and h = hint [B, d]; it returns z' [B, k'].

| name | paper eq. | z' |
|------|-----------|----|
| lc   | (1) | [z, g(h)]                          latent concatenation |
| ac   | (2) | z + g(h), g maps to dim z           latent addition |
| fc   | (3) | z * (1 + alpha(h)) + beta(h)        FiLM on the embedding |
| mc   | (4) | enc([x, mask(h)])                   d constant channels, one per hint entry |

FiLM predicts alpha as a change from 1 (Perez et al.'s residual form), so an untrained scheme
passes z through rather than scaling it towards zero.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import flax.linen as nn


class HintEmbedding(nn.Module):
    """g: Linear(d, width), ReLU, Linear(width, out): [B, d] -> [B, out] (out = width if 0)."""

    width: int = 64
    out: int = 0

    @nn.compact
    def __call__(self, h: jax.Array) -> jax.Array:
        x = nn.relu(nn.Dense(self.width)(h))
        return nn.Dense(self.out or self.width)(x)


class LatentConcat(nn.Module):
    width: int = 64

    @nn.compact
    def __call__(self, encoder: nn.Module, x: jax.Array, h: jax.Array) -> jax.Array:
        return jnp.concatenate([encoder(x), HintEmbedding(self.width)(h)], axis=-1)


class LatentAdd(nn.Module):
    width: int = 64

    @nn.compact
    def __call__(self, encoder: nn.Module, x: jax.Array, h: jax.Array) -> jax.Array:
        z = encoder(x)
        return z + HintEmbedding(self.width, z.shape[-1])(h)


class FiLM(nn.Module):
    width: int = 64

    @nn.compact
    def __call__(self, encoder: nn.Module, x: jax.Array, h: jax.Array) -> jax.Array:
        z = encoder(x)
        alpha, beta = jnp.split(HintEmbedding(self.width, 2 * z.shape[-1])(h), 2, axis=-1)
        return z * (1.0 + alpha) + beta


class MaskedInput(nn.Module):
    width: int = 64

    @nn.compact
    def __call__(self, encoder: nn.Module, x: jax.Array, h: jax.Array) -> jax.Array:
        masks = jnp.broadcast_to(h[..., None, None, :], x.shape[:-1] + h.shape[-1:])
        return encoder(jnp.concatenate([x, masks.astype(x.dtype)], axis=-1))


SCHEMES: dict[str, type[nn.Module]] = {
    "lc": LatentConcat,
    "ac": LatentAdd,
    "fc": FiLM,
    "mc": MaskedInput,
}
