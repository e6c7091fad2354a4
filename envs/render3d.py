"""A pure-JAX ray caster for MJX scenes: pixels for thousands of envs at once, in the graph.

One primary ray per pixel from a pinhole camera, analytic hits on MuJoCo's primitive geoms, the
nearest kept; no OpenGL, no host round trip, so `render` jits and vmaps with the physics.

Built for throughput on a GPU. The work is in the camera frame, so ray directions are iota
arithmetic; each geom's distance is a closed form over all pixels, unrolled over the geoms at
trace time, and the nearest hit and its geom travel as one int32 key, so XLA makes the search
one kernel with no [pixels, geoms] array in memory. Only each pixel's winner then gets a
normal, from the hit point in that geom's frame. Vectors are tuples of three arrays: [..., 3]
arrays, with their stacks and slices, split XLA's fusions.

More of what it owns and why: docs/design.md, "Module notes", envs/render3d.py.
"""

from __future__ import annotations

import math
from functools import partial
from typing import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

# mjtGeom values; heightfields, meshes and SDFs are not drawn.
PLANE, HFIELD, SPHERE, CAPSULE, ELLIPSOID, CYLINDER, BOX, MESH, SDF = range(9)
SUPPORTED = {
    PLANE: "plane",
    SPHERE: "sphere",
    CAPSULE: "capsule",
    ELLIPSOID: "ellipsoid",
    CYLINDER: "cylinder",
    BOX: "box",
}
_UNSUPPORTED = {HFIELD: "hfield", MESH: "mesh", SDF: "sdf"}
_DEFAULT_RGBA = (0.5, 0.5, 0.5, 1.0)  # MJCF's geom rgba when none is given: the material's shows
_DARK_SQUARE = 0.6  # the checker's second tone, as a fraction of the plane's colour
SKY = (0.6, 0.7, 0.85)  # the default background


def _static(**kwargs):
    return struct.field(pytree_node=False, **kwargs)


@struct.dataclass
class Camera:
    """Pinhole camera: `pos` float32[3] in the world; `xmat` float32[3, 3] laid out as MuJoCo's
    cam_xmat, its columns the camera's right, up and backward axes in world coordinates (it looks
    along minus the third column); `fovy` the vertical field of view in degrees."""

    pos: jax.Array
    xmat: jax.Array
    fovy: float = _static(default=45.0)


@struct.dataclass
class Hits:
    """Per pixel of an [S, S] image: `distance` along the unit ray to the nearest surface (inf
    where none), its `geom` id (int32, -1 where none), the unit outward `normal` [S, S, 3] in
    world coordinates and the hit point `local` [S, S, 3] in that geom's frame (0 where none)."""

    distance: jax.Array
    geom: jax.Array
    normal: jax.Array
    local: jax.Array


@struct.dataclass
class Scene:
    """What is drawn and how, fixed at trace time (no leaves: jit may take it as an argument):
    the drawn geoms' ids sorted by type, their types, sizes and RGB colours; the floor square
    (m), the direction the light travels (unit, world), the ambient, diffuse and headlight
    weights, the background RGB and the fog distance (m; 0 for none). Made by `make_scene`."""

    geom: tuple[int, ...] = _static()
    type: tuple[int, ...] = _static()
    size: tuple[tuple[float, float, float], ...] = _static()
    rgb: tuple[tuple[float, float, float], ...] = _static()
    checker: float = _static()
    light_dir: tuple[float, float, float] = _static()
    ambient: float = _static()
    diffuse: float = _static()
    headlight: float = _static()
    background: tuple[float, float, float] = _static()
    fog: float = _static()


def make_scene(
    mj_model,
    *,
    groups: Sequence[int] = (0, 1, 2),
    checker: float = 1.0,
    light_dir: Sequence[float] = (-0.3, 0.5, -1.0),
    ambient: float = 0.35,
    diffuse: float = 0.55,
    headlight: float = 0.2,
    background: Sequence[float] = SKY,
    fog: float = 0.0,
) -> Scene:
    """The Scene of `mj_model`'s geoms in `groups` whose alpha is not 0; a ValueError names any
    such geom of a type other than plane, sphere, capsule, ellipsoid, cylinder and box."""
    floats = lambda v: tuple(float(x) for x in v)  # noqa: E731
    drawn = []
    for g in range(mj_model.ngeom):
        rgba = floats(mj_model.geom_rgba[g])
        if mj_model.geom_matid[g] >= 0 and rgba == _DEFAULT_RGBA:
            rgba = floats(mj_model.mat_rgba[mj_model.geom_matid[g]])
        if rgba[3] == 0 or int(mj_model.geom_group[g]) not in groups:
            continue
        kind = int(mj_model.geom_type[g])
        if kind not in SUPPORTED:
            raise ValueError(
                f"geom {g} '{mj_model.geom(g).name}' is a {_UNSUPPORTED.get(kind, kind)}; "
                f"render3d draws only {', '.join(SUPPORTED.values())} (hide it with its group or "
                "rgba alpha 0)"
            )
        drawn.append((kind, g, floats(mj_model.geom_size[g]), rgba[:3]))
    kinds, ids, sizes, rgbs = zip(*sorted(drawn)) if drawn else ((), (), (), ())
    light = floats(np.asarray(light_dir) / np.linalg.norm(light_dir))
    return Scene(
        ids,
        kinds,
        sizes,
        rgbs,
        float(checker),
        light,
        float(ambient),
        float(diffuse),
        float(headlight),
        floats(background),
        float(fog),
    )


def look_at(eye, target, up=(0.0, 0.0, 1.0), fovy: float = 45.0) -> Camera:
    """Camera at eye[3] looking at target[3], `up` (not along the view) pointing up the image."""
    eye, target, up = (jnp.asarray(v, jnp.float32) for v in (eye, target, up))
    back = (eye - target) / jnp.linalg.norm(eye - target)
    right = jnp.cross(up, back) / jnp.linalg.norm(jnp.cross(up, back))
    return Camera(eye, jnp.stack([right, jnp.cross(back, right), back], axis=1), fovy)


def tracking_camera(
    target, distance: float, elevation_deg: float, azimuth_deg: float, fovy: float = 45.0
) -> Camera:
    """MuJoCo's free camera orbiting target[3]: it looks along (cos el cos az, cos el sin az,
    sin el) from `distance` away, so elevation -20 looks down and azimuth 90 looks along +y."""
    el, az = jnp.deg2rad(jnp.float32(elevation_deg)), jnp.deg2rad(jnp.float32(azimuth_deg))
    forward = jnp.stack([jnp.cos(el) * jnp.cos(az), jnp.cos(el) * jnp.sin(az), jnp.sin(el)])
    up = jnp.stack([-jnp.sin(el) * jnp.cos(az), -jnp.sin(el) * jnp.sin(az), jnp.cos(el)])
    pos = jnp.asarray(target, jnp.float32) - distance * forward
    return Camera(pos, jnp.stack([jnp.cross(forward, up), up, -forward], axis=1), fovy)


Vec = tuple  # (x, y, z): three arrays of one shape, or scalars; a frame is the Vec of its axes


def _vec(a: jax.Array) -> Vec:
    return a[..., 0], a[..., 1], a[..., 2]


def _dot(a: Vec, b: Vec) -> jax.Array:
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _cross(a: Vec, b: Vec) -> Vec:
    return a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]


def _out_of(frame: Vec, v: Vec) -> Vec:
    """The vector whose coordinates in the frame with axes `frame` are v."""
    return tuple(sum(frame[j][i] * v[j] for j in range(3)) for i in range(3))


def _unit(v: Vec) -> Vec:
    s = jax.lax.rsqrt(_dot(v, v))
    return tuple(c * s for c in v)


def _sqrt(h: jax.Array) -> jax.Array:
    """sqrt(max(h, 0)) as h rsqrt(h): one fast instruction on GPUs, against IEEE sqrt's several."""
    h = jnp.maximum(h, 1e-30)
    return h * jax.lax.rsqrt(h)


def _rays(size: int, fovy: float) -> Vec:
    """Unit rays (three float32[S*S]) in the camera frame through the pixel centres, row-major
    from the top-left pixel."""
    half = math.tan(math.radians(fovy) / 2)
    c = (jnp.arange(size, dtype=jnp.float32) + 0.5) * (2 * half / size) - half
    return _unit((jnp.tile(c, size), -jnp.repeat(c, size), -jnp.ones(size * size, jnp.float32)))


def _near_root(b: jax.Array, c, h: jax.Array) -> jax.Array:
    """The smaller root c / (b + sqrt h) of a t^2 - 2 b t + c = 0 given h = b^2 - a c (inf if
    h < 0): exact for rays along a cylinder's axis (a -> 0); <= 0 behind or inside."""
    return jnp.where(h >= 0, c / (b + _sqrt(h)), jnp.inf)


def _distance(kind: int, d: Vec, c: Vec, frame: Vec, size: Sequence) -> jax.Array:
    """[P] ray length from the camera (the origin) along unit rays d to one geom with centre c,
    axes `frame` and MuJoCo size `size`; inf for a miss. Discriminants come from perpendicular
    distances, as b^2 - a c loses float32's digits at silhouettes."""
    if kind == PLANE:
        dn = _dot(d, frame[2])
        t = _dot(c, frame[2]) / dn
        ok = dn < 0
        for i in range(2):  # MuJoCo draws planes within size[0:2] where those are > 0
            ok &= (size[i] <= 0) | (jnp.abs(t * _dot(d, frame[i]) - _dot(c, frame[i])) <= size[i])
        t = jnp.where(ok, t, jnp.inf)
    elif kind == SPHERE:
        b = _dot(d, c)
        miss = tuple(c[i] - b * d[i] for i in range(3))  # centre to the ray's nearest point
        h = size[0] ** 2 - _dot(miss, miss)
        t = jnp.where(h >= 0, b - _sqrt(h), jnp.inf)
    elif kind in (CAPSULE, CYLINDER):
        # The infinite cylinder first, then the end (sphere or disc) on the side the hit fell.
        u, r, hl = frame[2], size[0], size[1]
        du, cu = _dot(d, u), _dot(c, u)
        across = tuple(c[i] - cu * u[i] for i in range(3))  # the centre's offset across the axis
        a, b = jnp.maximum(1.0 - du * du, 1e-12), _dot(d, across)
        h = a * r * r - _dot(d, _cross(c, u)) ** 2
        t = _near_root(b, _dot(across, across) - r * r, h)
        axial = t * du - cu  # along the axis from the centre
        end = jnp.where(axial > 0, hl, -hl)
        if kind == CAPSULE:
            centre = tuple(c[i] + end * u[i] for i in range(3))
            b_end = _dot(d, centre)
            miss = tuple(centre[i] - b_end * d[i] for i in range(3))
            h_end = r * r - _dot(miss, miss)
            t_end = jnp.where(h_end >= 0, b_end - _sqrt(h_end), jnp.inf)
        else:
            t_end = (end + cu) / du
            t_end = jnp.where(jnp.abs(a * t_end - b) <= _sqrt(h), t_end, jnp.inf)
        t = jnp.where(h < 0, jnp.inf, jnp.where(jnp.abs(axial) <= hl, t, t_end))
    elif kind == ELLIPSOID:  # a unit sphere in coordinates scaled by 1/size along the axes
        ds = tuple(_dot(frame[i], d) / size[i] for i in range(3))
        cs = tuple(_dot(frame[i], c) / size[i] for i in range(3))
        cross = _cross(ds, cs)
        t = _near_root(_dot(ds, cs), _dot(cs, cs) - 1.0, _dot(ds, ds) - _dot(cross, cross))
    else:  # box: the slabs' intervals; a ray along a face gets a huge but finite one
        near, far = -jnp.inf, jnp.inf
        for i in range(3):
            v = _dot(d, frame[i])
            inv = 1.0 / jnp.where(jnp.abs(v) < 1e-12, 1e-12, v)
            mid, half = _dot(c, frame[i]) * inv, size[i] * jnp.abs(inv)
            near, far = jnp.maximum(near, mid - half), jnp.minimum(far, mid + half)
        t = jnp.where(near <= far, near, jnp.inf)
    return jnp.where(t > 0, t, jnp.inf)


def _local_normal(kind: int, p: Vec, size: Vec) -> Vec:
    """Outward normal (not unit) at points p on geoms of one type, in the geoms' frames."""
    x, y, z = p
    zero = jnp.zeros_like(x)
    if kind == PLANE:
        return zero, zero, jnp.ones_like(x)
    if kind == SPHERE:
        return p
    if kind == CAPSULE:
        return x, y, z - jnp.clip(z, -size[1], size[1])
    if kind == ELLIPSOID:
        return tuple(p[i] / size[i] ** 2 for i in range(3))
    if kind == CYLINDER:
        cap = jnp.abs(z) - size[1] > jnp.sqrt(x * x + y * y) - size[0]
        return jnp.where(cap, zero, x), jnp.where(cap, zero, y), jnp.where(cap, jnp.sign(z), zero)
    gap = [jnp.abs(p[i]) - size[i] for i in range(3)]  # box: the face nearest the point
    fx = (gap[0] >= gap[1]) & (gap[0] >= gap[2])
    fy = ~fx & (gap[1] >= gap[2])
    return (
        jnp.where(fx, jnp.sign(x), zero),
        jnp.where(fy, jnp.sign(y), zero),
        jnp.where(fx | fy, zero, jnp.sign(z)),
    )


def _low_bits(scene: Scene) -> int:
    """Mask of the key's low bits, which hold the geom's index; the distance keeps the others
    (relative error under 2e-6 for up to 16 geoms)."""
    return (1 << max(1, math.ceil(math.log2(len(scene.geom))))) - 1


def _nearest(scene: Scene, rays: Vec, centre: jax.Array, rot: jax.Array) -> jax.Array:
    """int32[P] key of each pixel's nearest hit: the distance's bits (positive floats order as
    their bits do) with its geom's index in the scene in the low bits, so one min chain finds
    both. On GPUs the chain is unrolled over the geoms, which XLA makes one kernel; XLA on CPU
    would copy that kernel into each consumer, so there it is a scan with a switch on the type."""
    low = _low_bits(scene)
    pack = lambda t, g: (jax.lax.bitcast_convert_type(t, jnp.int32) & ~low) | g  # noqa: E731
    start = jnp.full(rays[0].shape, np.iinfo(np.int32).max, jnp.int32)

    def unrolled():
        key = start
        for g, (kind, size) in enumerate(zip(scene.type, scene.size)):
            key = jnp.minimum(
                key, pack(_distance(kind, rays, _vec(centre[g]), tuple(map(_vec, rot[g])), size), g)
            )
        return jax.lax.optimization_barrier(key)  # made once, not inside each consumer

    def scanned():
        kinds = sorted(set(scene.type))

        def step(key, geom):
            g, branch, c, axes, size = geom
            fns = [partial(_distance, k, rays) for k in kinds]
            t = jax.lax.switch(branch, fns, _vec(c), tuple(map(_vec, axes)), _vec(size))
            return jnp.minimum(key, pack(t, g)), None

        g = jnp.arange(len(scene.geom), dtype=jnp.int32)
        branch = jnp.asarray([kinds.index(kind) for kind in scene.type], jnp.int32)
        return jax.lax.scan(
            step, start, (g, branch, centre, rot, jnp.asarray(scene.size, jnp.float32))
        )[0]

    return jax.lax.platform_dependent(cpu=scanned, default=unrolled)


def _cast(scene: Scene, geom_xpos: jax.Array, geom_xmat: jax.Array, camera: Camera, size: int):
    """In the camera frame, per pixel (arrays [P = S*S]): rays, distance, index into the scene's
    geoms (-1 where none), unit normal, hit point in the geom's frame (0 where none), and the
    geom's (type, r, g, b)."""
    rays = _rays(size, camera.fovy)
    zero = jnp.zeros_like(rays[0])
    if not scene.geom:
        return (
            rays,
            zero + jnp.inf,
            zero.astype(jnp.int32) - 1,
            (zero,) * 3,
            (zero,) * 3,
            (zero,) * 4,
        )
    exact = jax.lax.Precision.HIGHEST  # GPUs would multiply float32 matrices in TF32
    ids = np.asarray(scene.geom)
    centre = jnp.einsum("gj,ji->gi", geom_xpos[ids] - camera.pos, camera.xmat, precision=exact)
    # [G, axis, coordinate]
    rot = jnp.einsum("ji,gjk->gki", camera.xmat, geom_xmat[ids], precision=exact)
    key, low = _nearest(scene, rays, centre, rot), _low_bits(scene)
    hit = key < 0x7F800000  # the bits of inf
    index = jnp.where(hit, key & low, -1)
    distance = jnp.where(hit, jax.lax.bitcast_convert_type(key & ~low, jnp.float32), jnp.inf)
    # The winner's centre, axes, size, type and colour, one gather per column: XLA on GPUs fuses
    # those into their consumers, but writes out the columns of a single gather of whole rows.
    static = np.concatenate(
        [np.asarray(scene.size), np.asarray(scene.type)[:, None], np.asarray(scene.rgb)], 1
    )
    table = jnp.concatenate([centre, rot.reshape(-1, 9), jnp.asarray(static, jnp.float32)], 1)
    w = [column[jnp.maximum(index, 0)] for column in table.T]
    frame = (tuple(w[3:6]), tuple(w[6:9]), tuple(w[9:12]))
    local = tuple(
        _dot(axis, tuple(jnp.where(hit, distance, 0) * rays[i] - w[i] for i in range(3)))
        for axis in frame
    )
    normal = (zero,) * 3
    for kind in sorted(set(scene.type)):
        normal = tuple(
            jnp.where(w[15] == kind, n, m)
            for n, m in zip(_local_normal(kind, local, w[12:15]), normal)
        )
    normal = tuple(jnp.where(hit, n, 0.0) for n in _unit(_out_of(frame, normal)))
    return rays, distance, index, normal, tuple(jnp.where(hit, v, 0.0) for v in local), w[15:19]


def cast(
    scene: Scene, geom_xpos: jax.Array, geom_xmat: jax.Array, camera: Camera, size: int
) -> Hits:
    """Hits of an [S, S] image (row 0 the top) of the geoms at geom_xpos[ngeom, 3],
    geom_xmat[ngeom, 3, 3] (as mjx.Data holds them) seen by `camera`."""
    _, distance, index, normal, local, _ = _cast(scene, geom_xpos, geom_xmat, camera, size)
    geom = jnp.asarray(scene.geom + (-1,), jnp.int32)[index]
    image = lambda v: jnp.stack(v, -1).reshape(size, size, 3)  # noqa: E731
    world = _out_of(_vec(camera.xmat), normal)  # the camera's axes are the columns of xmat
    return Hits(distance.reshape(size, size), geom.reshape(size, size), image(world), image(local))


def depth(
    scene: Scene, geom_xpos: jax.Array, geom_xmat: jax.Array, camera: Camera, size: int
) -> jax.Array:
    """float32[S, S] distance along each unit ray to the nearest surface, inf where none."""
    return cast(scene, geom_xpos, geom_xmat, camera, size).distance


def render(
    scene: Scene, geom_xpos: jax.Array, geom_xmat: jax.Array, camera: Camera, size: int = 64
) -> jax.Array:
    """uint8[S, S, 3] picture (row 0 the top) of the geoms at geom_xpos[ngeom, 3],
    geom_xmat[ngeom, 3, 3] seen by `camera`."""
    rays, distance, index, normal, local, (kind, *rgb) = _cast(
        scene, geom_xpos, geom_xmat, camera, size
    )
    light = tuple(_dot(axis, scene.light_dir) for axis in _vec(camera.xmat))  # in the camera frame
    facing = jnp.maximum(-_dot(normal, rays), 0.0)
    shade = (
        scene.ambient
        + scene.diffuse * jnp.maximum(-_dot(normal, light), 0.0)
        + scene.headlight * facing
    )
    # Planes are checkered; the squares fade to their mean where a pixel would span most of one.
    square = jnp.floor(local[0] / scene.checker) + jnp.floor(local[1] / scene.checker)
    footprint = (
        distance * (2 * math.tan(math.radians(camera.fovy) / 2) / size) / jnp.maximum(facing, 0.05)
    )
    contrast = jnp.clip(1.5 - 2.0 * footprint / scene.checker, 0.0, 1.0) * (1 - _DARK_SQUARE) / 2
    tone = 1.0 - (1 - _DARK_SQUARE) / 2 + jnp.where(jnp.mod(square, 2) == 0, contrast, -contrast)
    tone = jnp.where(kind == PLANE, tone, 1.0)
    fade = jnp.exp(-distance / scene.fog) if scene.fog > 0 else 1.0
    colour = [
        jnp.where(index >= 0, bg + fade * (c * tone * shade - bg), bg)
        for c, bg in zip(rgb, scene.background)
    ]
    # The three bytes packed in one uint32 once per pixel: XLA on GPUs would otherwise redo the
    # shading for each channel of the uint8[S, S, 3] it writes.
    rgb8 = [jnp.round(jnp.clip(c, 0.0, 1.0) * 255.0).astype(jnp.uint32) for c in colour]
    packed = jax.lax.optimization_barrier(rgb8[0] | rgb8[1] << 8 | rgb8[2] << 16)
    return (
        jnp.stack([packed >> (8 * i) & 255 for i in range(3)], -1)
        .astype(jnp.uint8)
        .reshape(size, size, 3)
    )
