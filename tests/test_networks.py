"""Networks and conditioning schemes: the conv as patches equals nn.Conv; each scheme's shape and
use of h."""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hintsjax.models.agents import AGENTS
from hintsjax.models.conditioning import SCHEMES
from hintsjax.models.networks import (
    ActorCritic,
    BraxVisionEncoder,
    Encoder,
    PatchConv,
    blocked_conv,
    image_patches,
    patch_conv,
    lr_labels,
    scale_pixels,
)


@pytest.mark.parametrize(
    "size,channels,kernel,stride", [(64, 3, 8, 4), (15, 32, 4, 2), (6, 64, 3, 1), (36, 5, 8, 4)]
)
def test_patch_conv_equals_nn_conv_with_the_same_params(size, channels, kernel, stride):
    x = jax.random.normal(jax.random.key(0), (2, size, size, channels))
    layer = PatchConv(16, kernel, stride)
    params = layer.init(jax.random.key(1), x)
    params = jax.tree.map(lambda p: p + 0.1, params)  # a non-zero bias too
    ref = nn.Conv(16, (kernel, kernel), (stride, stride), "VALID").apply(params, x)
    np.testing.assert_allclose(layer.apply(params, x), ref, rtol=1e-5, atol=1e-5)


@pytest.mark.parametrize(
    "shape,kernel,stride",
    [((2, 64, 64, 3), 8, 4), ((3, 2, 15, 15, 32), 4, 2), ((1, 37, 41, 5), 8, 4)],
)
def test_blocked_conv_equals_patch_conv_in_values_and_gradients(shape, kernel, stride):
    """Odd sides (cropped blocks), leading batch axes (vmapped seeds) and both inputs' gradients."""
    kx, kk, kc = jax.random.split(jax.random.key(2), 3)
    x = jax.random.normal(kx, shape)
    w = jax.random.normal(kk, (kernel, kernel, shape[-1], 8))
    cot = jax.random.normal(kc, patch_conv(x, w, stride).shape)

    def loss(conv):
        return lambda x, w: (conv(x, w, stride) * cot).sum()

    np.testing.assert_allclose(
        blocked_conv(x, w, stride), patch_conv(x, w, stride), rtol=1e-4, atol=1e-4
    )
    for got, want in zip(
        jax.grad(loss(blocked_conv), (0, 1))(x, w), jax.grad(loss(patch_conv), (0, 1))(x, w)
    ):
        np.testing.assert_allclose(got, want, rtol=1e-4, atol=1e-3)


def test_image_patches_order_is_row_column_channel():
    x = jnp.arange(4 * 4 * 2, dtype=jnp.float32).reshape(1, 4, 4, 2)
    p = image_patches(x, 2, 2)  # [1, 2, 2, 8]
    assert p.shape == (1, 2, 2, 8)
    # the patch at output (1, 0) covers rows 2-3, columns 0-1
    expected = np.concatenate([x[0, 2, 0], x[0, 2, 1], x[0, 3, 0], x[0, 3, 1]])
    np.testing.assert_array_equal(p[0, 1, 0], expected)


def test_encoder_latent_is_1024_for_64x64():
    x = jnp.zeros((3, 64, 64, 3))
    z, _ = Encoder().init_with_output(jax.random.key(0), x)
    assert z.shape == (3, 1024)


def test_a_bfloat16_encoder_keeps_float32_params_and_features_near_float32s():
    """ppo.encoder_dtype=bfloat16: the same parameters (float32), features returned as float32,
    within bfloat16's 8 bits of mantissa of the float32 encoder's, and its matmuls in bfloat16
    (the features differ: the dtype reaches the convolutions)."""
    x = jax.random.uniform(jax.random.key(5), (3, 64, 64, 3), minval=-1, maxval=1)
    params = Encoder().init(jax.random.key(0), x)
    assert (
        Encoder(jnp.bfloat16).init(jax.random.key(0), x)["params"].keys() == params["params"].keys()
    )
    assert all(p.dtype == jnp.float32 for p in jax.tree.leaves(params))
    full, half = Encoder().apply(params, x), Encoder(jnp.bfloat16).apply(params, x)
    assert half.dtype == jnp.float32 and half.shape == full.shape
    scale = float(jnp.abs(full).max())
    assert 0 < float(jnp.abs(half - full).max()) <= 0.05 * scale


class BraxCNN(nn.Module):
    """Brax's `networks.CNN` as Playground's vision config builds it (brax 0.14.2: nn.Conv with
    SAME padding, ELU, nn.max_pool 2x2/2 SAME), flattened: the reference the encoder matches."""

    @nn.compact
    def __call__(self, x):
        for features, kernel in ((16, 5), (32, 3)):
            x = nn.elu(nn.Conv(features, (kernel, kernel), strides=(2, 2), padding="SAME")(x))
            x = nn.max_pool(x, window_shape=(2, 2), strides=(2, 2), padding="SAME")
        return x.reshape(x.shape[:-3] + (-1,))


@pytest.mark.parametrize("size,channels", [(64, 3), (64, 9), (37, 1)])
def test_the_brax_vision_encoder_equals_brax_s_cnn_with_the_same_params(size, channels):
    """ppo.encoder=brax_vision: Brax's layers, its SAME paddings (an odd side's odd pixel after)
    and max-pools (an odd side's last window of one) included; 64x64 gives Brax's 4x4x32."""
    x = jax.random.normal(jax.random.key(1), (2, size, size, channels))
    params = BraxVisionEncoder().init(jax.random.key(0), x)
    # the same kernels and biases, under Brax's layer names
    names = {"PatchConv_0": "Conv_0", "PatchConv_1": "Conv_1"}
    theirs = {"params": {names[k]: v for k, v in params["params"].items()}}
    ours = BraxVisionEncoder().apply(params, x)
    np.testing.assert_allclose(ours, BraxCNN().apply(theirs, x), rtol=1e-5, atol=1e-5)
    if size == 64:
        assert ours.shape == (2, 512)
    # in bfloat16: float32 features within bfloat16's 8 bits of mantissa of the float32 ones
    half = BraxVisionEncoder(jnp.bfloat16).apply(params, x)
    assert half.dtype == jnp.float32
    assert float(jnp.abs(half - ours).max()) <= 0.05 * float(jnp.abs(ours).max())
    try:  # and Brax's own module, where brax is installed (the playground extra)
        from brax.training import networks as brax_networks
    except ImportError:
        return
    cnn = brax_networks.CNN(
        num_filters=(16, 32), kernel_sizes=((5, 5), (3, 3)), strides=((2, 2), (2, 2)),
        activation=nn.elu, max_pool=True, padding="SAME",
    )  # fmt: skip
    brax_out = cnn.apply(theirs, x).reshape(2, -1)
    np.testing.assert_allclose(ours, brax_out, rtol=1e-5, atol=1e-5)


def test_scale_pixels_maps_to_minus_one_one():
    np.testing.assert_allclose(scale_pixels(jnp.array([0, 255], jnp.uint8)), [-1.0, 1.0])


OBS = {
    "pixels": jax.random.randint(jax.random.key(2), (4, 64, 64, 3), 0, 256).astype(jnp.uint8),
    "hint": jax.random.normal(jax.random.key(3), (4, 2)),
    "state": jax.random.normal(jax.random.key(4), (4, 3)),
}


class Features(nn.Module):
    """Just the conditioned features z' of a pixel agent."""

    scheme: str

    @nn.compact
    def __call__(self, obs):
        cond = SCHEMES[self.scheme](64, name="conditioning")
        return cond(Encoder(name="encoder"), scale_pixels(obs["pixels"]), obs["hint"])


@pytest.mark.parametrize(
    "scheme,width", [("lc", 1024 + 64), ("ac", 1024), ("fc", 1024), ("mc", 1024)]
)
def test_scheme_feature_width_and_dependence_on_the_hint(scheme, width):
    net = Features(scheme)
    params = net.init(jax.random.key(0), OBS)
    z = net.apply(params, OBS)
    assert z.shape == (4, width)
    other = net.apply(params, {**OBS, "hint": OBS["hint"] + 1.0})
    assert float(jnp.abs(z - other).max()) > 1e-4  # the hint changes the features
    if scheme == "mc":  # d extra constant input channels, one per hint entry
        assert params["params"]["encoder"]["PatchConv_0"]["kernel"].shape == (8, 8, 3 + 2, 32)


def test_film_with_a_zero_embedding_passes_the_latent_through():
    net = Features("fc")
    params = net.init(jax.random.key(0), OBS)
    zero_out = jax.tree_util.tree_map_with_path(
        lambda path, p: jnp.zeros_like(p)
        if "conditioning" in str(path) and "Dense_1" in str(path)
        else p,
        params,
    )
    assert not np.allclose(net.apply(params, OBS), net.apply(zero_out, OBS))  # the zeroing bites
    film = net.apply(zero_out, OBS)
    plain = Encoder().apply({"params": params["params"]["encoder"]}, scale_pixels(OBS["pixels"]))
    np.testing.assert_allclose(film, plain, rtol=1e-6, atol=1e-6)


@pytest.mark.parametrize("agent", list(AGENTS))
def test_each_agent_reads_only_its_inputs(agent):
    spec = AGENTS[agent]
    net = ActorCritic(spec, "fc", 2)
    obs = {k: OBS[k] for k in spec.observe}
    params = net.init(jax.random.key(0), obs)
    mean, log_std, value = net.apply(params, obs)
    assert mean.shape == (4, 2) and log_std.shape == (2,) and value.shape == (4,)
    assert ("encoder" in params["params"]) == spec.pixels
    labels = lr_labels(params)["params"]
    assert labels["actor"]["Dense_0"]["kernel"] == "actor" and labels["log_std"] == "actor"
    assert labels["critic"]["Dense_0"]["kernel"] == "critic"
    if spec.pixels:
        assert labels["encoder"]["PatchConv_0"]["kernel"] == "encoder"


def test_a_critic_that_does_not_train_the_encoder_leaves_the_shared_features_to_the_actor():
    """critic_trains_encoder=False (ppo.critic_trains_encoder): the same outputs, but the value's
    gradient reaches the critic's MLP alone, none of the encoder or the conditioning it shares
    with the actor; the actor's gradient still reaches them."""
    spec = AGENTS["hints"]
    obs = {k: OBS[k] for k in spec.observe}
    shared, own = (
        ActorCritic(spec, "fc", 2),
        ActorCritic(spec, "fc", 2, critic_trains_encoder=False),
    )
    params = shared.init(jax.random.key(0), obs)
    for a, b in zip(shared.apply(params, obs), own.apply(params, obs)):
        np.testing.assert_array_equal(a, b)

    def grads(net, output):
        return jax.grad(lambda p: net.apply(p, obs)[output].sum())(params)["params"]

    nonzero = lambda tree: any(bool(np.any(x)) for x in jax.tree.leaves(tree))  # noqa: E731
    for part in ("encoder", "conditioning"):
        assert nonzero(grads(shared, 2)[part]) and not nonzero(grads(own, 2)[part]), part
        assert nonzero(grads(own, 0)[part]), part  # the policy still trains them
    jax.tree.map(np.testing.assert_array_equal, grads(own, 2)["critic"], grads(shared, 2)["critic"])


@pytest.mark.parametrize("agent", ["hints", "ppo_rgb", "asym_ac"])
def test_a_critic_with_its_own_encoder_and_the_actor_train_apart(agent):
    """critic_encoder="own" (ppo.critic_encoder): the critic reads an encoder (and, for a
    conditioned agent, a conditioning) of its own, at the encoders' learning rate. The value's
    gradient reaches those and none of the actor's; the action's gradient reaches the actor's and
    none of the critic's. The actor's outputs are the shared network's given the same actor's
    parameters; the value is the critic's own encoder's (its parameters swapped for the actor's
    encoder's, it is the shared network's value)."""
    spec = AGENTS[agent]
    obs = {k: OBS[k] for k in spec.observe}
    net, shared = ActorCritic(spec, "fc", 2, critic_encoder="own"), ActorCritic(spec, "fc", 2)
    params = net.init(jax.random.key(0), obs)["params"]
    mine = [p for p in ("encoder", "conditioning") if p in params]
    assert mine == (["encoder", "conditioning"] if spec.conditioned else ["encoder"])
    theirs = [f"critic_{p}" for p in mine]
    assert set(theirs) <= set(params)
    labels = lr_labels({"params": params})["params"]
    assert all(set(jax.tree.leaves(labels[p])) == {"critic_encoder"} for p in theirs)

    def grads(output):
        return jax.grad(lambda p: net.apply({"params": p}, obs)[output].sum())(params)

    nonzero = lambda tree: any(bool(np.any(x)) for x in jax.tree.leaves(tree))  # noqa: E731
    value, action = grads(2), grads(0)
    for a, c in zip(mine, theirs):
        assert nonzero(value[c]) and not nonzero(value[a]), a
        assert nonzero(action[a]) and not nonzero(action[c]), a
    as_shared = {k: v for k, v in params.items() if k not in theirs}
    out, ref = net.apply({"params": params}, obs), shared.apply({"params": as_shared}, obs)
    np.testing.assert_array_equal(out[0], ref[0])
    np.testing.assert_array_equal(out[1], ref[1])
    assert not np.allclose(out[2], ref[2])  # the critic's own encoder is another draw
    swapped = {**params, **{c: params[a] for a, c in zip(mine, theirs)}}
    np.testing.assert_allclose(net.apply({"params": swapped}, obs)[2], ref[2], rtol=1e-6)


def test_a_log_std_floor_holds_the_std_up_and_leaves_it_alone_above():
    """min_log_std (ppo.min_log_std): a log std below the floor is the floor, and its gradient is 0
    there; one above is as learnt. Without a floor nothing changes."""
    spec = AGENTS["ppo_state"]
    obs = {"state": OBS["state"]}
    free, floored = (
        ActorCritic(spec, "fc", 2, hidden=(8,)),
        ActorCritic(spec, "fc", 2, hidden=(8,), min_log_std=-1.0),
    )
    params = free.init(jax.random.key(0), obs)
    params = {**params, "params": {**params["params"], "log_std": jnp.array([-3.0, 0.5])}}
    np.testing.assert_array_equal(free.apply(params, obs)[1], [-3.0, 0.5])
    np.testing.assert_array_equal(floored.apply(params, obs)[1], [-1.0, 0.5])
    grad = jax.grad(lambda p: floored.apply(p, obs)[1].sum())(params)["params"]["log_std"]
    np.testing.assert_array_equal(grad, [0.0, 1.0])


@pytest.mark.parametrize("agent", ["hints", "ppo_rgb"])
def test_pixel_scale_sets_the_range_the_encoder_sees(agent):
    """ppo.pixel_scale: bytes 0 and 255 enter the encoder as -s and s (Playground's vision tasks'
    grey in [-0.5, 0.5] is s = 0.5), and the network's features are the encoder's (conditioned
    for HINTS) of those values; s = 1 is the range as it was."""
    bytes_ = jnp.array([0, 255], jnp.uint8)
    np.testing.assert_allclose(scale_pixels(bytes_, 0.5), [-0.5, 0.5])
    np.testing.assert_allclose(scale_pixels(bytes_), [-1.0, 1.0])
    spec = AGENTS[agent]
    obs = {k: OBS[k] for k in spec.observe}
    half, whole = ActorCritic(spec, "fc", 2, pixel_scale=0.5), ActorCritic(spec, "fc", 2)
    params = whole.init(jax.random.key(0), obs)
    seen = {}

    def encoder_input(module, *args):  # record what the encoder is called with
        if isinstance(module, Encoder):
            seen.setdefault(module.scope.path, args[0])
        return None

    with nn.intercept_methods(
        lambda f, args, kwargs, ctx: encoder_input(ctx.module, *args) or f(*args, **kwargs)
    ):
        half.apply(params, obs)
    (x,) = seen.values()
    np.testing.assert_allclose(x, scale_pixels(obs["pixels"]) * 0.5, rtol=1e-6)
    assert not np.allclose(half.apply(params, obs)[2], whole.apply(params, obs)[2])


def test_swish_mlps_and_a_softplus_std_head_compute_brax_s_policy():
    """ppo.activation=swish and ppo.std_head=softplus, by hand from the parameters: the actor's
    hidden layer is swish(x W0 + b0) and its 2A outputs are the mean and the raw std, std =
    softplus(raw) + 0.001 a row (so the log std is [B, A] and there is no log_std parameter); the
    critic's hidden layer is swish too. Near init the std is near softplus(0) = 0.69 (Brax's)."""
    spec = AGENTS["ppo_state"]
    obs = {"state": OBS["state"]}
    net = ActorCritic(spec, "fc", 2, hidden=(8,), activation="swish", std_head="softplus")
    params = net.init(jax.random.key(0), obs)
    p = params["params"]
    assert "log_std" not in p and p["actor"]["Dense_1"]["kernel"].shape == (8, 4)

    def mlp(q, x):
        h = jax.nn.swish(x @ q["Dense_0"]["kernel"] + q["Dense_0"]["bias"])
        return h @ q["Dense_1"]["kernel"] + q["Dense_1"]["bias"]

    mean, log_std, value = net.apply(params, obs)
    out = mlp(p["actor"], obs["state"])
    np.testing.assert_allclose(mean, out[:, :2], rtol=1e-5, atol=1e-6)
    np.testing.assert_allclose(
        log_std, np.log(jax.nn.softplus(out[:, 2:]) + 0.001), rtol=1e-5, atol=1e-6
    )
    np.testing.assert_allclose(value, mlp(p["critic"], obs["state"])[:, 0], rtol=1e-5, atol=1e-6)
    assert log_std.shape == (4, 2) and np.all(np.abs(np.exp(log_std) - 0.694) < 0.05)
    # the same parameters under ReLU give other values: the network reads the setting
    relu = ActorCritic(spec, "fc", 2, hidden=(8,), std_head="softplus")
    assert not np.allclose(relu.apply(params, obs)[2], value)


@pytest.mark.parametrize("shape", [(3, 8, 8, 4), (2, 5, 7, 3), (2, 1, 4, 6, 2)])
def test_max_pool_2x2_equals_nn_max_pool_in_values_and_gradients_ties_included(shape):
    """max_pool_2x2 (BraxVisionEncoder's pool, elementwise ops) is nn.max_pool's 2x2/2 SAME pool:
    the same values, and the same gradient, all of it to each window's first maximum, where a
    third of the inputs tie (a flat patch of picture) and on odd sides (SAME's short windows)."""
    from hintsjax.models.networks import max_pool_2x2

    x = jax.random.normal(jax.random.key(0), shape)
    x = jnp.where(jax.random.uniform(jax.random.key(1), shape) < 0.33, 0.25, x)
    ref = lambda v: nn.max_pool(v, (2, 2), strides=(2, 2), padding="SAME")  # noqa: E731
    np.testing.assert_array_equal(max_pool_2x2(x), ref(x))
    g = jax.random.normal(jax.random.key(2), ref(x).shape)
    grads = [jax.grad(lambda v, f=f: (f(v) * g).sum())(x) for f in (max_pool_2x2, ref)]
    np.testing.assert_array_equal(*grads)
