"""The agent's networks: the pixel encoder, MLPs, the hint embedding and the actor-critic."""

from __future__ import annotations

from typing import Sequence

import jax
import jax.numpy as jnp
import flax.linen as nn

from hintsjax.agents import AgentSpec
from hintsjax.conditioning import SCHEMES, HintEmbedding


def he_init(gain: float = 1.0) -> nn.initializers.Initializer:
    """He (fan-in) normal init scaled by `gain`.

    Not the orthogonal init PPO codebases often use: a QR decomposition inside
    `jit(vmap(init))` stalled XLA's CPU backend (jax 0.10.2) for minutes.
    """
    return nn.initializers.variance_scaling(2.0 * gain, "fan_in", "truncated_normal")


def scale_pixels(pixels: jax.Array) -> jax.Array:
    """uint8[..., H, W, C] -> float32 in [-1, 1]."""
    return pixels.astype(jnp.float32) / 127.5 - 1.0


class PatchConv(nn.Module):
    """A VALID convolution written as image patches times a dense kernel: [B, H, W, C] -> [B, H', W', F].

    Mathematically `nn.Conv`; computed this way because XLA lowers it to a matmul, which stays
    fast where `nn.Conv` does not: with seed-vmapped weights (a grouped convolution) and, on
    CPU, inside `scan` bodies whose weights change each iteration (about 12x slower there).
    """

    features: int
    kernel: int
    stride: int

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        patches = jax.lax.conv_general_dilated_patches(
            x, (self.kernel, self.kernel), (self.stride, self.stride), "VALID",
            dimension_numbers=("NHWC", "HWIO", "NHWC"),
        )
        return nn.Dense(self.features, kernel_init=he_init())(patches)


class Encoder(nn.Module):
    """Three conv layers (32 8x8/4, 64 4x4/2, 64 3x3/1, ReLU), flattened: [B, H, W, C] -> [B, k]."""

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for features, kernel, stride in ((32, 8, 4), (64, 4, 2), (64, 3, 1)):
            x = nn.relu(PatchConv(features, kernel, stride)(x))
        return x.reshape(x.shape[:-3] + (-1,))


class MLP(nn.Module):
    """Hidden ReLU layers then a linear output: [B, n] -> [B, features[-1]]."""

    features: Sequence[int]
    out_scale: float = 1.0

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for width in self.features[:-1]:
            x = nn.relu(nn.Dense(width, kernel_init=he_init())(x))
        return nn.Dense(self.features[-1], kernel_init=he_init(self.out_scale**2 / 2))(x)


class ActorCritic(nn.Module):
    """obs dict (batched) -> (action mean [B, A], log std [A], value [B]).

    The features z' come from the agent's inputs: pixels through the encoder (conditioned on
    the hint by the scheme), the state vector, or the embedded hint alone. Actor and critic are
    three-layer MLPs on z'; the policy is a Gaussian with a learnt, state-independent std.
    Top-level parameter names ("encoder", "conditioning", "actor", "log_std", "critic") are the
    optimiser's learning-rate groups.
    """

    agent: AgentSpec
    scheme: str
    action_size: int
    hint_width: int = 64
    hidden: tuple[int, ...] = (256, 256)

    def features(self, obs: dict[str, jax.Array]) -> jax.Array:
        agent = self.agent
        if agent.pixels and agent.hint:
            cond = SCHEMES[self.scheme](self.hint_width, name="conditioning")
            return cond(Encoder(name="encoder"), scale_pixels(obs["pixels"]), obs["hint"])
        if agent.pixels:
            return Encoder(name="encoder")(scale_pixels(obs["pixels"]))
        if agent.hint:
            return HintEmbedding(self.hint_width, name="conditioning")(obs["hint"])
        return obs["state"]

    @nn.compact
    def __call__(self, obs: dict[str, jax.Array]) -> tuple[jax.Array, jax.Array, jax.Array]:
        z = self.features(obs)
        mean = MLP((*self.hidden, self.action_size), out_scale=0.01, name="actor")(z)
        log_std = self.param("log_std", nn.initializers.zeros, (self.action_size,))
        value = MLP((*self.hidden, 1), out_scale=1.0, name="critic")(z)[..., 0]
        return mean, log_std, value


LR_GROUPS = {"encoder": "encoder", "conditioning": "encoder", "actor": "actor", "log_std": "actor", "critic": "critic"}


def lr_labels(params) -> dict:
    """The learning-rate group ('encoder', 'actor' or 'critic') of every parameter leaf."""
    return {
        col: {name: jax.tree.map(lambda _, g=LR_GROUPS[name]: g, sub) for name, sub in tree.items()}
        for col, tree in params.items()
    }
