"""Car racing in pure JAX: Gymnasium `CarRacing-v3`'s tracks and reward, a car of our own, 96x96.

The track is Gymnasium's generator in fixed shapes (a `lax.scan` trace, CANDIDATES traced at once,
padded to MAX_TILES); the deploy variant `hairpin` bends the first corner back towards the centre.
The car is Gymnasium's car (car_dynamics.py) stepped without Box2D: one rigid body on four WHEELS,
each gripping by the surface under it. Reward, lap and episode are Gymnasium's; the picture is its
96x96 state view without the indicator bar. Each part, its deviations from Gymnasium and how far
they are measured to go: docs/environments.md, "Car racing in detail".
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from hintsjax.envs import raster
from hintsjax.envs.core import Env, Step
from hintsjax.envs.hints import register_composite, register_hint

NAME = "car_racing"

# -- Gymnasium's constants -----------------------------------------------------------------------
SCALE = 6.0
TRACK_RAD = 900 / SCALE
PLAYFIELD = 2000 / SCALE
TRACK_DETAIL_STEP = 21 / SCALE
TRACK_TURN_RATE = 0.31
TRACK_WIDTH = 40 / SCALE  # half-width of the road
BORDER = 8 / SCALE
BORDER_MIN_COUNT = 4
GRASS_DIM = PLAYFIELD / 20.0
CHECKPOINTS = 12
START_ALPHA = -math.pi / CHECKPOINTS
FPS = 50
ZOOM = 2.7 * SCALE  # px per u in Gymnasium's 1000x800 window
# Gymnasium's car (car_dynamics.py, SIZE = 0.02): hull mass and inertia, wheel radius and inertia.
MASS, INERTIA = 7.3, 19.2
FRONT, REAR = 1.6, 1.64  # centre to front and rear axle
WHEEL_R, WHEEL_INERTIA = 27 * 0.02, 4000 * 0.02**2
ENGINE_POWER = 1e8 * 0.02**2  # per rear wheel
FRICTION_LIMIT = 1e6 * 0.02**2  # per wheel, on road
TYRE_STIFFNESS = 205000 * 0.02**2  # force per u/s of slip
BRAKE_RATE = 15 * WHEEL_R * FPS  # u/s^2 of rim speed at full brake
# u/s: Box2D's cap on a body's translation, b2_maxTranslation = 2 u per 1/50 s step
MAX_SPEED = 100.0
# Gymnasium's wheels (WHEELPOS, WHEEL_W, WHEEL_R times SIZE) in the car's frame [right, forward]
# (u): front-left, front-right, rear-left, rear-right; each a box WHEEL_HALF [across, along] either
# side.
WHEELS = np.array([(-55, 80), (55, 80), (-55, -82), (55, -82)], np.float32) * 0.02
WHEEL_HALF = np.array([14, 27], np.float32) * 0.02
WHEEL_FORWARD, WHEEL_LEFT = WHEELS[:, 1], -WHEELS[:, 0]  # FRONT, FRONT, -REAR, -REAR; +-1.1
# Box2D's centre of mass of the hull (density 1) and the wheels (0.1) lies MASS_BEHIND behind the
# hull's origin (the car's xy); the car turns about it and its velocity is the centre of mass's.
MASS_BEHIND = 0.0805
# The front wheels' joint limit is 0.4 rad, which Box2D holds with a slop: pushed by the steering
# motor, Gymnasium's wheels settle at 0.4202 rad (measured); a target within it is met exactly.
STEER_LIMIT = 0.42
STEERED = np.array([1.0, 1.0, 0.0, 0.0], np.float32)
DRIVEN = np.array([0.0, 0.0, 1.0, 1.0], np.float32)

# -- ours --------------------------------------------------------------------------------------
MAX_TILES = 400
TRACE_STEPS = 800
# Trace steps per loop iteration. 8 runs 2.5x slower on XLA:CPU; on a GPU the trace is latency-bound
# (docs/throughput.md) and unrolling is untried.
TRACE_UNROLL = 1
CANDIDATES = 3
LOOKAHEAD = 10  # tiles (35 u) ahead for the curvature hint
PREVIEW = (1, 3, 6, 10, 15, 21, 28, 36)  # tiles ahead in the state observation

TWO_PI = 2 * math.pi
f32 = jnp.float32


@struct.dataclass
class CarRacingParams:
    """Track-generator ranges (what `hairpin` changes) and the reward's constants."""

    last_radius_low: float = 1.5 * TRACK_RAD  # checkpoint 11
    last_radius_high: float = 1.5 * TRACK_RAD
    second_alpha_low: float = TWO_PI / CHECKPOINTS  # checkpoint 1
    second_alpha_high: float = 2 * TWO_PI / CHECKPOINTS
    # Gymnasium's glue measure is sqrt((cos b dx)^2 + (sin b dy)^2)
    perpendicular_glue: bool = False
    lap_complete_percent: float = 0.95
    grass_grip: float = 0.6


VARIANTS = {
    "standard": CarRacingParams(),
    "hairpin": CarRacingParams(
        last_radius_low=TRACK_RAD / 3,
        last_radius_high=TRACK_RAD / 2,
        second_alpha_low=math.radians(5.0),
        second_alpha_high=math.radians(15.0),
        perpendicular_glue=True,
    ),
}


@struct.dataclass
class Track:
    """A closed track: centre points xy[i] (u), across-track angle beta[i] (the right-hand normal is
    (cos, sin)), kerb flags, and n_tiles valid entries of MAX_TILES. Tile i spans point i-1 to i."""

    xy: jax.Array
    beta: jax.Array
    kerb: jax.Array
    n_tiles: jax.Array

    @property
    def mask(self) -> jax.Array:
        return jnp.arange(MAX_TILES) < self.n_tiles


@struct.dataclass
class Car:
    """Pose (u, rad: forward is (-sin angle, cos angle)), body-frame velocity [forward, left] (u/s),
    yaw rate (rad/s), front wheel angle (rad, + left), throttle, rim speeds float32[4] of the WHEELS
    [front-left, front-right, rear-left, rear-right] (u/s)."""

    xy: jax.Array
    angle: jax.Array
    vel: jax.Array
    yaw_rate: jax.Array
    steer: jax.Array
    gas: jax.Array
    wheel_speed: jax.Array

    @classmethod
    def at(
        cls, xy, angle, speed=0.0, lateral=0.0, yaw_rate=0.0, steer=0.0, gas=0.0, wheel_speed=None
    ):
        """A hand-set car; the four wheels roll at `speed` unless given."""
        wheels = (speed,) * 4 if wheel_speed is None else wheel_speed
        return cls(
            jnp.asarray(xy, f32),
            f32(angle),
            jnp.asarray([speed, lateral], f32),
            f32(yaw_rate),
            f32(steer),
            f32(gas),
            jnp.asarray(wheels, f32),
        )


@struct.dataclass
class CarRacingState:
    """The track, the car, which tiles were visited, and the step count."""

    track: Track
    car: Car
    visited: jax.Array
    t: jax.Array


# -- track generation ----------------------------------------------------------------------------


def checkpoints(key: jax.Array, params: CarRacingParams) -> tuple[jax.Array, jax.Array]:
    """float32[12] angles and radii of the checkpoints, drawn as Gymnasium does."""
    k_noise, k_rad, k_last, k_second = jax.random.split(key, 4)
    c = jnp.arange(CHECKPOINTS, dtype=f32)
    noise = jax.random.uniform(k_noise, (CHECKPOINTS,), f32, 0.0, TWO_PI / CHECKPOINTS)
    rad = jax.random.uniform(k_rad, (CHECKPOINTS,), f32, TRACK_RAD / 3, TRACK_RAD)
    alpha = (
        (TWO_PI * c / CHECKPOINTS + noise)
        .at[0]
        .set(0.0)
        .at[-1]
        .set(TWO_PI * (CHECKPOINTS - 1) / CHECKPOINTS)
    )
    alpha = alpha.at[1].set(
        jax.random.uniform(k_second, (), f32, params.second_alpha_low, params.second_alpha_high)
    )
    last = jax.random.uniform(k_last, (), f32, params.last_radius_low, params.last_radius_high)
    return alpha, rad.at[0].set(1.5 * TRACK_RAD).at[-1].set(last)


def trace(alpha_c: jax.Array, rad_c: jax.Array, steps: int = TRACE_STEPS) -> tuple[jax.Array, ...]:
    """Gymnasium's trace from its start (1.5 TRACK_RAD, 0) heading north: float32[steps] each of the
    angle before the step (less 2 pi past the last checkpoint), across-track angle, x, y after
    it."""
    cx, cy, idx = rad_c * jnp.cos(alpha_c), rad_c * jnp.sin(alpha_c), jnp.arange(CHECKPOINTS)

    def step(carry, _):
        x, y, beta, dest = carry
        alpha = jnp.arctan2(y, x)
        alpha = jnp.where(alpha < 0, alpha + TWO_PI, alpha)
        # the next checkpoint at or after `dest` lying ahead; past the last one, wrap to 0
        ahead = (idx >= dest) & (alpha <= alpha_c)
        found = ahead.any()
        dest = jnp.where(found, jnp.argmax(ahead), 0)
        alpha = jnp.where(found, alpha, alpha - TWO_PI)
        r1x, r1y = jnp.cos(beta), jnp.sin(beta)
        proj = (r1x * (cx[dest] - x) + r1y * (cy[dest] - y)) * SCALE
        beta = beta - TWO_PI * jnp.maximum(0.0, jnp.ceil((beta - alpha - 1.5 * math.pi) / TWO_PI))
        beta = beta + TWO_PI * jnp.maximum(0.0, jnp.ceil((alpha - 1.5 * math.pi - beta) / TWO_PI))
        turn = jnp.minimum(TRACK_TURN_RATE, jnp.abs(0.001 * proj))
        new_beta = beta - jnp.where(proj > 0.3, turn, 0.0) + jnp.where(proj < -0.3, turn, 0.0)
        x, y = x - r1y * TRACK_DETAIL_STEP, y + r1x * TRACK_DETAIL_STEP
        return (x, y, new_beta, dest), (alpha, 0.5 * (beta + new_beta), x, y)

    init = (f32(1.5 * TRACK_RAD), f32(0.0), f32(0.0), jnp.int32(0))
    return jax.lax.scan(step, init, None, length=steps, unroll=TRACE_UNROLL)[1]


def wrap(a: jax.Array) -> jax.Array:
    """Angle into [-pi, pi)."""
    return (a + math.pi) % TWO_PI - math.pi


def _lap(key: jax.Array, params: CarRacingParams) -> tuple[Track, jax.Array]:
    """One candidate track from the trace's second lap, and whether Gymnasium would accept it."""
    alpha, beta, x, y = trace(*checkpoints(key, params))
    passes = jnp.cumsum(
        jnp.concatenate(
            [jnp.zeros(1, bool), (alpha[1:] > START_ALPHA) & (alpha[:-1] <= START_ALPHA)]
        )
    )
    i1, i2 = jnp.argmax(passes >= 1), jnp.argmax(passes >= 2)
    n = i2 - 1 - i1
    x, y, beta = (
        jax.lax.dynamic_slice(jnp.concatenate([a, jnp.zeros(MAX_TILES, f32)]), (i1,), (MAX_TILES,))
        for a in (x, y, beta)
    )
    xy = jnp.stack([x, y], -1)
    last = jnp.clip(n - 1, 0, MAX_TILES - 1)
    # Gymnasium's own measure
    gap = (xy[0] - xy[last]) * jnp.stack([jnp.cos(beta[0]), jnp.sin(beta[0])])
    gap = jnp.where(params.perpendicular_glue, jnp.abs(gap.sum()), jnp.linalg.norm(gap))
    ok = (passes[-1] >= 2) & (n >= 50) & (n <= MAX_TILES) & (gap <= TRACK_DETAIL_STEP)
    n = jnp.clip(n, 50, MAX_TILES)
    i = jnp.arange(MAX_TILES)
    xy, beta = jnp.where((i < n)[:, None], xy, 0.0), jnp.where(i < n, beta, 0.0)
    return Track(xy, beta, _kerbs(beta, n), n.astype(jnp.int32)), ok


def _kerbs(beta: jax.Array, n: jax.Array) -> jax.Array:
    """bool[MAX_TILES] kerb flags of a track with across-track angles beta[MAX_TILES] (n valid):
    where BORDER_MIN_COUNT successive heading steps turn one way by more than 0.2 the rate, and the
    BORDER_MIN_COUNT - 1 tiles before."""
    # the headings repeat with period n, padded by c on either side so that shifts are slices
    c, i = BORDER_MIN_COUNT, jnp.arange(MAX_TILES)
    # dbeta[k]: the turn into tile k - c + 1
    dbeta = wrap(jnp.diff(beta[jnp.arange(-c, MAX_TILES + c) % n]))
    turns = jnp.stack([dbeta[c - 1 - k : c - 1 - k + MAX_TILES + c - 1] for k in range(c)])
    sharp = (jnp.abs(turns) > 0.2 * TRACK_TURN_RATE).all(0) & (jnp.abs(jnp.sign(turns).sum(0)) == c)
    return jnp.stack([sharp[k : k + MAX_TILES] for k in range(c)]).any(0) & (i < n)


def track_from_gymnasium(points: np.ndarray) -> Track:
    """A Track holding Gymnasium's track `env.unwrapped.track` (float[n, 4] of alpha, beta, x, y per
    centre point; its tile i spans point i-1 to i, as ours), padded to MAX_TILES; kerbs by
    `_kerbs`."""
    points = np.asarray(points, np.float64)
    n = len(points)
    if not CONTACT_TILES <= n <= MAX_TILES:  # fewer would repeat tiles in wheel_contact's window
        raise ValueError(f"a track of {n} centre points does not fit {CONTACT_TILES}..{MAX_TILES}")
    xy = np.zeros((MAX_TILES, 2), np.float32)
    beta = np.zeros(MAX_TILES, np.float32)
    xy[:n], beta[:n] = points[:, 2:4], points[:, 1]
    n_tiles = jnp.asarray(n, jnp.int32)
    return Track(jnp.asarray(xy), jnp.asarray(beta), _kerbs(jnp.asarray(beta), n_tiles), n_tiles)


def generate_track(key: jax.Array, params: CarRacingParams) -> Track:
    """A fresh closed track: the first of CANDIDATES traced in parallel that Gymnasium accepts."""
    tracks, ok = jax.vmap(_lap, in_axes=(0, None))(jax.random.split(key, CANDIDATES), params)
    pick = jnp.argmax(ok)
    return jax.tree.map(lambda a: a[pick], tracks)


def first_corner_angle(track: Track, window: int = 20) -> jax.Array:
    """Degrees between the straights into and out of the first corner (180 if none): the first
    `window`-tile (70 u) stretch turning by >= 45 degrees starts it; its largest turn over a
    `window` stretch within the next `window` tiles is the corner's turn."""
    n, i = track.n_tiles, jnp.arange(MAX_TILES)
    heading = jnp.cumsum(
        jnp.where((i > 0) & (i < n), wrap(track.beta - jnp.roll(track.beta, 1)), 0.0)
    )
    turn = jnp.where(i + window < n, jnp.abs(jnp.roll(heading, -window) - heading), 0.0)
    start = jnp.argmax(turn >= math.radians(45))
    corner = jnp.where((i >= start) & (i <= start + window), turn, 0.0).max()
    return 180.0 - jnp.degrees(jnp.where(turn.max() >= math.radians(45), corner, 0.0))


# -- where the car is on the track ---------------------------------------------------------------


def _normal(beta: jax.Array) -> jax.Array:
    return jnp.stack([jnp.cos(beta), jnp.sin(beta)], -1)


def _quads(track: Track, tiles: jax.Array) -> jax.Array:
    """float32[k, 4, 2] corners of tiles, clockwise: left and right of its end, right and left of
    its start."""
    prev = (tiles - 1) % track.n_tiles
    end, start = track.xy[tiles], track.xy[prev]
    n1, n0 = _normal(track.beta[tiles]) * TRACK_WIDTH, _normal(track.beta[prev]) * TRACK_WIDTH
    return jnp.stack([end - n1, end + n1, start + n0, start - n0], -2)


def _edge_lines(quads: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Unit inward normals float32[..., 4, 2] and offsets [..., 4] of quads' edges [front, right,
    back, left]: a point p is inside where p . normal - offset >= 0 for all four."""
    e = jnp.roll(quads, -1, axis=-2) - quads
    normal = jnp.stack([e[..., 1], -e[..., 0]], -1) / jnp.maximum(
        jnp.linalg.norm(e, axis=-1, keepdims=True), 1e-6
    )
    return normal, jnp.sum(normal * quads, -1)


def nearest_point(track: Track, p: jax.Array) -> jax.Array:
    """int32 index of the centre point nearest to p[2]."""
    d2 = jnp.sum((track.xy - p) ** 2, -1)
    return jnp.argmin(jnp.where(track.mask, d2, jnp.inf))


def tile_at(track: Track, p: jax.Array) -> tuple[jax.Array, jax.Array]:
    """(tile index, inside): the tile whose quad holds p[2], searched near the nearest point."""
    tiles = (nearest_point(track, p) + jnp.arange(-2, 4)) % track.n_tiles
    normal, offset = _edge_lines(_quads(track, tiles))
    inside = (normal @ p - offset >= 0).all(-1)
    return tiles[jnp.argmax(inside)], inside.any()


# tiles searched for wheel contacts: nearest point - 2 .. + 3 (the car spans <= 2.7 u)
CONTACT_TILES = 6


@struct.dataclass
class WheelContact:
    """Which tiles the wheels touch: `tiles` int32[CONTACT_TILES] searched around the car, `touched`
    bool[CONTACT_TILES] whether a wheel touches each, `on_road` bool[4] whether each wheel touches
    any."""

    tiles: jax.Array
    touched: jax.Array
    on_road: jax.Array


def wheel_corners(car: Car) -> jax.Array:
    """float32[4, 4, 2] world corners of the four WHEELS' boxes, the front pair turned by the
    steering."""
    half_across, half_along = WHEEL_HALF
    corner_along = np.array([1.0, 1.0, -1.0, -1.0], np.float32) * half_along
    corner_left = np.array([1.0, -1.0, -1.0, 1.0], np.float32) * half_across
    delta = STEERED[:, None] * car.steer
    c, s = jnp.cos(delta), jnp.sin(delta)
    ahead = WHEEL_FORWARD[:, None] + c * corner_along - s * corner_left  # [4 wheels, 4 corners]
    left = WHEEL_LEFT[:, None] + s * corner_along + c * corner_left
    cs, sn = jnp.cos(car.angle), jnp.sin(car.angle)  # forward (-sin, cos), left (-cos, -sin)
    return jnp.stack([car.xy[0] - ahead * sn - left * cs, car.xy[1] + ahead * cs - left * sn], -1)


def wheel_contact(track: Track, car: Car) -> WheelContact:
    """The tiles the wheels touch. Box2D touches a tile when a wheel's box overlaps its quad; here
    when a corner of the box lies inside the quad (a tile's corner poking into a wheel is
    missed)."""
    tiles = (nearest_point(track, car.xy) + jnp.arange(-2, CONTACT_TILES - 2)) % track.n_tiles
    normal, offset = _edge_lines(_quads(track, tiles))  # [K, 4, 2], [K, 4]
    p = wheel_corners(car).reshape(16, 1, 1, 2)
    # [16, K]
    inside = (p[..., 0] * normal[..., 0] + p[..., 1] * normal[..., 1] - offset >= 0).all(-1)
    return WheelContact(tiles, inside.any(0), inside.reshape(4, 4 * CONTACT_TILES).any(-1))


def _track_frame(track: Track, car: Car):
    """Nearest point index, the car's signed offset left of the centre line (u), heading error
    (rad)."""
    j = nearest_point(track, car.xy)
    lateral = -jnp.sum((car.xy - track.xy[j]) * _normal(track.beta[j]))
    return j, lateral, wrap(car.angle - track.beta[j])


def _curvature(track: Track, j: jax.Array, half: int = 3) -> jax.Array:
    """Signed curvature (1/u, + left) at point j, from the heading change over +-half tiles."""
    n = track.n_tiles
    turn = wrap(track.beta[(j + half) % n] - track.beta[(j - half) % n])
    return turn / (2 * half * TRACK_DETAIL_STEP)


# -- the car -------------------------------------------------------------------------------------


# [steer, gas, brake]: steering left to right, gas and brake from none to full (Gymnasium's Box).
ACTION_RANGE = (np.array([-1.0, 0.0, 0.0], np.float32), np.array([1.0, 1.0, 1.0], np.float32))


def drive(car: Car, action: jax.Array, grip: jax.Array) -> Car:
    """One 1/50 s frame under action [steer, gas, brake] (clipped) with grip float32[4] per wheel (1
    on the road), in the WHEELS' order. As Gymnasium's `Car.step` then Box2D's `world.Step`: each
    wheel's force from the velocities and wheel angle at the frame's start, held for the frame;
    velocities then positions updated (semi-implicit Euler); the wheels turn towards the steering
    target."""
    steer_action, gas, brake = jnp.clip(action, *ACTION_RANGE)
    gas = car.gas + jnp.minimum(gas - car.gas, 0.1)
    target, limit, dt = (
        jnp.clip(-steer_action, -STEER_LIMIT, STEER_LIMIT),
        grip * FRICTION_LIMIT,
        1.0 / FPS,
    )
    u, v, r = car.vel[0], car.vel[1], car.yaw_rate
    c, s = jnp.cos(STEERED * car.steer), jnp.sin(STEERED * car.steer)
    # each wheel's ground velocity [forward, left] in the car's frame, then along and across the
    # wheel
    arm = WHEEL_FORWARD + MASS_BEHIND  # ahead of the mass centre
    ground_u, ground_v = u - r * WHEEL_LEFT, v + r * arm
    along, across = ground_u * c + ground_v * s, -ground_u * s + ground_v * c
    spin = car.wheel_speed + dt * DRIVEN * ENGINE_POWER * gas * WHEEL_R**2 / WHEEL_INERTIA / (
        jnp.abs(car.wheel_speed) + 5.0 * WHEEL_R
    )
    spin = jnp.sign(spin) * jnp.maximum(jnp.abs(spin) - BRAKE_RATE * brake * dt, 0.0)
    spin = jnp.where(brake >= 0.9, 0.0, spin)
    f_long, f_lat = TYRE_STIFFNESS * (spin - along), -TYRE_STIFFNESS * across
    scale = jnp.minimum(1.0, limit / jnp.maximum(jnp.sqrt(f_long**2 + f_lat**2), 1e-6))
    f_long, f_lat = f_long * scale, f_lat * scale
    spin = spin - dt * f_long * WHEEL_R**2 / WHEEL_INERTIA
    # each wheel's force in the car's frame, and its moment about the mass centre (+ turns left)
    fx, fy = f_long * c - f_lat * s, f_long * s + f_lat * c
    u, v = u + dt * fx.sum() / MASS, v + dt * fy.sum() / MASS  # in the frame at the frame's start
    # Box2D's speed cap
    cap = jnp.minimum(1.0, MAX_SPEED / jnp.maximum(jnp.sqrt(u**2 + v**2), 1e-6))
    u, v = u * cap, v * cap
    r = r + dt * jnp.sum(arm * fy - WHEEL_LEFT * fx) / INERTIA
    angle = car.angle + dt * r
    fwd0, left0 = (
        jnp.stack([-jnp.sin(car.angle), jnp.cos(car.angle)]),
        jnp.stack([-jnp.cos(car.angle), -jnp.sin(car.angle)]),
    )
    fwd = jnp.stack([-jnp.sin(angle), jnp.cos(angle)])
    # the origin, about the mass centre
    xy = car.xy + dt * (u * fwd0 + v * left0) + MASS_BEHIND * (fwd - fwd0)
    turn_c, turn_s = jnp.cos(dt * r), jnp.sin(dt * r)  # the same velocity in the turned car's frame
    vel = jnp.stack([u * turn_c + v * turn_s, v * turn_c - u * turn_s])
    steer = car.steer + jnp.clip(50.0 * (target - car.steer), -3.0, 3.0) * dt
    return car.replace(
        xy=xy, angle=angle, vel=vel, yaw_rate=r, steer=steer, gas=gas, wheel_speed=spin
    )


# -- the picture ---------------------------------------------------------------------------------

SIZE = 96
BACKGROUND, GRASS, ROAD = (0.4, 0.8, 0.4), (0.4, 230 / 255, 0.4), 102 / 255
KERB_RED, KERB_WHITE, HULL = (1.0, 0.0, 0.0), (1.0, 1.0, 1.0), (0.8, 0.0, 0.0)
PIXEL = 0.5 * (1000 / SIZE + 800 / SIZE) / ZOOM  # mean pixel size in u, for anti-aliasing
# car-frame coordinates [right, forward] (u) of each pixel centre: the car at window (500, 600)
_cols, _rows = (np.arange(SIZE) + 0.5) * 1000 / SIZE, (np.arange(SIZE) + 0.5) * 800 / SIZE
VIEW = np.stack(
    np.broadcast_arrays((_cols[None, :] - 500) / ZOOM, (600 - _rows[:, None]) / ZOOM), -1
)
VIEW = VIEW.astype(np.float32)
VIEW_CENTRE = np.array([0.0, 200 / ZOOM], np.float32)
# The road is drawn in BLOCKS x BLOCKS blocks, each from its BLOCK_TILES tiles nearest to it among
# the VIEW_TILES nearest the view's centre: 16 tile tests per pixel. Against drawing every tile,
# 0.4% of pictures differ, by a pixel or two (measured on 256 hairpin states off the centre line).
BLOCKS, BLOCK_TILES, VIEW_TILES = 4, 16, 64
RENDER_UNROLL = 4  # tiles per loop iteration: 1.7x faster than 1 on a GPU (docs/throughput.md)
_B = SIZE // BLOCKS
VIEW_BLOCKS = (
    VIEW.reshape(BLOCKS, _B, BLOCKS, _B, 2).transpose(0, 2, 1, 3, 4).reshape(BLOCKS**2, _B, _B, 2)
)
BLOCK_CENTRES = VIEW_BLOCKS.mean((1, 2))
HULL_POLYS = [
    [(-60, 130), (60, 130), (60, 110), (-60, 110)],
    [(-15, 120), (15, 120), (20, 20), (-20, 20)],
    [(25, 20), (50, -10), (50, -40), (20, -90), (-20, -90), (-50, -40), (-50, -10), (-25, 20)],
    [(-50, -120), (50, -120), (50, -90), (-50, -90)],
]


def _hull_cover() -> np.ndarray:
    """float32[S, S] coverage of Gymnasium's hull polygons, 4x4 supersampled (the car never
    moves)."""
    sub = (np.arange(4) + 0.5) / 4 - 0.5
    du, dv = np.meshgrid(sub * 1000 / SIZE / ZOOM, -sub * 800 / SIZE / ZOOM)
    p = VIEW[:, :, None, None, :] + np.stack([du, dv], -1)
    hit = np.zeros(p.shape[:-1], bool)
    for poly in HULL_POLYS:
        q = np.array(poly, np.float32) * 0.02
        e = np.roll(q, -1, 0) - q
        cross = e[:, 0] * (p[..., None, 1] - q[:, 1]) - e[:, 1] * (p[..., None, 0] - q[:, 0])
        hit |= (cross >= 0).all(-1) | (cross <= 0).all(-1)
    return hit.mean((-1, -2)).astype(np.float32)


HULL_COVER = _hull_cover()
# rows and columns the car (steered wheels too) stays in
CAR_WINDOW = (slice(62, 84), slice(42, 54))


def _box_cover(
    points: jax.Array, centre: jax.Array, angle: jax.Array, half: np.ndarray
) -> jax.Array:
    """float32[S, S] anti-aliased coverage of a rectangle turned by angle (rad, ccw)."""
    d = points - centre
    c, s = jnp.cos(angle), jnp.sin(angle)
    local = (
        jnp.abs(jnp.stack([c * d[..., 0] + s * d[..., 1], -s * d[..., 0] + c * d[..., 1]], -1))
        - half
    )
    outside = jnp.linalg.norm(jnp.maximum(local, 0.0), axis=-1) + jnp.minimum(local.max(-1), 0.0)
    return raster.coverage(outside, 0.0, PIXEL)


def _car_frame(points: jax.Array, car: Car) -> jax.Array:
    """float32[..., 2] world points in the car's frame [right, forward] (elementwise: XLA:CPU runs
    [..., 2] @ [2, 2] products many times slower)."""
    c, s = jnp.cos(car.angle), jnp.sin(car.angle)
    d = points - car.xy
    return jnp.stack([d[..., 0] * c + d[..., 1] * s, d[..., 1] * c - d[..., 0] * s], -1)


def _road(state: CarRacingState) -> tuple[jax.Array, ...]:
    """Per pixel [S, S]: road coverage, its grey, kerb coverage, whether the kerb is red."""
    track, car = state.track, state.car
    local = _car_frame(track.xy, car)
    d2 = jnp.where(track.mask, jnp.sum((local - jnp.asarray(VIEW_CENTRE)) ** 2, -1), jnp.inf)
    near = jax.lax.top_k(-d2, VIEW_TILES)[1]
    to_block = jnp.sum((local[near][None] - jnp.asarray(BLOCK_CENTRES)[:, None]) ** 2, -1)
    far, pick = jax.lax.top_k(-jnp.where(jnp.isfinite(d2[near]), to_block, jnp.inf), BLOCK_TILES)
    tiles = near[pick]  # [blocks, k]
    normal, offset = _edge_lines(_car_frame(_quads(track, tiles), car))
    offset = jnp.where(jnp.isfinite(far)[..., None], offset, 1e9)  # padding tiles cover nothing
    # a pixel's x depends on its column only and y on its row: edge distances are row + column
    # [blocks, B]
    cols, rows = jnp.asarray(VIEW_BLOCKS[:, 0, :, 0]), jnp.asarray(VIEW_BLOCKS[:, :, 0, 1])
    across = cols[:, None, None, :] * normal[..., 0, None]  # [blocks, k, 4, B]
    down = rows[:, None, None, :] * normal[..., 1, None] - offset[..., None]
    right = wrap(track.beta[(tiles - 1) % track.n_tiles] - track.beta[tiles]) > 0  # the kerb's side
    kerb_width = jnp.where(track.kerb[tiles], BORDER, -1e9)
    shade = ROAD + jnp.where(state.visited[tiles], 0.0, 0.01 * (tiles % 3))

    def paint_tile(canvas, tile):
        cover, grey, kerb_cover, kerb_red = canvas
        across, down, right, kerb_width, red, shade = tile
        # front, right, back, left
        d = [down[:, j, :, None] + across[:, j, None, :] for j in range(4)]
        right, kerb_width, red, shade = (a[:, None, None] for a in (right, kerb_width, red, shade))
        along = (d[0] >= -1e-3) & (d[2] >= -1e-3)  # between the tile's two ends, overlapping seams
        road = jnp.where(along, jnp.clip(0.5 + jnp.minimum(d[1], d[3]) / PIXEL, 0.0, 1.0), 0.0)
        side = jnp.where(right, d[1], d[3])  # kerbs lie BORDER wide on the turn's inner side
        band = jnp.where(
            along, jnp.clip(0.5 + jnp.minimum(-side, side + kerb_width) / PIXEL, 0.0, 1.0), 0.0
        )
        return (
            jnp.maximum(cover, road),
            jnp.where(road > 0, shade, grey),
            jnp.maximum(kerb_cover, band),
            jnp.where(band > 0, red, kerb_red),
        ), None

    zero = jnp.zeros(VIEW_BLOCKS.shape[:-1], f32)
    per_tile = jax.tree.map(
        lambda a: jnp.moveaxis(a, 1, 0), (across, down, right, kerb_width, tiles % 2 == 1, shade)
    )
    canvas = jax.lax.scan(
        paint_tile, (zero, zero + ROAD, zero, zero > 0), per_tile, unroll=RENDER_UNROLL
    )[0]
    return tuple(
        a.reshape(BLOCKS, BLOCKS, _B, _B).swapaxes(1, 2).reshape(SIZE, SIZE) for a in canvas
    )


def render_track(state: CarRacingState) -> jax.Array:
    """float32[S, S, 3]: grass, kerbs and road around the car (Gymnasium's colours)."""
    car = state.car
    c, s = jnp.cos(car.angle), jnp.sin(car.angle)
    right, ahead = jnp.asarray(VIEW[..., 0]), jnp.asarray(VIEW[..., 1])
    world = [car.xy[0] + right * c - ahead * s, car.xy[1] + right * s + ahead * c]
    cell = [jnp.floor(w / GRASS_DIM).astype(jnp.int32) for w in world]
    patch = (((cell[0] | cell[1]) & 1) == 0)[..., None]  # Gymnasium's lighter squares
    inside = ((jnp.abs(world[0]) <= PLAYFIELD) & (jnp.abs(world[1]) <= PLAYFIELD))[..., None]
    image = jnp.where(inside, jnp.where(patch, jnp.array(GRASS), jnp.array(BACKGROUND)), 0.0)
    cover, grey, kerb_cover, kerb_red = _road(state)
    kerb = jnp.where(kerb_red[..., None], jnp.array(KERB_RED), jnp.array(KERB_WHITE))
    image = image + kerb_cover[..., None] * (kerb - image)
    return image + cover[..., None] * (grey[..., None] - image)


def render_car(image: jax.Array, car: Car) -> jax.Array:
    """Paint the wheels (the front pair steered) and the hull; the car sits still in the picture,
    so only the CAR_WINDOW rows and columns around it are touched."""
    rows, cols = CAR_WINDOW
    crop, points = image[rows, cols], jnp.asarray(VIEW[rows, cols])
    for i, centre in enumerate(WHEELS):
        cover = _box_cover(points, jnp.asarray(centre), car.steer if i < 2 else 0.0, WHEEL_HALF)
        crop = raster.paint(crop, cover, (0.0, 0.0, 0.0))
    crop = raster.paint(crop, jnp.asarray(HULL_COVER[rows, cols]), HULL)
    return image.at[rows, cols].set(crop)


# -- the env -------------------------------------------------------------------------------------


class CarRacing(Env):
    name = NAME
    max_steps = 1000
    action_size = 3
    image_size = SIZE
    fixed_image_size = True

    def default_params(self) -> CarRacingParams:
        return VARIANTS["standard"]

    def initial_state(self, key: jax.Array, params: CarRacingParams) -> CarRacingState:
        track = generate_track(key, params)
        # Gymnasium's start: the first centre point, facing along the track
        car = Car.at(track.xy[0], track.beta[0])
        return CarRacingState(track, car, jnp.zeros(MAX_TILES, bool), jnp.zeros((), jnp.int32))

    def action_range(self, params: CarRacingParams) -> tuple[jax.Array, jax.Array]:
        return jnp.asarray(ACTION_RANGE[0]), jnp.asarray(ACTION_RANGE[1])

    def transition(self, key, state: CarRacingState, action, params: CarRacingParams) -> Step:
        track = state.track
        # a wheel grips as on the road while it touches a tile (Box2D: the contacts of the last
        # step)
        grip = jnp.where(wheel_contact(track, state.car).on_road, 1.0, params.grass_grip)
        car = drive(state.car, jnp.asarray(action, f32), grip)
        contact = wheel_contact(track, car)
        before = state.visited[contact.tiles]
        new = contact.touched & ~before
        visited = state.visited.at[contact.tiles].set(before | contact.touched)
        count = visited.sum()
        # Gymnasium's FrictionDetector ends the lap when tile 0 is first touched past the share
        past = count > params.lap_complete_percent * track.n_tiles
        lap = (count == track.n_tiles) | ((new & (contact.tiles == 0)).any() & past)
        out = (jnp.abs(car.xy) > PLAYFIELD).any()
        reward = jnp.where(out, -100.0, 1000.0 / track.n_tiles * new.sum() - 0.1)
        return Step(state.replace(car=car, visited=visited), reward.astype(f32), lap | out)

    def render(self, state: CarRacingState, params: CarRacingParams) -> jax.Array:
        """uint8[96, 96, 3]: Gymnasium's car-centred view (without its indicator bar)."""
        return raster.to_uint8(render_car(render_track(state), state.car))

    def state_obs(self, state: CarRacingState, params: CarRacingParams) -> jax.Array:
        """float32[28]: see `state_observation`."""
        return state_observation(state)

    def metrics(self, state: CarRacingState, params: CarRacingParams) -> dict[str, jax.Array]:
        """The paper's progress P (visited tiles / all tiles) of the state an episode ended in."""
        return {"progress": progress(state)}


def state_observation(state: CarRacingState) -> jax.Array:
    """float32[28], scaled to about [-1, 1]: forward and lateral speed /100 u/s, yaw rate /5 rad/s,
    steering angle /0.4 rad, throttle, rear and front wheel spin (rim minus forward speed) /100 u/s,
    offset left of the centre line /TRACK_WIDTH, sin and cos of the heading error, on_track,
    progress; then [forward, left] /50 u of the centre points PREVIEW tiles past the nearest one."""
    track, car = state.track, state.car
    j, lateral, error = _track_frame(track, car)
    c, s = jnp.cos(car.angle), jnp.sin(car.angle)
    ahead = (track.xy[(j + jnp.asarray(PREVIEW)) % track.n_tiles] - car.xy) @ jnp.array(
        [[-s, -c], [c, -s]]
    )
    slip = car.wheel_speed.reshape(2, 2).mean(-1) - car.vel[0]  # [front, rear] pairs
    on = tile_at(track, car.xy)[1].astype(f32)
    head = jnp.stack(
        [
            car.vel[0] / 100,
            car.vel[1] / 100,
            car.yaw_rate / 5,
            car.steer / 0.4,
            car.gas,
            slip[1] / 100,
            slip[0] / 100,
            lateral / TRACK_WIDTH,
            jnp.sin(error),
            jnp.cos(error),
            on,
            progress(state),
        ]
    )
    return jnp.concatenate([head, ahead.reshape(-1) / 50.0]).astype(f32)


def progress(state: CarRacingState) -> jax.Array:
    """float32 P = visited tiles / all tiles (SPEC section 6)."""
    return (state.visited.sum() / state.track.n_tiles).astype(f32)


# -- hints (SPEC section 3) ----------------------------------------------------------------------

A_LAT = 100.0  # u/s^2: about half the tyres' grip, so target_speed leaves room to steer
V_MAX = 100.0


@register_hint(NAME, "speed", dim=1, unit="u/s")
def speed(state: CarRacingState, params: CarRacingParams) -> jax.Array:
    """The hull's speed over ground (1 u is about 1 m: the car is 5 u long)."""
    return jnp.linalg.norm(state.car.vel)[None]


@register_hint(NAME, "curvature", dim=1, unit="1/u")
def curvature(state: CarRacingState, params: CarRacingParams) -> jax.Array:
    """Signed track curvature (+ left) LOOKAHEAD tiles (35 u) ahead of the nearest centre point."""
    j = nearest_point(state.track, state.car.xy)
    return _curvature(state.track, (j + LOOKAHEAD) % state.track.n_tiles)[None]


@register_hint(NAME, "on_track", dim=1, unit="1")
def on_track(state: CarRacingState, params: CarRacingParams) -> jax.Array:
    """1.0 if the car's centre is on a tile, else 0.0."""
    return tile_at(state.track, state.car.xy)[1].astype(f32)[None]


@register_hint(NAME, "target_speed", dim=1, unit="u/s")
def target_speed(state: CarRacingState, params: CarRacingParams) -> jax.Array:
    """sqrt(A_LAT / |kappa|) for the sharpest curvature over the next 2 LOOKAHEAD tiles, at most V_MAX."""  # noqa: E501
    j = nearest_point(state.track, state.car.xy)
    ahead = jnp.arange(2 * LOOKAHEAD + 1)
    kappa = jnp.abs(
        jax.vmap(lambda k: _curvature(state.track, (j + k) % state.track.n_tiles))(ahead)
    ).max()
    return jnp.minimum(jnp.sqrt(A_LAT / jnp.maximum(kappa, 1e-6)), V_MAX)[None]


@register_hint(NAME, "state", dim=28, unit="scaled, see state_observation")
def full_state(state: CarRacingState, params: CarRacingParams) -> jax.Array:
    """The state observation."""
    return state_observation(state)


register_composite(NAME, "composite", ("on_track", "curvature"))


# Training defaults, RunConfig layers over the dataclasses' (hintsjax/settings/env_defaults.py): the
# hint, deploy variants and PPO settings of every agent; `learners`, the layer of every agent but
# the converged references; `agents`, an agent's own layer (the references' budgets and settings).
# 1000 episodes of 1000 steps (SPEC section 5); trained on the standard track, deployed on
# hairpins. The paper conditions the car with scheme mc (scheme=mc).
# The car's references run on its state (state_observation: speeds, steering, the track's
# next centre points): PPO on the state reached 716 on standard tracks after 1 M steps (1
# seed, 10 episodes), so the expert takes 2 M at the agents' settings. GAIL's reward is
# -log(1 - D) > 0, as idp's: with the signed log odds a car could gain by leaving the
# playfield, which ends the episode.
# The learners use the authors' action head (Appx A.3: mean 2 sigmoid(x) - 1, std >= 0.01) and
# every agent is evaluated with sampled actions (the authors' protocol): measured on PPO-RGB, 5
# seeds (experiments/results/car_learning.md), the sigmoid head's training episodes return 546
# against the clipped Gaussian's 163, and the policies' means score far below their samples (the
# sigmoid head 18 against 504, the Gaussian 167 against 438): they keep a std near 0.8 and drive
# on it, gas and brake below 0 being none.
TRAINING = dict(
    hint="composite",
    eval_variants=("hairpin",),
    stochastic_eval=True,
    ppo=dict(total_env_steps=1_000_000, num_envs=128, starts_per_rollout=True),
    learners=dict(ppo=dict(action_head="sigmoid")),
    agents=dict(
        expert_ppo=dict(ppo=dict(total_env_steps=2_000_000)),
        gail=dict(ppo=dict(total_env_steps=2_000_000), gail=dict(reward="original")),
        dagger=dict(ppo=dict(total_env_steps=250_000), dagger=dict(buffer_size=250_000)),
    ),
)
