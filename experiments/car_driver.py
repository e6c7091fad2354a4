"""Our car against Gymnasium's CarRacing-v3 under one scripted driver (issue 26, item 1).

    python experiments/car_driver.py [--tracks 50] [--speeds 30,60,90]   # -> experiments/results/car_driver.md

The driver is pure pursuit on the track's centre line: it steers towards the centre point
LOOKAHEAD points past the nearest one (steer = -GAIN x the angle to it, clipped to [-1, 1]; +1
turns right in both envs), and holds a target speed with gas 0.5 below it and brake 0.3 above
1.1 x it. The same numpy function drives both envs, on 50 tracks of each (Gymnasium's seeds
0..49; ours the keys 0..49: different tracks from the same generator), for 1000 steps or until the
episode ends. Per target speed: tiles visited (progress), return, laps completed and their time,
top speed, and how often the car leaves the road (all four wheels, or in ours both axles, off the
tiles) per lap of track.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from report import markdown_table  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
LOOKAHEAD = 5  # centre points (about 3.5 u each) ahead of the nearest
GAIN = 2.0
STEPS = 1000


def pursue(xy: np.ndarray, angle: np.ndarray, speed: np.ndarray, track: list[np.ndarray], target_speed: float) -> np.ndarray:
    """Actions [B, 3] (steer, gas, brake) for cars at xy [B, 2], heading angle [B] (forward is
    (-sin, cos)), speed [B], on tracks given as centre points [n_b, 2] each."""
    actions = np.zeros((len(xy), 3), np.float32)
    for b, points in enumerate(track):
        j = int(np.argmin(np.sum((points - xy[b]) ** 2, axis=1)))
        rel = points[(j + LOOKAHEAD) % len(points)] - xy[b]
        fwd = np.array([-np.sin(angle[b]), np.cos(angle[b])])
        left = np.array([-np.cos(angle[b]), -np.sin(angle[b])])
        bearing = np.arctan2(rel @ left, rel @ fwd)  # + : the target is to the left
        actions[b] = [np.clip(-GAIN * bearing, -1, 1), 0.5 * (speed[b] < target_speed), 0.3 * (speed[b] > 1.1 * target_speed)]
    return actions


def summarize(progress, returns, lap_steps, top_speed, exits) -> dict:
    laps = np.isfinite(lap_steps)
    return {"progress": float(np.mean(progress)), "progress_std": float(np.std(progress)),
            "return": float(np.mean(returns)), "return_std": float(np.std(returns)),
            "laps": int(laps.sum()), "lap_seconds": float(np.mean(lap_steps[laps]) / 50) if laps.any() else None,
            "top_speed": float(np.mean(top_speed)), "exits_per_lap": float(np.mean(exits / np.maximum(progress, 1e-3)))}


def drive_gymnasium(tracks: int, target_speed: float) -> dict:
    import gymnasium as gym

    env = gym.make("CarRacing-v3", continuous=True)
    progress, returns, lap_steps, top, exits = [], [], [], [], []
    for seed in range(tracks):
        env.reset(seed=seed)
        u = env.unwrapped
        points = np.array([(x, y) for _, _, x, y in u.track])
        total, fastest, off_before, out, lap = 0.0, 0.0, False, 0, np.inf
        for t in range(STEPS):
            hull = u.car.hull
            speed = float(np.linalg.norm(hull.linearVelocity))
            action = pursue(np.array([[hull.position[0], hull.position[1]]]), np.array([hull.angle]), np.array([speed]),
                            [points], target_speed)[0]
            _, reward, terminated, truncated, _ = env.step(action)
            total += reward
            fastest = max(fastest, speed)
            off = all(len(w.tiles) == 0 for w in u.car.wheels)
            out += off and not off_before
            off_before = off
            if terminated or truncated:
                if terminated and u.tile_visited_count >= len(u.track) * u.lap_complete_percent:
                    lap = t + 1
                break
        progress.append(u.tile_visited_count / len(u.track))
        returns.append(total)
        lap_steps.append(lap)
        top.append(fastest)
        exits.append(out)
    env.close()
    return summarize(np.array(progress), np.array(returns), np.array(lap_steps), np.array(top), np.array(exits))


def drive_ours(tracks: int, target_speed: float) -> dict:
    import jax
    import jax.numpy as jnp

    from hintsjax import envs
    from hintsjax.envs import car_racing as car

    env = envs.make("car_racing", observe=("state",))
    params = envs.make_params("car_racing")
    keys = jnp.stack([jax.random.key(i) for i in range(tracks)])
    state = jax.jit(jax.vmap(env.initial_state, in_axes=(0, None)))(keys, params)

    @jax.jit
    def step(state, action):
        def one(s, a):
            out = env.transition(jax.random.key(0), s, a, params)
            on_road = jax.vmap(lambda p: car.tile_at(s.track, p)[1])(car._axles(out.state.car))
            return out.state.replace(t=s.t + 1), out.reward, out.terminated, ~on_road.any()
        return jax.vmap(one)(state, action)

    n = np.asarray(state.track.n_tiles)
    points = [np.asarray(state.track.xy[b, : n[b]]) for b in range(tracks)]
    alive = np.ones(tracks, bool)
    total, fastest, out, off_before = np.zeros(tracks), np.zeros(tracks), np.zeros(tracks), np.zeros(tracks, bool)
    lap = np.full(tracks, np.inf)
    for t in range(STEPS):
        c = state.car
        speed = np.linalg.norm(np.asarray(c.vel), axis=1)
        action = pursue(np.asarray(c.xy), np.asarray(c.angle), speed, points, target_speed)
        state, reward, done, off = jax.tree.map(np.asarray, step(state, jnp.asarray(action)))
        total += np.where(alive, reward, 0.0)
        fastest = np.where(alive, np.maximum(fastest, speed), fastest)
        out += alive & off & ~off_before
        off_before = off
        visited = np.asarray(state.visited.sum(axis=1))
        lapped = alive & done & (visited > 0.95 * n)
        lap = np.where(lapped, t + 1, lap)
        alive &= ~done
        if not alive.any():
            break
    progress = np.asarray(state.visited.sum(axis=1)) / n
    return summarize(progress, total, lap, fastest, out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=50)
    parser.add_argument("--speeds", default="30,60,90")
    parser.add_argument("--out", type=Path, default=RESULTS / "car_driver.md")
    args = parser.parse_args()
    rows, raw = [], {}
    for target in [float(s) for s in args.speeds.split(",")]:
        for name, drive in (("Gymnasium CarRacing-v3 (Box2D)", drive_gymnasium), ("ours (hintsjax car_racing)", drive_ours)):
            start = time.perf_counter()
            r = drive(args.tracks, target)
            raw[f"{name} @ {target:.0f}"] = {**r, "seconds": round(time.perf_counter() - start, 1)}
            print(name, target, r, flush=True)
            rows.append([f"{target:.0f}", name, f"{r['progress']:.3f} ± {r['progress_std']:.3f}",
                         f"{r['return']:.0f} ± {r['return_std']:.0f}", f"{r['laps']}/{args.tracks}",
                         "-" if r["lap_seconds"] is None else f"{r['lap_seconds']:.1f}", f"{r['top_speed']:.1f}",
                         f"{r['exits_per_lap']:.2f}"])
    lines = ["# The scripted driver on Gymnasium's car and on ours", "",
             f"Made by `python experiments/car_driver.py --tracks {args.tracks} --speeds {args.speeds}` on a 2-core "
             "CPU (development machine, 2026-11-25; Gymnasium 1.4.0 with Box2D 2.3.10). Pure pursuit on the centre "
             f"line ({LOOKAHEAD} points ahead, gain {GAIN}), a target speed held by gas 0.5 / brake 0.3; "
             f"{args.tracks} tracks per env, 1000 steps at most. Progress: tiles visited / all (mean ± std over "
             "tracks); laps: episodes ended by a completed lap, and their mean time; exits: times the car left the "
             "road (all wheels / both axles off the tiles) per lap of track driven.", "",
             *markdown_table(["target speed (u/s)", "env", "progress", "return", "laps", "lap time (s)",
                              "top speed (u/s)", "exits per lap"], rows), ""]
    args.out.write_text("\n".join(lines))
    args.out.with_suffix(".json").write_text(json.dumps(raw, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
