"""The agent's networks: the pixel encoder, MLPs, the hint embedding and the actor-critic."""

from __future__ import annotations

import functools
from typing import Any, Sequence

import jax
import jax.numpy as jnp
import flax.linen as nn

from hintsjax.models import normalization
from hintsjax.models.agents import AgentSpec
from hintsjax.models.conditioning import HintEmbedding, SCHEMES
from hintsjax.models.normalization import StateNorm


def he_init(gain: float = 1.0) -> nn.initializers.Initializer:
    """He (fan-in) normal init scaled by `gain`.

    Not the orthogonal init PPO codebases often use: a QR decomposition inside
    `jit(vmap(init))` stalled XLA's CPU backend (jax 0.10.2) for minutes.
    """
    return nn.initializers.variance_scaling(2.0 * gain, "fan_in", "truncated_normal")


def scale_pixels(pixels: jax.Array, scale: float = 1.0) -> jax.Array:
    """uint8[..., H, W, C] -> float32 in [-scale, scale]."""
    return (pixels.astype(jnp.float32) / 127.5 - 1.0) * scale


def image_patches(x: jax.Array, kernel: int, stride: int) -> jax.Array:
    """[B, H, W, C] -> [B, H', W', k*k*C] VALID patches, ordered (row, column, channel).

    Built from k*k strided slices: pure data movement, where `lax.conv_general_dilated_patches`
    costs a convolution with an identity kernel (8x the FLOPs of the real layer for 4x4x32).
    """
    h = (x.shape[-3] - kernel) // stride + 1
    w = (x.shape[-2] - kernel) // stride + 1
    span_h, span_w = stride * (h - 1) + 1, stride * (w - 1) + 1
    slices = [
        x[..., i : i + span_h : stride, j : j + span_w : stride, :]
        for i in range(kernel)
        for j in range(kernel)
    ]
    return jnp.concatenate(slices, axis=-1)


def blocked_conv(x: jax.Array, kernel: jax.Array, stride: int) -> jax.Array:
    """A VALID convolution, stride s dividing the kernel's side k: [B, H, W, C] -> [B, H', W', F].

    The picture is cut into s x s blocks (space to depth: [B, H/s, W/s, s*s*C]) and the kernel
    into (k/s)^2 blocks of [s*s*C, F]; the output is the sum of the (k/s)^2 products of shifted
    block views with their kernel blocks. Nothing the size of the patches ([B, H', W', k*k*C],
    (k/s)^2 times the picture) is written: the 8x8/4 layer reads its picture once, not four times.
    """
    k, c, f = kernel.shape[0], kernel.shape[2], kernel.shape[3]
    q = k // stride
    h = (x.shape[-3] - k) // stride + 1
    w = (x.shape[-2] - k) // stride + 1
    hb, wb = h + q - 1, w + q - 1  # the blocks the output's receptive fields cover
    batch = x.shape[:-3]
    x = x[..., : hb * stride, : wb * stride, :]
    x = x.reshape(*batch, hb, stride, wb, stride, c)
    x = jnp.swapaxes(x, -4, -3).reshape(*batch, hb, wb, stride * stride * c)
    # kernel [k, k, C, F] -> [q, s, q, s, C, F] -> [q, q, s, s, C, F]: the same (row, column,
    # channel) order within a block as the picture's
    blocks = jnp.swapaxes(kernel.reshape(q, stride, q, stride, c, f), 1, 2)
    blocks = blocks.reshape(q, q, stride * stride * c, f)
    out = None  # summed in float32 (a bfloat16 encoder's products too), as one matmul would
    for a in range(q):
        for b in range(q):
            view = x[..., a : a + h, b : b + w, :]
            term = jnp.matmul(view, blocks[a, b], preferred_element_type=jnp.float32)
            out = term if out is None else out + term
    return out.astype(x.dtype)


def patch_conv(x: jax.Array, kernel: jax.Array, stride: int) -> jax.Array:
    """A VALID convolution as one matmul of the image patches with the flattened kernel."""
    k, c, f = kernel.shape[0], kernel.shape[2], kernel.shape[3]
    return image_patches(x, k, stride) @ kernel.reshape(k * k * c, f)


class PatchConv(nn.Module):
    """A VALID convolution as matmuls: [B, H, W, C] -> [B, H', W', F].

    The same parameters (kernel [k, k, C, F], bias [F]) and result as `nn.Conv`; computed as
    matmuls because they stay fast where `nn.Conv` does not: with seed-vmapped weights (a
    grouped convolution, 4x slower on a GPU) and, on CPU, inside `scan` bodies whose weights
    change each iteration (12x slower; docs/throughput.md). A strided layer whose stride divides
    its kernel computes as `blocked_conv` (no patches written), the others as `patch_conv`.
    """

    features: int
    kernel: int
    stride: int
    dtype: Any = None  # computation dtype (params stay float32)
    blocked: bool = True  # False: patches at every layer (experiments/bench_encoder.py compares)

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        k, c = self.kernel, x.shape[-1]
        kernel = self.param("kernel", he_init(), (k, k, c, self.features))
        bias = self.param("bias", nn.initializers.zeros, (self.features,))
        dtype = self.dtype or jnp.result_type(x, kernel)
        blocked = self.blocked and self.stride > 1 and k % self.stride == 0
        conv = blocked_conv if blocked else patch_conv
        return conv(x.astype(dtype), kernel.astype(dtype), self.stride) + bias.astype(dtype)


# The smallest picture side the encoder takes: its VALID convolutions map 36 pixels to 8, 3 and 1.
MIN_IMAGE_SIZE = 36


class Encoder(nn.Module):
    """Three conv layers (32 8x8/4, 64 4x4/2, 64 3x3/1, ReLU), flattened: [B, H, W, C] -> [B, k],
    computed in `dtype` (None: the input's), returned as float32."""

    dtype: Any = None

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for features, kernel, stride in ((32, 8, 4), (64, 4, 2), (64, 3, 1)):
            x = nn.relu(PatchConv(features, kernel, stride, dtype=self.dtype)(x))
        return x.reshape(x.shape[:-3] + (-1,)).astype(jnp.float32)


def max_pool_2x2(x: jax.Array) -> jax.Array:
    """nn.max_pool(x, (2, 2), strides=(2, 2), padding="SAME") over [..., H, W, C], its values and
    its gradient (all of it to each window's first maximum, row by row, as XLA's select-and-scatter
    gives it) alike, ties included, but from elementwise ops: the select-and-scatter that
    reduce_window's gradient is has no fast deterministic form on GPUs (XLA's deterministic ops
    serialise it), and on a CPU it is slower too."""
    h, w = x.shape[-3:-1]
    pad = [(0, 0)] * (x.ndim - 3) + [(0, h % 2), (0, w % 2), (0, 0)]
    x = jnp.pad(x, pad, constant_values=-jnp.inf)  # SAME: an odd side's last window is short
    *lead, h, w, c = x.shape
    windows = x.reshape(*lead, h // 2, 2, w // 2, 2, c)
    windows = jnp.moveaxis(windows, (-4, -2), (-2, -1)).reshape(*lead, h // 2, w // 2, c, 4)
    first = jnp.arange(4) == jnp.argmax(windows, axis=-1)[..., None]
    return jnp.where(first, windows, 0.0).sum(axis=-1)


class BraxVisionEncoder(nn.Module):
    """The CNN of Brax's vision PPO as MuJoCo Playground tunes it for CartpoleBalance
    (`dm_control_suite_params.brax_vision_ppo_config`): two SAME convolutions (16 5x5/2, 32 3x3/2),
    each followed by ELU and a 2x2 max-pool, flattened: [B, 64, 64, C] -> [B, 512]. The same
    layers as Brax's `networks.CNN` computed as PatchConv's matmuls and max_pool_2x2; He inits,
    not Brax's orthogonal ones (he_init says why). Computed in `dtype`, returned as float32."""

    dtype: Any = None

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        for features, kernel, stride in ((16, 5, 2), (32, 3, 2)):
            # zero-padded so that PatchConv's VALID convolution is nn.Conv's SAME one
            pads = jax.lax.padtype_to_pads(x.shape[-3:-1], (kernel,) * 2, (stride,) * 2, "SAME")
            x = jnp.pad(x, [(0, 0)] * (x.ndim - 3) + list(pads) + [(0, 0)])
            x = nn.elu(PatchConv(features, kernel, stride, dtype=self.dtype)(x))
            x = max_pool_2x2(x)
        return x.reshape(x.shape[:-3] + (-1,)).astype(jnp.float32)


# The pixel encoders (`ppo.encoder`): "nature", the paper's (Mnih et al. 2015's layers), and
# "brax_vision", Brax's vision PPO's as Playground tunes it (experiments/playground_vision.py).
ENCODERS = {"nature": Encoder, "brax_vision": BraxVisionEncoder}


# The MLPs' hidden activation (`ppo.activation`): hintsjax's ReLU, or swish (x sigmoid(x)), the
# activation of Brax's PPO networks, vision ones included.
ACTIVATIONS = {"relu": nn.relu, "swish": nn.swish}


class MLP(nn.Module):
    """Hidden layers (`activation`, an ACTIVATIONS key) then a linear output:
    [B, n] -> [B, features[-1]]."""

    features: Sequence[int]
    out_scale: float = 1.0
    activation: str = "relu"

    @nn.compact
    def __call__(self, x: jax.Array) -> jax.Array:
        act = ACTIVATIONS[self.activation]
        for width in self.features[:-1]:
            x = act(nn.Dense(width, kernel_init=he_init())(x))
        return nn.Dense(self.features[-1], kernel_init=he_init(self.out_scale**2 / 2))(x)


SIGMOID_MIN_STD = 0.01  # the sigmoid head's floor on the policy's std
# The policy's std (`ppo.std_head`): "param", one learnt parameter a dimension whatever the input
# (log std [A], starting at std 1); "softplus", Brax's: softplus of the actor's second A outputs
# plus SOFTPLUS_MIN_STD, so it depends on the input (log std [B, A], starting near softplus(0),
# 0.69).
STD_HEADS = ("param", "softplus")
SOFTPLUS_MIN_STD = 0.001


class ActorCritic(nn.Module):
    """obs dict (batched) -> (action mean [B, A], log std [A] or [B, A], value [B]).

    The features z' come from the agent's inputs: pixels through the encoder (conditioned on
    the hint by the scheme), the state vector, or the embedded hint alone. Actor and critic are
    three-layer MLPs on z' (their hidden activation `activation`); the policy is a Gaussian whose
    std is a learnt parameter ([A]) or, with `std_head` "softplus", the actor's ([B, A]). With
    `action_head` "sigmoid" (the authors' head) its mean is 2 sigmoid(x) - 1 and its std at least
    SIGMOID_MIN_STD; "gaussian" and "tanh" leave both as they are (tanh squashes in the env:
    envs.SquashedActions). Without `critic_trains_encoder` the critic reads z' through a
    stop-gradient: its loss trains the critic's MLP alone. With `critic_encoder` "own" the critic
    reads features of its own, from an encoder (and conditioning) that its loss alone trains.
    The hint's role is the agent's `hint_use`: the features' input (conditioned by the scheme), the
    critic's alone (embedded beside z', "critic_hint"), or a target that z' predicts ("hint_head",
    given by `predict_hint`). Top-level parameter names are the optimiser's learning-rate groups.
    With `normalize_state` the state passes through the running normaliser first
    (hintsjax.models.normalization; its statistics are the "obs_stats" collection).
    """

    agent: AgentSpec
    scheme: str
    action_size: int
    hint_width: int = 64
    hidden: tuple[int, ...] = (256, 256)
    normalize_state: bool = False
    action_head: str = "gaussian"
    critic_trains_encoder: bool = True
    min_log_std: float | None = None  # a floor on the log std, after the head's own (None: none)
    encoder: str = "nature"  # the pixel encoder, an ENCODERS key
    encoder_dtype: str = "float32"  # the pixel encoder's arithmetic
    critic_encoder: str = "shared"  # "own": the critic's features from an encoder of its own
    pixel_scale: float = 1.0  # the pictures enter the encoder in [-pixel_scale, pixel_scale]
    activation: str = "relu"  # the MLPs' hidden activation, an ACTIVATIONS key
    std_head: str = "param"  # the policy's std, a STD_HEADS entry

    def features(self, obs: dict[str, jax.Array], owner: str = "") -> jax.Array:
        """z' from the agent's inputs; `owner` "critic_" builds the critic's own encoder and
        conditioning (modules critic_encoder and critic_conditioning)."""
        agent = self.agent
        make = ENCODERS[self.encoder]
        encoder = lambda: make(jnp.dtype(self.encoder_dtype), name=f"{owner}encoder")  # noqa: E731
        if agent.conditioned:
            cond = SCHEMES[self.scheme](self.hint_width, name=f"{owner}conditioning")
            return cond(encoder(), scale_pixels(obs["pixels"], self.pixel_scale), obs["hint"])
        if agent.pixels:
            return encoder()(scale_pixels(obs["pixels"], self.pixel_scale))
        if agent.hint and agent.hint_use == "input":
            return HintEmbedding(self.hint_width, name="conditioning")(obs["hint"])
        return (
            StateNorm(name=normalization.NAME)(obs["state"])
            if self.normalize_state
            else obs["state"]
        )

    @nn.compact
    def __call__(
        self, obs: dict[str, jax.Array], predict_hint: bool = False
    ) -> tuple[jax.Array, ...]:
        z = self.features(obs)
        mlp = functools.partial(MLP, activation=self.activation)
        if self.std_head == "softplus":
            out = mlp((*self.hidden, 2 * self.action_size), out_scale=0.01, name="actor")(z)
            mean, raw = jnp.split(out, 2, axis=-1)
            log_std = jnp.log(nn.softplus(raw) + SOFTPLUS_MIN_STD)
        else:
            mean = mlp((*self.hidden, self.action_size), out_scale=0.01, name="actor")(z)
            log_std = self.param("log_std", nn.initializers.zeros, (self.action_size,))
        if self.action_head == "sigmoid":
            mean, log_std = (
                2.0 * nn.sigmoid(mean) - 1.0,
                jnp.maximum(log_std, jnp.log(SIGMOID_MIN_STD)),
            )
        if self.min_log_std is not None:
            log_std = jnp.maximum(log_std, self.min_log_std)
        if self.critic_encoder == "own":
            critic_in = self.features(obs, owner="critic_")
        else:
            critic_in = z if self.critic_trains_encoder else jax.lax.stop_gradient(z)
        # the privileged hint beside the features, the critic's alone
        if self.agent.hint_use == "critic":
            critic_in = jnp.concatenate(
                [critic_in, HintEmbedding(self.hint_width, name="critic_hint")(obs["hint"])], -1
            )
        value = mlp((*self.hidden, 1), out_scale=1.0, name="critic")(critic_in)[..., 0]
        if self.agent.hint_use != "target":
            return mean, log_std, value
        # Built at every call (init included), returned when asked: the loss's prediction of the
        # hint.
        prediction = mlp((self.hidden[0], obs["hint"].shape[-1]), name="hint_head")(z)
        return (mean, log_std, value, prediction) if predict_hint else (mean, log_std, value)


# "frozen": the normaliser's statistics, which the optimiser leaves alone (normalization.update sets
# them). The hint's head trains with the encoder it shapes; the critic's hint embedding with the
# critic.
LR_GROUPS = {
    "encoder": "encoder",
    "conditioning": "encoder",
    # ppo.critic_encoder=own: a group of its own (clipped apart under ppo.grad_clip=per_part, so
    # the critic's loss never shrinks the actor's encoder's step), at the encoders' rate
    "critic_encoder": "critic_encoder",
    "critic_conditioning": "critic_encoder",
    "actor": "actor",
    "log_std": "actor",
    "critic": "critic",
    "critic_hint": "critic",
    "hint_head": "encoder",
    normalization.NAME: "frozen",
}


def lr_labels(params) -> dict:
    """The learning-rate group ('encoder', 'actor', 'critic', 'critic_encoder' or 'frozen') of
    every parameter leaf."""
    return {
        col: {name: jax.tree.map(lambda _, g=LR_GROUPS[name]: g, sub) for name, sub in tree.items()}
        for col, tree in params.items()
    }
