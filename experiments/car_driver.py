"""Our car against Gymnasium's CarRacing-v3 under one scripted driver, on Gymnasium's own tracks (issues 26, 50).

    python experiments/car_driver.py [--tracks 10] [--speeds 30,60,90]
        # -> experiments/results/car_driver.md, .json

The driver is pure pursuit on the track's centre line: it steers towards the centre point
LOOKAHEAD points past the nearest one (steer = -GAIN x the angle to it, clipped to [-1, 1]; +1
turns right in both envs), and holds a target speed with gas 0.5 below it and brake 0.3 above
1.1 x it. The same numpy function drives both envs on the same tracks: Gymnasium's
`reset(seed=s)` for s = 0..tracks-1, whose `env.unwrapped.track` is loaded into our Track
(`car_racing.track_from_gymnasium`); both cars start at its first centre point, for 1000 steps or
until the episode ends. Per target speed: tiles visited (progress), return (and per track in the
json), laps completed and their time, top speed, and how often the car leaves the road (all four
wheels off the tiles) per lap of track. Then our visit rules are replayed along Gymnasium's
driven trajectories and their counts of visited tiles compared with Gymnasium's (`visit_rule_gap`).
"""  # noqa: E501

from __future__ import annotations

import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from hintsjax.reproduce.markdown import markdown_table

RESULTS = Path(__file__).resolve().parent / "results"
LOOKAHEAD = 5  # centre points (about 3.5 u each) ahead of the nearest
GAIN = 2.0
STEPS = 1000


def pursue(
    xy: np.ndarray,
    angle: np.ndarray,
    speed: np.ndarray,
    track: list[np.ndarray],
    target_speed: float,
) -> np.ndarray:
    """Actions [B, 3] (steer, gas, brake) for cars at xy [B, 2], heading angle [B] (forward is
    (-sin, cos)), speed [B], on tracks given as centre points [n_b, 2] each."""
    actions = np.zeros((len(xy), 3), np.float32)
    for b, points in enumerate(track):
        j = int(np.argmin(np.sum((points - xy[b]) ** 2, axis=1)))
        rel = points[(j + LOOKAHEAD) % len(points)] - xy[b]
        fwd = np.array([-np.sin(angle[b]), np.cos(angle[b])])
        left = np.array([-np.cos(angle[b]), -np.sin(angle[b])])
        bearing = np.arctan2(rel @ left, rel @ fwd)  # + : the target is to the left
        actions[b] = [
            np.clip(-GAIN * bearing, -1, 1),
            0.5 * (speed[b] < target_speed),
            0.3 * (speed[b] > 1.1 * target_speed),
        ]
    return actions


def summarize(progress, returns, lap_steps, top_speed, exits) -> dict:
    laps = np.isfinite(lap_steps)
    return {
        "progress": float(np.mean(progress)),
        "progress_std": float(np.std(progress)),
        "return": float(np.mean(returns)),
        "return_std": float(np.std(returns)),
        "laps": int(laps.sum()),
        "lap_seconds": float(np.mean(lap_steps[laps]) / 50) if laps.any() else None,
        "top_speed": float(np.mean(top_speed)),
        "exits_per_lap": float(np.mean(exits / np.maximum(progress, 1e-3))),
        "returns": [round(float(r), 1) for r in returns],
    }


@dataclass(frozen=True)
class GymnasiumEpisodes:
    """The driver's episodes on Gymnasium's car: the summary, and per seed its track (float[n, 4]:
    alpha, beta, x, y per centre point), the hull's pose per frame (float[T, 4]: x, y, angle, the
    front wheels' angle) and the tiles it had visited after each frame (int[T])."""

    summary: dict
    tracks: list[np.ndarray]
    poses: list[np.ndarray]
    visited: list[np.ndarray]


def gymnasium_tracks(seeds: range) -> list[np.ndarray]:
    """Gymnasium's tracks for `reset(seed=s)`, each float[n, 4] (alpha, beta, x, y per centre
    point)."""
    import gymnasium as gym

    env = gym.make("CarRacing-v3", continuous=True)
    tracks = []
    for seed in seeds:
        env.reset(seed=seed)
        tracks.append(np.array(env.unwrapped.track))
    env.close()
    return tracks


def drive_gymnasium(seeds: range, target_speed: float) -> GymnasiumEpisodes:
    import gymnasium as gym

    env = gym.make("CarRacing-v3", continuous=True)
    progress, returns, lap_steps, top, exits, tracks, poses, visits = [], [], [], [], [], [], [], []
    for seed in seeds:
        env.reset(seed=seed)
        u = env.unwrapped
        tracks.append(np.array(u.track))
        points = tracks[-1][:, 2:4]
        total, fastest, off_before, out, lap, pose, visited = 0.0, 0.0, False, 0, np.inf, [], []
        for t in range(STEPS):
            hull = u.car.hull
            speed = float(np.linalg.norm(hull.linearVelocity))
            action = pursue(
                np.array([[hull.position[0], hull.position[1]]]),
                np.array([hull.angle]),
                np.array([speed]),
                [points],
                target_speed,
            )[0]
            _, reward, terminated, truncated, _ = env.step(action)
            pose.append(
                [hull.position[0], hull.position[1], hull.angle, u.car.wheels[0].joint.angle]
            )
            visited.append(u.tile_visited_count)
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
        poses.append(np.array(pose))
        visits.append(np.array(visited))
    env.close()
    summary = summarize(
        np.array(progress), np.array(returns), np.array(lap_steps), np.array(top), np.array(exits)
    )
    return GymnasiumEpisodes(summary, tracks, poses, visits)


def stack_tracks(tracks: list[np.ndarray]):
    """Gymnasium's tracks as one batched Track (car_racing.track_from_gymnasium each)."""
    import jax
    import jax.numpy as jnp

    from hintsjax.envs.car_racing import track_from_gymnasium

    return jax.tree.map(lambda *a: jnp.stack(a), *(track_from_gymnasium(t) for t in tracks))


def our_tracks(count: int):
    """Our generator's tracks for the keys 0..count-1, batched."""
    import jax
    import jax.numpy as jnp

    from hintsjax.envs.car_racing import VARIANTS, generate_track

    keys = jnp.stack([jax.random.key(i) for i in range(count)])
    return jax.jit(jax.vmap(generate_track, in_axes=(0, None)))(keys, VARIANTS["standard"])


def drive_ours(tracks, target_speed: float) -> dict:
    """The driver on our car on a batch of Tracks, each from Gymnasium's start (its first centre
    point)."""
    import jax
    import jax.numpy as jnp

    from hintsjax import envs
    from hintsjax.envs import car_racing as car

    env = envs.make("car_racing", observe=("state",))
    params = envs.make_params("car_racing")
    count = int(tracks.n_tiles.shape[0])

    def start(track):
        return car.CarRacingState(
            track,
            car.Car.at(track.xy[0], track.beta[0]),
            jnp.zeros(car.MAX_TILES, bool),
            jnp.zeros((), jnp.int32),
        )

    state = jax.jit(jax.vmap(start))(tracks)

    @jax.jit
    def step(state, action):
        def one(s, a):
            out = env.transition(jax.random.key(0), s, a, params)
            off = ~car.wheel_contact(s.track, out.state.car).on_road.any()
            return out.state.replace(t=s.t + 1), out.reward, out.terminated, off

        return jax.vmap(one)(state, action)

    n = np.asarray(state.track.n_tiles)
    points = [np.asarray(state.track.xy[b, : n[b]]) for b in range(count)]
    alive = np.ones(count, bool)
    total, fastest, out, off_before = (
        np.zeros(count),
        np.zeros(count),
        np.zeros(count),
        np.zeros(count, bool),
    )
    lap = np.full(count, np.inf)
    for t in range(STEPS):
        c = state.car
        speed = np.linalg.norm(np.asarray(c.vel), axis=1)
        action = pursue(np.asarray(c.xy), np.asarray(c.angle), speed, points, target_speed)
        new_state, reward, done, off = step(state, jnp.asarray(action))
        state = jax.tree.map(
            lambda a, b: jnp.where(alive.reshape(-1, *[1] * (a.ndim - 1)), a, b), new_state, state
        )
        reward, done, off = np.asarray(reward), np.asarray(done), np.asarray(off)
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


def visit_rule_gap(episodes: GymnasiumEpisodes) -> dict:
    """Our visit rules replayed along Gymnasium's driven trajectories: per frame, our count of
    visited tiles less Gymnasium's, for the wheel rule (car_racing.wheel_contact) and the centre
    rule (the tile holding the car's centre, the rule before issue 50): mean, mean |.|, max |.| over
    all frames."""
    import jax
    import jax.numpy as jnp

    from hintsjax.envs import car_racing as car

    @jax.jit
    def replay(track, poses):
        def frame(visited, pose):
            c = car.Car.at(pose[:2], pose[2], steer=pose[3])
            contact = car.wheel_contact(track, c)
            wheels = visited[0].at[contact.tiles].set(visited[0][contact.tiles] | contact.touched)
            tile, on = car.tile_at(track, c.xy)
            centre = visited[1].at[tile].set(visited[1][tile] | on)
            return (wheels, centre), (wheels.sum(), centre.sum())

        empty = jnp.zeros(car.MAX_TILES, bool)
        return jax.lax.scan(frame, (empty, empty), poses)[1]

    gaps = {"wheels": [], "centre": []}
    for track, poses, visited in zip(episodes.tracks, episodes.poses, episodes.visited):
        wheels, centre = replay(car.track_from_gymnasium(track), jnp.asarray(poses, jnp.float32))
        gaps["wheels"].append(np.asarray(wheels) - visited)
        gaps["centre"].append(np.asarray(centre) - visited)
    out = {}
    for rule, parts in gaps.items():
        d = np.concatenate(parts)
        final = np.array([p[-1] for p in parts])
        out[rule] = {
            "mean": float(d.mean()),
            "mean_abs": float(np.abs(d).mean()),
            "max_abs": int(np.abs(d).max()),
            "final_mean_abs": float(np.abs(final).mean()),
            "frames": int(len(d)),
        }
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--tracks", type=int, default=10, help="Gymnasium's seeds 0..tracks-1")
    parser.add_argument("--speeds", default="30,60,90")
    parser.add_argument("--out", type=Path, default=RESULTS / "car_driver.md")
    args = parser.parse_args()
    seeds = range(args.tracks)
    rows, gap_rows, track_rows, raw = [], [], [], {}
    for target in [float(s) for s in args.speeds.split(",")]:
        start = time.perf_counter()
        episodes = drive_gymnasium(seeds, target)
        theirs = {**episodes.summary, "seconds": round(time.perf_counter() - start, 1)}
        start = time.perf_counter()
        ours = {
            **drive_ours(stack_tracks(episodes.tracks), target),
            "seconds": round(time.perf_counter() - start, 1),
        }
        gap = visit_rule_gap(episodes)
        ratio = ours["return"] / theirs["return"] - 1
        raw[f"{target:.0f}"] = {
            "gymnasium": theirs,
            "ours": ours,
            "return_difference": ratio,
            "visited_tiles_gap": gap,
        }
        print(target, raw[f"{target:.0f}"], flush=True)
        for name, r in (
            ("Gymnasium CarRacing-v3 (Box2D)", theirs),
            ("ours (hintsjax car_racing)", ours),
        ):
            rows.append(
                [
                    f"{target:.0f}",
                    name,
                    f"{r['progress']:.3f} ± {r['progress_std']:.3f}",
                    f"{r['return']:.0f} ± {r['return_std']:.0f}",
                    f"{r['laps']}/{args.tracks}",
                    "-" if r["lap_seconds"] is None else f"{r['lap_seconds']:.1f}",
                    f"{r['top_speed']:.1f}",
                    f"{r['exits_per_lap']:.2f}",
                ]
            )
        rows.append(
            [f"{target:.0f}", "ours / Gymnasium - 1", "", f"{100 * ratio:+.1f} %", "", "", "", ""]
        )
        for name, r in (("Gymnasium", theirs), ("ours", ours)):
            track_rows.append([f"{target:.0f}", name] + [f"{x:.0f}" for x in r["returns"]])
        for rule, g in gap.items():
            gap_rows.append(
                [
                    f"{target:.0f}",
                    rule,
                    f"{g['mean']:+.2f}",
                    f"{g['mean_abs']:.2f}",
                    str(g["max_abs"]),
                    f"{g['final_mean_abs']:.2f}",
                    str(g["frames"]),
                ]
            )
    lines = [
        "# The scripted driver on Gymnasium's car and on ours, on Gymnasium's tracks",
        "",
        f"Made by `python experiments/car_driver.py --tracks {args.tracks} --speeds {args.speeds}` "
        f"on the 2-core CPU development machine, {time.strftime('%Y-%m-%d', time.gmtime())} "
        f"(Gymnasium 1.4.0 with Box2D 2.3.10). Both envs drive the same {args.tracks} tracks: "
        f"Gymnasium's `reset(seed=s)` for s = 0..{args.tracks - 1}, loaded into our Track "
        "(`car_racing.track_from_gymnasium`), each car from Gymnasium's start. Pure pursuit on the "
        f"centre line ({LOOKAHEAD} points ahead, gain {GAIN}), a target speed held by gas 0.5 / "
        "brake 0.3, 1000 steps at most. Progress: tiles visited / all (mean ± std over tracks); "
        "laps: episodes ended by a completed lap, and their mean time; exits: times all four "
        "wheels left the tiles, per lap of track driven.",
        "",
        *markdown_table(
            [
                "target speed (u/s)",
                "env",
                "progress",
                "return",
                "laps",
                "lap time (s)",
                "top speed (u/s)",
                "exits per lap",
            ],
            rows,
        ),
        "",
        "## Return per track",
        "",
        *markdown_table(["target speed (u/s)", "env"] + [f"seed {s}" for s in seeds], track_rows),
        "",
        "## Visited tiles along Gymnasium's trajectories",
        "",
        "Gymnasium's car is driven as above; after every frame its hull's pose and front-wheel "
        "angle are replayed into our visit rules on the same track, and our count of visited tiles "
        "is compared with Gymnasium's `tile_visited_count`. wheels: a tile is visited when a "
        "corner of a wheel's box lies in its quad (`car_racing.wheel_contact`, the env's rule); "
        "centre: when the car's centre lies in it (the env's rule before issue 50). Difference = "
        "ours - Gymnasium's, in tiles, over every frame of every track; final: at the episode's "
        "last frame.",
        "",
        *markdown_table(
            [
                "target speed (u/s)",
                "rule",
                "mean difference",
                "mean abs difference",
                "max abs difference",
                "final mean abs difference",
                "frames",
            ],
            gap_rows,
        ),
        "",
    ]
    args.out.write_text("\n".join(lines))
    args.out.with_suffix(".json").write_text(json.dumps(raw, indent=1))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
