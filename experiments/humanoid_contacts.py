"""Where a Humanoid step's cost goes, and whether pruning collision pairs could cut it.

    python experiments/humanoid_contacts.py [--envs 64] [--poses 30000] [--no-steps]

pairs   the robot's self-collision candidates (contype/conaffinity compatible, different bodies,
        not parent and child: what MuJoCo and MJX test), and each pair's smallest distance over
        poses drawn in the joint ranges (30% of joints at a limit) by MuJoCo C's mj_geomDistance.
        A pair that never comes near could be excluded without changing the dynamics.
steps   env steps/s of the jitted, vmapped transition (a scan of 5 steps, after a compile call)
        as it is (Euler), with the file's RK4, with contacts disabled, and with floor contacts
        only (the last two change Humanoid-v5's dynamics: they bound what contacts cost, they
        are not options).
"""

from __future__ import annotations

import argparse
import time

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from hintsjax import envs
from hintsjax.envs.humanoid import Humanoid
from hintsjax.envs.physics import JaxPhysics, capacities


def self_pairs(m: mujoco.MjModel) -> list[tuple[int, int]]:
    pairs = []
    for a in range(m.ngeom):
        for b in range(a + 1, m.ngeom):
            ba, bb = m.geom_bodyid[a], m.geom_bodyid[b]
            if 0 in (ba, bb) or ba == bb or m.body_parentid[ba] == bb or m.body_parentid[bb] == ba:
                continue
            if (m.geom_contype[a] & m.geom_conaffinity[b]) or (
                m.geom_contype[b] & m.geom_conaffinity[a]
            ):
                pairs.append((a, b))
    return pairs


def closest_approach(m: mujoco.MjModel, pairs, poses: int, seed: int = 0) -> np.ndarray:
    """Each pair's smallest distance (m; negative: overlap) over `poses` sampled joint poses."""
    d, rng, fromto = mujoco.MjData(m), np.random.default_rng(seed), np.zeros(6)
    hinges = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE]
    lo, hi, adr = m.jnt_range[hinges, 0], m.jnt_range[hinges, 1], m.jnt_qposadr[hinges]
    closest = np.full(len(pairs), np.inf)
    for _ in range(poses):
        u = rng.uniform(size=len(hinges))
        u = np.where(rng.uniform(size=len(hinges)) < 0.3, np.round(u), u)
        d.qpos[:] = m.qpos0
        d.qpos[adr] = lo + (hi - lo) * u
        mujoco.mj_kinematics(m, d)
        for k, (a, b) in enumerate(pairs):
            closest[k] = min(closest[k], mujoco.mj_geomDistance(m, d, a, b, 0.5, fromto))
    return closest


def rk4(m: mujoco.MjModel) -> None:
    # humanoid.xml's own (envs/humanoid.py uses Euler)
    m.opt.integrator = mujoco.mjtIntegrator.mjINT_RK4


def no_contacts(m: mujoco.MjModel) -> None:
    m.opt.disableflags |= mujoco.mjtDisableBit.mjDSBL_CONTACT


def floor_only(m: mujoco.MjModel) -> None:
    m.geom_contype[:] = 2
    m.geom_conaffinity[:] = 0
    m.geom_contype[0], m.geom_conaffinity[0] = 0, 2  # geom 0 is the floor


def steps_per_second(change, n: int, steps: int = 5) -> tuple[float, int]:
    """(env steps/s, MJX contact slots) of Humanoid's transition with `change` applied to its
    model."""
    env = Humanoid(envs.make_hint("humanoid", "velocity"))
    model = env.make_mj_model()
    if change:
        change(model)
    env.physics = JaxPhysics(model)
    params, keys = env.default_params(), jax.random.split(jax.random.key(0), n)
    state = jax.vmap(lambda k: env.initial_state(k, params))(keys)
    action = jnp.zeros((n, env.action_size))
    step = jax.vmap(lambda k, s, a: env.transition(k, s, a, params).state)
    run = jax.jit(
        lambda s: jax.lax.scan(lambda s, _: (step(keys, s, action), None), s, None, steps)[0]
    )
    jax.block_until_ready(run(state))
    t = time.perf_counter()
    jax.block_until_ready(run(state))
    return n * steps / (time.perf_counter() - t), capacities(model)[0]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", type=int, default=64)
    parser.add_argument("--poses", type=int, default=30_000)
    parser.add_argument("--no-steps", action="store_true", help="only the pair distances")
    args = parser.parse_args()

    m = Humanoid.make_mj_model()
    pairs = self_pairs(m)
    closest = closest_approach(m, pairs, args.poses)
    for cm in (1, 5, 10):
        print(
            f"{np.sum(closest > cm / 100)} of {len(pairs)} self pairs never come within {cm} cm "
            f"({args.poses} poses)",
            flush=True,
        )
    if args.no_steps:
        return
    rows = (
        ("as it is", None),
        ("RK4", rk4),
        ("contacts off", no_contacts),
        ("floor contacts only", floor_only),
    )
    for name, change in rows:
        rate, slots = steps_per_second(change, args.envs)
        print(
            f"{name:>20}: {rate:8.0f} env steps/s ({args.envs} envs, {slots} contact slots, "
            f"{jax.devices()[0].platform})",
            flush=True,
        )


if __name__ == "__main__":
    main()
