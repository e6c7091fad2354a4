"""render3d: depth parity with MuJoCo's ray casters (MJX's and C's), a sphere where pinhole maths
puts it, vmap against a loop, the checkered floor and the lighting worked out by hand, bad models
refused, MuJoCo's free-camera convention, and pictures of Gymnasium's ant, humanoid and cheetah.

Geom poses come from MuJoCo C's mj_forward (or mj_kinematics), put into an mjx.Data with
mjx.put_data where MJX needs one: mjx.forward computes the same geom_xpos and geom_xmat but
takes 5-20 s to compile on CPU, which this file's budget of seconds does not allow.
"""

from __future__ import annotations

import contextlib
import io
import math
import os

import gymnasium
import jax
import jax.numpy as jnp
import mujoco
import numpy as np
import pytest

with contextlib.redirect_stdout(io.StringIO()):  # mjx prints a notice when warp is absent
    from mujoco import mjx

from hintsjax.envs import render3d
from hintsjax.envs.render3d import look_at, make_scene, tracking_camera

GYM_ASSETS = os.path.join(os.path.dirname(gymnasium.__file__), "envs", "mujoco", "assets")
BACKGROUND = np.round(np.asarray(render3d.SKY) * 255).astype(np.uint8)

# One of each supported type at a non-trivial pose, each on a free joint (for the vmap test);
# the cylinder in group 1 (for the group test); an invisible sphere and a box in the hidden
# group 3, which must not be drawn; nothing collides, to keep MJX cheap.
MJCF = """
<mujoco>
  <default><geom contype="0" conaffinity="0"/></default>
  <asset><material name="blue" rgba="0.2 0.3 0.9 1"/></asset>
  <worldbody>
    <geom name="floor" type="plane" size="4 4 0.1" rgba="0.8 0.8 0.8 1"/>
    <body name="ball" pos="0.6 -0.7 0.6"><freejoint/>
      <geom name="ball" type="sphere" size="0.4" rgba="1 0 0 1"/></body>
    <body name="pill" pos="-0.9 0.2 0.7" quat="0.9 0.3 -0.2 0.25"><freejoint/>
      <geom name="pill" type="capsule" size="0.2 0.5" rgba="0 1 0 1"/></body>
    <body name="egg" pos="1.3 0.9 0.6" quat="0.8 -0.2 0.5 0.3"><freejoint/>
      <geom name="egg" type="ellipsoid" size="0.5 0.3 0.2" material="blue"/></body>
    <body name="can" pos="-0.3 1.3 0.5" quat="0.7 0.6 0.2 -0.3"><freejoint/>
      <geom name="can" type="cylinder" size="0.3 0.35" group="1" rgba="1 1 0 1"/></body>
    <body name="crate" pos="0.2 0.3 0.45" quat="0.85 0.1 0.3 0.4"><freejoint/>
      <geom name="crate" type="box" size="0.3 0.2 0.25" rgba="0 1 1 1"/></body>
    <geom name="ghost" type="sphere" size="0.5" pos="-1.5 -1.5 0.6" rgba="1 1 1 0"/>
    <geom name="hidden" type="box" size="0.4 0.4 0.4" pos="1.5 -1.5 0.5" group="3"/>
  </worldbody>
</mujoco>
"""
CAMERA = dict(eye=(-2.0, -3.0, 2.2), target=(0.2, 0.3, 0.5))


@pytest.fixture(scope="module")
def render():
    return jax.jit(render3d.render, static_argnames="size")


@pytest.fixture(scope="module")
def cast():
    return jax.jit(render3d.cast, static_argnames="size")


@pytest.fixture(scope="module")
def world(cast):
    """The test scene after MuJoCo C's mj_forward: MjModel, MjData, mjx.Model, mjx.Data, its
    Scene, and the Hits of the 32x32 view from CAMERA (shared: each compile costs seconds)."""
    m = mujoco.MjModel.from_xml_string(MJCF)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    dx = mjx.put_data(m, d)
    scene = make_scene(m)
    return (
        m,
        d,
        mjx.put_model(m),
        dx,
        scene,
        cast(scene, dx.geom_xpos, dx.geom_xmat, look_at(**CAMERA), size=32),
    )


def pixel_rays(camera: render3d.Camera, size: int) -> np.ndarray:
    """float64[S*S, 3] unit world rays through the pixel centres, row 0 at the top, worked out
    independently of render3d: right u, up v, forward -back through a pinhole of fovy."""
    half = math.tan(math.radians(camera.fovy) / 2)
    c = ((np.arange(size) + 0.5) / size * 2 - 1) * half
    u, v = np.meshgrid(c, -c)
    xmat = np.asarray(camera.xmat, np.float64)
    rays = u[..., None] * xmat[:, 0] + v[..., None] * xmat[:, 1] - xmat[:, 2]
    return (rays / np.linalg.norm(rays, axis=-1, keepdims=True)).reshape(-1, 3)


def test_depth_matches_mjx_ray(world):
    """Every pixel of a 32x32 view against mjx.ray along the same ray. MJX's ray has no
    cylinder, so pixels where ours hits the cylinder are left out (elsewhere the cylinder is
    behind what both hit). Measured (CPU, jax 0.10.2, mujoco 3.17.0): 668 hits; masks and geom
    ids identical; max |d depth| 5.1e-5 m, at two silhouette pixels of the capsule where MJX's
    float32 b^2 - ac loses digits (against MuJoCo C, below, ours is within 4.6e-6 there).
    Tolerances: 5e-4 m; at most 2 silhouette pixels that one hits and the other misses."""
    m, _, mx, dx, _, hits = world
    camera = look_at(**CAMERA)
    dist, geom = jax.jit(
        jax.vmap(lambda v: mjx.ray(mx, dx, camera.pos, v, geomgroup=(1, 0, 1, 0, 0, 0)))
    )(jnp.asarray(pixel_rays(camera, 32), jnp.float32))
    ours, ours_geom = np.asarray(hits.distance).ravel(), np.asarray(hits.geom).ravel()
    theirs, theirs_geom = np.asarray(dist), np.asarray(geom)
    compared = ours_geom != mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "can")
    assert np.sum((np.isfinite(ours) != (theirs >= 0))[compared]) <= 2
    both = compared & np.isfinite(ours) & (theirs >= 0)
    assert both.sum() > 600 and len(set(theirs_geom[both])) == 5  # floor, ball, pill, egg, crate
    print(f"max |d depth| vs mjx.ray: {np.abs(ours[both] - theirs[both]).max():.2g} m")
    np.testing.assert_allclose(ours[both], theirs[both], rtol=0, atol=5e-4)
    assert np.sum(ours_geom[both] != theirs_geom[both]) <= 2


def test_depth_matches_mujoco_c_ray(world):
    """As above through `render3d.depth`, against MuJoCo C's mj_ray (float64, all six types,
    the cylinder included). Measured: max |d depth| 4.6e-6 m; masks and geom ids identical.
    Tolerances: 5e-5 m; at most 2 silhouette pixels differ in hit or geom."""
    m, d, _, dx, scene, _ = world
    camera = look_at(**CAMERA)
    depth = jax.jit(render3d.depth, static_argnames="size")
    ours = np.asarray(depth(scene, dx.geom_xpos, dx.geom_xmat, camera, size=32))
    ours_geom = np.asarray(world[5].geom).ravel()
    theirs, theirs_geom, geomid = np.zeros(32 * 32), np.zeros(32 * 32, int), np.zeros(1, np.int32)
    for i, ray in enumerate(pixel_rays(camera, 32)):
        groups = np.array([1, 1, 1, 0, 0, 0], np.uint8)
        theirs[i] = mujoco.mj_ray(
            m, d, np.asarray(camera.pos, np.float64), ray, groups, 1, -1, geomid
        )
        theirs_geom[i] = geomid[0]
    ours = ours.ravel()
    assert np.sum(np.isfinite(ours) != (theirs >= 0)) <= 2
    both = np.isfinite(ours) & (theirs >= 0)
    assert {m.geom(g).name for g in theirs_geom[both]} == {
        "floor",
        "ball",
        "pill",
        "egg",
        "can",
        "crate",
    }
    print(f"max |d depth| vs mj_ray: {np.abs(ours[both] - theirs[both]).max():.2g} m")
    np.testing.assert_allclose(ours[both], theirs[both], rtol=0, atol=5e-5)
    assert np.sum(ours_geom[both] != theirs_geom[both]) <= 2


def test_normals_are_unit_face_the_camera_and_are_tangent_to_the_surface(world):
    """Normals: unit, facing the ray, and perpendicular to the step between the hit points of
    neighbouring pixels on one geom, taking the mean of their two normals: exact on planes,
    spheres, box faces and a cylinder's side, nearly so elsewhere (pairs across a box edge are
    left out). Measured over 1160 pairs: 90th percentile |cos| 1.2e-5, max 0.098 (a pair across
    the capsule's body and cap, near its silhouette). Tolerances: 1e-3 and 0.2."""
    _, _, _, _, _, hits = world
    dist, geom, normal = np.asarray(hits.distance), np.asarray(hits.geom), np.asarray(hits.normal)
    rays = pixel_rays(look_at(**CAMERA), 32).reshape(32, 32, 3)
    hit = geom >= 0
    np.testing.assert_allclose(np.linalg.norm(normal[hit], axis=-1), 1.0, atol=1e-5)
    assert np.all(np.sum(normal * rays, -1)[hit] < 0)
    point = np.where(hit, dist, 0)[..., None] * rays
    cos = []
    for axis in (0, 1):
        step = np.diff(point, axis=axis)
        mean = np.delete(normal, -1, axis) + np.delete(normal, 0, axis)
        same = (
            np.delete(hit, 0, axis)
            & (np.diff(geom, axis=axis) == 0)
            & (np.linalg.norm(mean, axis=-1) > 1.5)
        )
        step, mean = step[same], mean[same]
        cos.append(
            np.abs(np.sum(step * mean, -1))
            / np.linalg.norm(step, axis=-1)
            / np.linalg.norm(mean, axis=-1)
        )
    cos = np.concatenate(cos)
    print(
        f"|cos| over {cos.size} pairs: 90th percentile {np.percentile(cos, 90):.2g}, max "
        f"{cos.max():.2g}"
    )
    assert cos.size > 1000 and np.percentile(cos, 90) < 1e-3 and cos.max() < 0.2


SPHERES = """
<mujoco>
  <worldbody>
    <geom name="red" type="sphere" size="1" pos="5 0 0" rgba="1 0 0 1"/>
    <geom name="green" type="sphere" size="0.3" pos="5 -1.5 1" rgba="0 1 0 1"/>
  </worldbody>
</mujoco>
"""


def test_spheres_land_where_pinhole_maths_puts_them(render, cast):
    """Camera at the origin looking along +x (right = -y, up = +z), fovy 45, 64x64. The red
    sphere (r 1 at 5 m, on the axis) is a disc of radius tan(asin(1/5)) / tan(22.5 deg) * 32 =
    15.77 px: area 781 px. The green one's centre (5, -1.5, 1) projects to u = 0.3 / tan(22.5),
    v = 0.2 / tan(22.5): column 54.68, row 16.05, so pixel (16, 55) is green and its depth is
    that of the ray through it, solved here in float64. Measured: 788 red pixels (0.9% over;
    tolerance 2%)."""
    m = mujoco.MjModel.from_xml_string(SPHERES)
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    scene = make_scene(m)
    xpos, xmat = (
        jnp.asarray(d.geom_xpos, jnp.float32),
        jnp.asarray(d.geom_xmat.reshape(-1, 3, 3), jnp.float32),
    )
    camera = look_at((0, 0, 0), (1, 0, 0))
    image = np.asarray(render(scene, xpos, xmat, camera, size=64))
    hits = cast(scene, xpos, xmat, camera, size=64)
    red = np.asarray(hits.geom) == 0
    assert abs(red.sum() - math.pi * 15.77**2) < 0.02 * math.pi * 15.77**2
    facing = pixel_rays(camera, 64)[32 * 64 + 32, 0]  # the normal there is -x, the light behind
    assert red[31:33, 31:33].all() and image[32, 32, 0] == round(
        255 * (scene.ambient + scene.headlight * facing)
    )
    assert image[32, 32, 1:].max() == 0
    tan = math.tan(math.radians(22.5))
    assert (0.3 / tan + 1) / 2 * 64 - 0.5 == pytest.approx(54.68, abs=0.01)
    assert (1 - 0.2 / tan) / 2 * 64 - 0.5 == pytest.approx(16.05, abs=0.01)
    assert (
        int(hits.geom[16, 55]) == 1 and image[16, 55, 1] > 100 and image[16, 55, [0, 2]].max() == 0
    )
    ray = pixel_rays(camera, 64)[16 * 64 + 55]
    b = ray @ np.array([5, -1.5, 1])
    expected = b - math.sqrt(b * b - (5**2 + 1.5**2 + 1**2 - 0.3**2))
    assert float(hits.distance[16, 55]) == pytest.approx(expected, abs=1e-5)
    centre_normal = np.asarray(hits.normal[32, 32])
    point = float(hits.distance[32, 32]) * pixel_rays(camera, 64)[32 * 64 + 32]
    np.testing.assert_allclose(centre_normal, point - np.array([5, 0, 0]), atol=1e-5)
    # far from both discs: the background, exactly
    assert (image[60:, :4] == BACKGROUND).all() and (image[:4, :4] == BACKGROUND).all()


def test_vmap_equals_a_loop_of_single_renders(world, render):
    """Three states at random free-joint poses (MuJoCo C's kinematics), each with its own
    tracking camera: the batched picture is the loop's, byte for byte."""
    m, d, _, _, scene, _ = world
    rng = np.random.default_rng(0)
    xpos, xmat = [], []
    for _ in range(3):
        state = mujoco.MjData(m)
        state.qpos[:] = m.qpos0 + rng.uniform(-0.3, 0.3, m.nq)
        mujoco.mj_kinematics(m, state)
        xpos.append(state.geom_xpos.copy())
        xmat.append(state.geom_xmat.reshape(-1, 3, 3).copy())
    xpos, xmat = jnp.asarray(np.stack(xpos), jnp.float32), jnp.asarray(np.stack(xmat), jnp.float32)
    cameras = jax.vmap(lambda p: tracking_camera(p, 5.0, -30.0, 60.0))(xpos[:, 1])
    batch = jax.jit(jax.vmap(lambda x, r, c: render3d.render(scene, x, r, c, 32)))(
        xpos, xmat, cameras
    )
    for i in range(3):
        one = render(scene, xpos[i], xmat[i], jax.tree.map(lambda a: a[i], cameras), size=32)
        np.testing.assert_array_equal(np.asarray(batch[i]), np.asarray(one))
    assert not np.array_equal(np.asarray(batch[0]), np.asarray(batch[1]))


def test_checkered_floor_and_lighting_by_hand(world, render):
    """Looking straight down at (-2.5, -2.5) from 2 m (right = +x, up = +y), the squares x in
    [-4, -3) and [-3, -2) along y = -2.5 get the two tones 0.6 and 1.0 of the floor's 0.8 grey,
    each times ambient + diffuse * (-n.L) + headlight * (-n.ray): checked to one level.
    Every pixel of the red ball in the usual view has red = 255 * that shade, and its side that
    faces the light is brighter than the side that does not."""
    m, _, _, dx, scene, hits = world
    light = np.asarray(scene.light_dir)
    top = look_at((-2.5, -2.5, 2.0), (-2.5, -2.5, 0.0), up=(0, 1, 0))
    image = np.asarray(render(scene, dx.geom_xpos, dx.geom_xmat, top, size=32)).astype(int)
    rays = pixel_rays(top, 32).reshape(32, 32, 3)
    half = 2 * math.tan(math.radians(22.5))
    col = lambda x: int(round(((x + 2.5) / half + 1) / 2 * 32 - 0.5))  # noqa: E731
    row = 15  # y = -2.5 + half / 32: still in the square [-3, -2)
    for x, tone in ((-3.2, 0.6), (-2.6, 1.0)):  # floor(x) + floor(y) even: the light tone
        shade = scene.ambient + scene.diffuse * -light[2] + scene.headlight * -rays[row, col(x), 2]
        assert abs(image[row, col(x), 0] - round(255 * 0.8 * tone * shade)) <= 1, x
    assert image[row, col(-2.6), 0] - image[row, col(-3.2), 0] > 40

    camera = look_at(**CAMERA)
    image = np.asarray(render(scene, dx.geom_xpos, dx.geom_xmat, camera, size=32)).astype(int)
    ball = np.asarray(hits.geom) == mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_GEOM, "ball")
    normal = np.asarray(hits.normal)[ball]
    lit = -normal @ light
    facing = -np.sum(normal * pixel_rays(camera, 32)[ball.ravel()], -1)
    shade = scene.ambient + scene.diffuse * np.maximum(lit, 0) + scene.headlight * facing
    assert np.abs(image[ball][:, 0] - np.round(255 * np.minimum(shade, 1))).max() <= 1
    assert ball.sum() > 20 and image[ball][lit > 0.5, 0].min() > image[ball][lit < 0, 0].max()
    assert (image[ball][:, 1:] == 0).all()


def test_hidden_and_invisible_geoms_are_not_drawn(world):
    """Groups 0-2 are drawn by default, others on request; alpha 0 never."""
    m = world[0]
    names = {m.geom(g).name for g in make_scene(m).geom}
    assert names == {"floor", "ball", "pill", "egg", "can", "crate"}
    assert "can" not in {m.geom(g).name for g in make_scene(m, groups=(0,)).geom}
    assert "hidden" in {m.geom(g).name for g in make_scene(m, groups=(0, 1, 2, 3)).geom}


def test_colours_follow_mujocos_material_rule():
    """As MuJoCo's visualiser: a material's rgba shows unless the geom sets its own rgba, and a
    geom whose colour has alpha 0 is not drawn."""
    m = mujoco.MjModel.from_xml_string("""
    <mujoco>
      <asset><material name="green" rgba="0 1 0 1"/><material name="clear" rgba="0 1 0 0"/></asset>
      <worldbody>
        <geom type="sphere" size="1" material="green"/>
        <geom type="sphere" size="1" material="green" rgba="1 0 0 1"/>
        <geom type="sphere" size="1" material="clear"/>
      </worldbody>
    </mujoco>
    """)
    scene = make_scene(m)
    assert scene.geom == (0, 1) and scene.rgb == ((0.0, 1.0, 0.0), (1.0, 0.0, 0.0))


def test_mesh_geoms_are_refused_unless_hidden():
    mjcf = """
    <mujoco>
      <asset><mesh name="tet" vertex="0 0 0  1 0 0  0 1 0  0 0 1"/></asset>
      <worldbody><geom type="plane" size="1 1 1"/><geom name="rock" type="mesh" mesh="tet" group="{}"/></worldbody>
    </mujoco>
    """  # noqa: E501
    with pytest.raises(
        ValueError, match="'rock' is a mesh.*plane, sphere, capsule, ellipsoid, cylinder, box"
    ):
        make_scene(mujoco.MjModel.from_xml_string(mjcf.format(0)))
    # group 3: not drawn
    assert len(make_scene(mujoco.MjModel.from_xml_string(mjcf.format(3))).geom) == 1


def test_cameras_follow_mujoco_conventions():
    """tracking_camera is MuJoCo's free camera (mjv_updateScene's, between its two eyes);
    look_at's frame is right-handed, orthonormal, and looks at its target."""
    m = mujoco.MjModel.from_xml_string(SPHERES)
    d = mujoco.MjData(m)
    scene, option, perturb = mujoco.MjvScene(m, 10), mujoco.MjvOption(), mujoco.MjvPerturb()
    for lookat, distance, elevation, azimuth in (
        ((1, 2, 3), 4.0, -20.0, 30.0),
        ((0, 0, 0.5), 2.5, -45.0, 200.0),
    ):
        free = mujoco.MjvCamera()
        free.lookat[:], free.distance, free.elevation, free.azimuth = (
            lookat,
            distance,
            elevation,
            azimuth,
        )
        mujoco.mjv_updateScene(m, d, option, perturb, free, mujoco.mjtCatBit.mjCAT_ALL, scene)
        ours = tracking_camera(jnp.asarray(lookat, jnp.float32), distance, elevation, azimuth)
        np.testing.assert_allclose(
            ours.pos, (scene.camera[0].pos + scene.camera[1].pos) / 2, atol=1e-5
        )
        np.testing.assert_allclose(-ours.xmat[:, 2], scene.camera[0].forward, atol=1e-6)
        np.testing.assert_allclose(ours.xmat[:, 1], scene.camera[0].up, atol=1e-6)
    camera = look_at((1.0, -2.0, 3.0), (0.5, 0.5, 0.0))
    np.testing.assert_allclose(camera.xmat.T @ camera.xmat, np.eye(3), atol=1e-6)
    assert float(jnp.linalg.det(camera.xmat)) == pytest.approx(1.0, abs=1e-6)
    view = np.array([0.5, 0.5, 0.0]) - np.array([1.0, -2.0, 3.0])
    np.testing.assert_allclose(-camera.xmat[:, 2], view / np.linalg.norm(view), atol=1e-6)
    assert camera.xmat[2, 1] > 0  # up points up


# Gymnasium v5 models and the tracking views recommended for them: (distance, elevation, azimuth).
GYM_VIEWS = {
    "ant.xml": (3.5, -35.0, 90.0),
    "humanoid.xml": (3.0, -15.0, 90.0),
    "half_cheetah.xml": (3.0, -15.0, 90.0),
}


@pytest.mark.parametrize("asset", sorted(GYM_VIEWS))
def test_gymnasium_models_look_right(asset, render):
    """A 64x64 tracking view of the torso after mj_forward. The robot is brown (0.8, 0.6, 0.4:
    red > green) and the floor green-grey (0.8, 0.9, 0.8: green > red): the robot is at the
    centre, the floor fills the bottom row and shows both checker tones, the top row is floor
    or sky, and the picture is not constant."""
    m = mujoco.MjModel.from_xml_path(os.path.join(GYM_ASSETS, asset))
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    xpos, xmat = (
        jnp.asarray(d.geom_xpos, jnp.float32),
        jnp.asarray(d.geom_xmat.reshape(-1, 3, 3), jnp.float32),
    )
    camera = tracking_camera(d.xpos[1], *GYM_VIEWS[asset])
    image = np.asarray(render(make_scene(m), xpos, xmat, camera, size=64)).astype(int)
    red, green = image[..., 0], image[..., 1]
    assert (red[31:33, 31:33] > green[31:33, 31:33] + 10).all()
    assert (green[-1] > red[-1]).all() and (
        (green[0] > red[0]) | (image[0] == BACKGROUND).all(-1)
    ).all()
    floor = green[green > red + 5]
    assert floor.max() - floor.min() > 60 and len(np.unique(floor)) > 10
    assert image.std() > 20
