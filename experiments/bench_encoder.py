"""Encoder implementations compared: the convolution as patches x dense, as blocked matmuls
(PatchConv's strided layers, hintsjax.models.networks.blocked_conv) and as nn.Conv, f32 and bf16.

    python experiments/bench_encoder.py [--batch 8192] [--seeds 5] [--convs patches,blocks,conv]
                                        [--deterministic-ops on|off]

For each variant: samples/s of forward+backward+Adam for the pixel encoder plus a 256-256 head,
once at one batch and once vmapped over `--seeds` weight copies (the seed-vmapped training case)
with the same total batch. Informs the choice of `hintsjax.models.networks.PatchConv`. Deterministic
GPU ops on, as hintsjax sets them, unless `--deterministic-ops off` (what a run under MuJoCo Warp
learns with): they slow the learner by about a third (docs/throughput.md).
"""

from __future__ import annotations

import argparse

import flax.linen as nn
import jax
import jax.numpy as jnp
import optax

from hintsjax.models.networks import MLP, PatchConv
from hintsjax.system import xla_flags

CONVS = ("patches", "blocks", "conv")


class Net(nn.Module):
    conv: str
    dtype: jnp.dtype

    @nn.compact
    def __call__(self, x):
        x = x.astype(self.dtype)
        for f, k, s in ((32, 8, 4), (64, 4, 2), (64, 3, 1)):
            if self.conv in ("patches", "blocks"):
                layer = PatchConv(f, k, s, dtype=self.dtype, blocked=self.conv == "blocks")
                x = nn.relu(layer(x))
            else:
                x = nn.relu(nn.Conv(f, (k, k), (s, s), "VALID", dtype=self.dtype)(x))
        x = x.reshape(x.shape[:-3] + (-1,)).astype(jnp.float32)
        return MLP((256, 256, 2))(x)


def rate(conv: str, dtype, batch: int, seeds: int) -> float:
    from bench import best_time

    net = Net(conv, dtype)
    per = batch // seeds
    x = jax.random.uniform(jax.random.key(0), (seeds, per, 64, 64, 3), minval=-1, maxval=1)
    params = jax.vmap(net.init)(jax.random.split(jax.random.key(1), seeds), x[:, :1])
    tx = optax.adam(1e-3)
    opt = jax.vmap(tx.init)(params)

    def step(p, s, x):
        g = jax.grad(lambda p: (net.apply(p, x) ** 2).mean())(p)
        u, s = tx.update(g, s, p)
        return optax.apply_updates(p, u), s

    f = jax.jit(jax.vmap(step))
    return seeds * per / best_time(f, params, opt, x, repeats=10)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--batch", type=int, default=8192)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--convs", default=",".join(CONVS), help=f"of {', '.join(CONVS)}")
    parser.add_argument("--deterministic-ops", choices=("on", "off"), default="on")
    args = parser.parse_args()
    if args.deterministic_ops == "off":  # before JAX's backend starts: it reads XLA_FLAGS once
        xla_flags.drop_determinism()
    convs = args.convs.split(",")
    if unknown := [c for c in convs if c not in CONVS]:
        parser.error(f"unknown --convs {', '.join(unknown)}; valid: {', '.join(CONVS)}")
    print(
        f"device: {jax.devices()[0].device_kind}, deterministic ops "
        f"{'on' if xla_flags.deterministic_gpu_ops() else 'off'}"
    )
    for conv in convs:
        for dtype in (jnp.float32, jnp.bfloat16):
            for seeds in (1, args.seeds):
                r = rate(conv, dtype, args.batch, seeds)
                print(
                    f"{conv:8s} {jnp.dtype(dtype).name:8s} seeds={seeds:<3d} batch={args.batch}: "
                    f"{r:,.0f} samples/s",
                    flush=True,
                )


if __name__ == "__main__":
    main()
