"""Our car against Gymnasium's Box2D car on a skidpad (issue 26, item 1): cornering without a track.

    python experiments/car_skidpad.py     # -> experiments/results/car_skidpad.md

Both cars start at rest in an empty world (no tiles: both use grass grip, 0.6 of the road's),
speed up straight to a target speed (gas 0.5 below it, none above; 200 frames), then hold a fixed
steering input for 150 frames under the same speed rule. Over the last 50 frames: the speed, the
yaw rate, the lateral acceleration speed x yaw rate, and the slip angle (the hull's sideways
against its forward speed). Gymnasium's car is `gymnasium.envs.box2d.car_dynamics.Car` in a
Box2D world stepped as CarRacing-v3 steps it; ours is `envs/car_racing.py: drive`.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
from hintsjax.reproduce.markdown import markdown_table

RESULTS = Path(__file__).resolve().parent / "results"
FPS, STRAIGHT, TURN, MEASURE = 50, 200, 150, 50


def control(speed: float, target: float, steer: float) -> np.ndarray:
    return np.array([steer, 0.5 * (speed < target), 0.0], np.float32)


def box2d_run(target: float, steer: float) -> np.ndarray:
    """[frames, 4]: speed, yaw rate, forward and sideways speed of Gymnasium's car."""
    import Box2D
    from gymnasium.envs.box2d.car_dynamics import Car

    world = Box2D.b2World((0, 0))
    car = Car(world, 0.0, 0.0, 0.0)
    out = []
    for t in range(STRAIGHT + TURN):
        hull = car.hull
        v = np.array(hull.linearVelocity)
        fwd, side = np.array(hull.GetWorldVector((0, 1))), np.array(hull.GetWorldVector((1, 0)))
        speed = float(np.linalg.norm(v))
        action = control(speed, target, steer if t >= STRAIGHT else 0.0)
        car.steer(-float(action[0]))
        car.gas(float(action[1]))
        car.brake(float(action[2]))
        car.step(1.0 / FPS)
        world.Step(1.0 / FPS, 6 * 30, 2 * 30)
        out.append([speed, hull.angularVelocity, v @ fwd, v @ side])
    car.destroy()
    return np.array(out)


def ours_run(target: float, steer: float) -> np.ndarray:
    import jax
    import jax.numpy as jnp

    from hintsjax.envs.car_racing import Car, drive

    step = jax.jit(lambda car, action: drive(car, action, jnp.full(4, 0.6)))
    car = Car.at([0.0, 0.0], 0.0)
    out = []
    for t in range(STRAIGHT + TURN):
        vel = np.asarray(car.vel)
        speed = float(np.linalg.norm(vel))
        car = step(car, jnp.asarray(control(speed, target, steer if t >= STRAIGHT else 0.0)))
        out.append([speed, float(car.yaw_rate), vel[0], vel[1]])
    return np.array(out)


def measure(trace: np.ndarray) -> dict:
    last = trace[-MEASURE:]
    speed, yaw = last[:, 0].mean(), np.abs(last[:, 1]).mean()
    slip = np.degrees(np.arctan2(np.abs(last[:, 3]), np.abs(last[:, 2]))).mean()
    return {
        "speed": speed,
        "yaw_rate": yaw,
        "lateral_acceleration": speed * yaw,
        "slip_degrees": slip,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--speeds", default="20,40,60")
    parser.add_argument("--steers", default="0.1,0.25,0.5,1.0")
    parser.add_argument("--out", type=Path, default=RESULTS / "car_skidpad.md")
    args = parser.parse_args()
    rows = []
    for target in [float(v) for v in args.speeds.split(",")]:
        for steer in [float(s) for s in args.steers.split(",")]:
            b, o = measure(box2d_run(target, steer)), measure(ours_run(target, steer))
            rows.append(
                [f"{target:.0f}", f"{steer:g}"]
                + [
                    f"{b[k]:.1f} / {o[k]:.1f}"
                    for k in ("speed", "yaw_rate", "lateral_acceleration", "slip_degrees")
                ]
            )
            print(rows[-1], flush=True)
    lines = [
        "# Skidpad: Gymnasium's Box2D car / ours",
        "",
        f"Made by `python experiments/car_skidpad.py --speeds {args.speeds} --steers "
        f"{args.steers}` (2-core CPU development machine, Gymnasium 1.4.0, Box2D 2.3.10, "
        f"{time.strftime('%Y-%m-%d', time.gmtime())}). Each cell: Gymnasium's value / ours, the "
        f"mean over the last {MEASURE} of {TURN} frames at a fixed steering input, after "
        f"{STRAIGHT} frames straight; on grass (both cars' grip 0.6 of the road's). Steer 1 is "
        "full lock (0.42 rad at the wheels in both: Box2D holds its 0.4 rad joint limit with a "
        "slop).",
        "",
        *markdown_table(
            [
                "target speed (u/s)",
                "steer",
                "speed (u/s)",
                "yaw rate (rad/s)",
                "lateral acceleration (u/s^2)",
                "slip angle (deg)",
            ],
            rows,
        ),
        "",
    ]
    args.out.write_text("\n".join(lines))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
