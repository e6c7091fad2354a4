"""Does the ant's agent see the same thing under MJX-Warp as under MJX-JAX? Every readout field and
the picture, one step at a time, from the states a learned policy visits.

    python experiments/physics_parity.py [--policies expert random] [--starts 2] [--steps 100]
                                         [--fresh 64]
                                         [--out experiments/results/physics_parity.json]

The ant learns less under physics=warp (experiments/results/physics_learning.md), while the packaged
expert scores the same under both (physics_expert.py) and the parity test compares qpos, qvel, tip
and reward on the idp only. A pixel agent sees pictures drawn from the readout's geom_xpos and
geom_xmat, and the ant's reward and observation read cfrc_ext. So: the packaged ant expert (mean
actions), and uniform random actions (a learner's first states), each run `--starts` episodes of
`--steps` steps under physics=jax; from every state visited, the same action is stepped once by
MJX's JAX solver, by MJX-Warp and by MuJoCo C (`mj_step` x frame skip from a fresh MjData, then
`mj_rnePostConstraint`, as Gymnasium does), and the script reports for every `Readout` field the
largest and median |difference| between each pair, the pictures' differences (pixels that differ,
largest channel difference), the reward's and observation's, and Warp's overflow flags.

It also checks three things a learning gap could hide in:
- the stage of the kinematic fields: each physics's stepped geom_xpos against the kinematics of
  its own integrated qpos (0 if fresh; MuJoCo C's RK4 leaves those of its last stage) and, for
  scale, the picture of the state before the step (what a picture one step late would be);
- the reset: `--fresh` starts drawn as the env draws them, put through each physics's forward
  pass: the free joint's quaternion (its norm in qpos), the observation and the picture;
- the contact forces: cfrc_ext, the contact cost and the clipped forces the observation holds.

Warp runs on any platform with warp-lang installed (Warp's CPU path is slow: minutes).
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from hintsjax import envs
from hintsjax.algorithms.experts import load
from hintsjax.envs.ant import TORSO
from hintsjax.envs.physics import LOST_MASK, Readout

HERE = Path(__file__).resolve().parent
OUT = HERE / "results" / "physics_parity.json"
FIELDS = [f for f in Readout.__dataclass_fields__ if f != "overflow"]
PAIRS = (("warp", "jax"), ("jax", "mujoco_c"), ("warp", "mujoco_c"))


def visited_states(env, policy: str, starts: int, steps: int):
    """The LocomotionStates [starts * steps] that `policy` (the packaged expert's mean actions, or
    uniform random actions in [-1, 1]) visits under `env` from `starts` reset keys, and its actions
    [starts * steps, 8] in them."""
    params = env.default_params()
    expert = load("ant") if policy == "expert" else None

    def episode(key):
        def step(ts, k):
            action = (
                expert.mean(ts.obs["state"])
                if expert
                else jax.random.uniform(k, (8,), minval=-1, maxval=1)
            )
            return env.step(key, ts.state, action, params), (ts.state, action)

        _, (states, actions) = jax.lax.scan(
            step, env.reset(key, params), jax.random.split(key, steps)
        )
        return states, actions

    states, actions = jax.jit(jax.vmap(episode))(jax.random.split(jax.random.key(2026), starts))
    return jax.tree.map(lambda x: x.reshape(starts * steps, *x.shape[2:]), (states, actions))


def mujoco_c(mj_model: mujoco.MjModel, qpos, qvel, ctrl, substeps: int) -> dict[str, np.ndarray]:
    """MuJoCo C's readout ([N, ...], float64) of each (qpos, qvel, ctrl) stepped `substeps` times
    from a fresh MjData (0: the forward pass), with mj_rnePostConstraint after, as Gymnasium's
    step."""
    out = {f: [] for f in FIELDS}
    data = mujoco.MjData(mj_model)
    for q, v, c in zip(
        np.asarray(qpos, np.float64), np.asarray(qvel, np.float64), np.asarray(ctrl, np.float64)
    ):
        mujoco.mj_resetData(mj_model, data)
        data.qpos[:], data.qvel[:], data.ctrl[:] = q, v, c
        if substeps:
            mujoco.mj_step(mj_model, data, nstep=substeps)
        else:
            mujoco.mj_forward(mj_model, data)
        mujoco.mj_rnePostConstraint(mj_model, data)
        for f in FIELDS:
            value = np.array(getattr(data, f))
            out[f].append(value.reshape(-1, 3, 3) if f == "geom_xmat" else value)
    return {f: np.stack(v) for f, v in out.items()}


def gaps(a, b) -> dict[str, float]:
    """max and median over states of the largest |a - b| in each state ([N, ...] arrays); {} for a
    field the model has none of (the ant has no sites)."""
    if np.asarray(a).size == 0:
        return {}
    per_state = (
        np.abs(np.asarray(a, np.float64) - np.asarray(b, np.float64))
        .reshape(len(a), -1)
        .max(axis=1)
    )
    return {"max": float(per_state.max()), "median": float(np.median(per_state))}


def picture_gaps(a, b) -> dict[str, float]:
    """How pictures [N, 64, 64, 3] (uint8) differ: the share of pictures with any pixel changed,
    pixels changed per picture (median, max) and the largest channel difference."""
    diff = np.abs(np.asarray(a, np.int32) - np.asarray(b, np.int32))
    changed = (diff.max(axis=-1) > 0).reshape(len(a), -1).sum(axis=1)
    return {
        "pictures_differing": float(np.mean(changed > 0)),
        "pixels_changed_median": float(np.median(changed)),
        "pixels_changed_max": int(changed.max()),
        "largest_channel_difference": int(diff.max()),
    }


def readout_of(physics, qpos, qvel, ctrl, substeps: int) -> dict[str, np.ndarray]:
    """A physics's Readout ([N, ...]) of each (qpos, qvel, ctrl), batched in one call."""
    run = jax.jit(jax.vmap(lambda q, v, c: physics.run(q, v, c, substeps, True)))
    out = jax.block_until_ready(run(qpos, qvel, ctrl))
    return {f: np.asarray(getattr(out, f)) for f in (*FIELDS, "overflow")}


def with_readout(env, state, r: dict[str, np.ndarray]):
    """`state` [N] with the picture's inputs (geom poses, centre of mass) taken from readout `r`."""
    com = np.asarray(env.body_mass) @ r["xipos"] / float(np.sum(env.body_mass))  # [N, 3]
    return state.replace(
        geom_xpos=jnp.asarray(r["geom_xpos"], jnp.float32),
        geom_xmat=jnp.asarray(r["geom_xmat"], jnp.float32),
        com=jnp.asarray(com, jnp.float32),
    )


def compare(policy: str, starts: int, steps: int, fresh: int) -> dict:
    t0 = time.perf_counter()
    env = {p: envs.make("ant", "none", ("state",), physics=p) for p in ("jax", "warp")}
    params, mj_model = env["jax"].default_params(), env["jax"].mj_model
    skip = params.frame_skip
    # the picture reads only the state
    render = jax.jit(jax.vmap(lambda s: env["jax"].render(s, params)))
    states, actions = visited_states(env["jax"], policy, starts, steps)
    n = len(actions)
    ctrl = jnp.clip(actions, *env["jax"].action_range(params))
    row: dict = {
        "env": "ant",
        "policy": policy,
        "states": n,
        "starts": starts,
        "steps": steps,
        "frame_skip": skip,
        "integrator": mujoco.mjtIntegrator(mj_model.opt.integrator).name,
    }

    # one step of each physics from every visited state, the same action
    out = {
        p: readout_of(env[p].physics, states.qpos, states.qvel, ctrl, skip) for p in ("jax", "warp")
    }
    out["mujoco_c"] = mujoco_c(mj_model, states.qpos, states.qvel, ctrl, skip)
    # Warp's repeatability here
    again = readout_of(env["warp"].physics, states.qpos, states.qvel, ctrl, skip)
    row["warp_vs_itself"] = {
        f: gaps(again[f], out["warp"][f])["max"] for f in ("qpos", "qvel", "geom_xpos", "cfrc_ext")
    }
    lost = out["warp"].pop("overflow") & LOST_MASK
    row["warp_worlds_overflowed"] = int(np.sum(lost != 0))
    out["jax"].pop("overflow")
    row["readout"] = {
        f: {f"{a}_vs_{b}": gaps(out[a][f], out[b][f]) for a, b in PAIRS}
        | {"scale_max_abs_jax": float(np.abs(out["jax"][f]).max(initial=0.0))}
        for f in FIELDS
    }

    # what the agent gets: reward, state observation, picture (each env's own transition)
    transition = {
        p: jax.jit(jax.vmap(lambda s, a, e=env[p]: e.transition(jax.random.key(0), s, a, params)))
        for p in env
    }
    stepped = {p: jax.block_until_ready(transition[p](states, actions)) for p in env}
    row["reward"] = gaps(stepped["warp"].reward, stepped["jax"].reward)
    row["obs"] = gaps(stepped["warp"].state.obs, stepped["jax"].state.obs)
    row["terminated_disagree"] = int(
        np.sum(np.asarray(stepped["warp"].terminated) != np.asarray(stepped["jax"].terminated))
    )
    cost = {p: 5e-4 * np.sum(np.clip(out[p]["cfrc_ext"], -1, 1) ** 2, axis=(1, 2)) for p in out}
    row["contact_cost"] = {f"{a}_vs_{b}": gaps(cost[a], cost[b]) for a, b in PAIRS} | {
        "mean_jax": float(cost["jax"].mean())
    }
    clipped = {p: np.asarray(np.clip(out[p]["cfrc_ext"], -1, 1)) for p in out}
    row["cfrc_ext_clipped"] = {f"{a}_vs_{b}": gaps(clipped[a], clipped[b]) for a, b in PAIRS}
    # [N] bodies in contact
    touching = {p: np.sum(np.any(out[p]["cfrc_ext"] != 0, axis=-1), axis=-1) for p in out}
    row["states_with_contact"] = {p: int(np.sum(t > 0)) for p, t in touching.items()}
    row["bodies_in_contact_mean"] = {p: float(np.mean(t)) for p, t in touching.items()}
    pictures = {p: np.asarray(render(stepped[p].state)) for p in env}
    pictures["mujoco_c"] = np.asarray(
        render(with_readout(env["jax"], stepped["jax"].state, out["mujoco_c"]))
    )
    row["picture"] = {f"{a}_vs_{b}": picture_gaps(pictures[a], pictures[b]) for a, b in PAIRS}
    # for scale: the picture one step late (the state the step started from)
    row["picture"]["jax_vs_one_step_late"] = picture_gaps(
        pictures["jax"], np.asarray(render(states))
    )

    # the stage of the kinematic fields: each physics's stepped geom_xpos against a forward pass
    # at its own integrated state (0: fresh), and against the other physics's
    fresh_at = {
        p: readout_of(
            env[p].physics,
            out[p]["qpos"].astype(np.float32),
            out[p]["qvel"].astype(np.float32),
            np.zeros_like(ctrl),
            0,
        )
        for p in env
    }
    fresh_at["mujoco_c"] = mujoco_c(
        mj_model, out["mujoco_c"]["qpos"], out["mujoco_c"]["qvel"], np.zeros(ctrl.shape), 0
    )
    # the last substep's start
    before = mujoco_c(mj_model, states.qpos, states.qvel, ctrl, skip - 1)
    last_start = mujoco_c(mj_model, before["qpos"], before["qvel"], np.zeros(ctrl.shape), 0)
    row["stage"] = {
        "stepped_vs_forward_at_own_new_qpos": {
            p: {f: gaps(out[p][f], fresh_at[p][f]) for f in ("geom_xpos", "xpos")} for p in out
        },
        "mujoco_c_stepped_vs_forward_at_last_substep_start": {
            f: gaps(out["mujoco_c"][f], last_start[f]) for f in ("geom_xpos", "xpos")
        },
        "torso_xpos_vs_qpos": {
            p: gaps(out[p]["xpos"][:, TORSO], out[p]["qpos"][:, :3]) for p in out
        },
    }
    fresh_pictures = {
        p: np.asarray(render(with_readout(env["jax"], stepped[p].state, fresh_at[p]))) for p in env
    }
    row["stage"]["picture_stepped_vs_fresh"] = {
        p: picture_gaps(pictures[p], fresh_pictures[p]) for p in env
    }

    # the reset: fresh starts drawn as the env draws them, through each physics's forward pass
    keys = jax.random.split(jax.random.key(7), fresh)
    qpos0, qvel0 = jax.vmap(lambda k: env["jax"].draw_start(k, params))(keys)
    at = {p: jax.block_until_ready(jax.jit(jax.vmap(env[p].state_at))(qpos0, qvel0)) for p in env}
    quat_norm = lambda q: np.linalg.norm(np.asarray(q)[:, 3:7], axis=-1)  # noqa: E731
    row["reset"] = {
        "drawn_quaternion_norm": {
            "min": float(quat_norm(qpos0).min()),
            "max": float(quat_norm(qpos0).max()),
        },
        **{
            f"{p}_qpos_quaternion_norm": {
                "min": float(quat_norm(at[p].qpos).min()),
                "max": float(quat_norm(at[p].qpos).max()),
            }
            for p in env
        },
        "qpos": gaps(at["warp"].qpos, at["jax"].qpos),
        "obs": gaps(at["warp"].obs, at["jax"].obs),
        "geom_xpos": gaps(at["warp"].geom_xpos, at["jax"].geom_xpos),
        "geom_xmat": gaps(at["warp"].geom_xmat, at["jax"].geom_xmat),
        "picture": picture_gaps(np.asarray(render(at["warp"])), np.asarray(render(at["jax"]))),
    }
    first = {p: jax.block_until_ready(transition[p](at[p], jnp.zeros((fresh, 8)))) for p in env}
    row["reset"]["first_step_from_each_own_reset"] = {
        "qpos": gaps(first["warp"].state.qpos, first["jax"].state.qpos),
        "reward": gaps(first["warp"].reward, first["jax"].reward),
        "picture": picture_gaps(
            np.asarray(render(first["warp"].state)), np.asarray(render(first["jax"].state))
        ),
    }
    row["seconds"] = round(time.perf_counter() - t0, 1)
    return row


def main() -> None:
    parser = argparse.ArgumentParser(description=" ".join(__doc__.split("\n\n")[0].split()))
    parser.add_argument(
        "--policies",
        nargs="+",
        choices=("expert", "random"),
        default=["expert", "random"],
        help="whose states: the packaged expert's (mean actions), uniform random "
        "actions' (default: both)",
    )
    parser.add_argument(
        "--starts",
        type=int,
        default=2,
        help="episodes of each policy under physics=jax (default: 2)",
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=100,
        help="steps of each, every one a compared state (default: 100)",
    )
    parser.add_argument("--fresh", type=int, default=64, help="reset states compared (default: 64)")
    parser.add_argument(
        "--out",
        type=Path,
        default=OUT,
        help=f"the JSON written (default: {OUT.relative_to(HERE.parent)})",
    )
    args = parser.parse_args()
    rows = []
    for policy in args.policies:
        row = compare(policy, args.starts, args.steps, args.fresh)
        row.update(
            device=jax.devices()[0].device_kind,
            jax_version=jax.__version__,
            mujoco_version=mujoco.__version__,
            command=f"python experiments/physics_parity.py --policies {policy} "
            f"--starts {args.starts} --steps {args.steps} --fresh {args.fresh}",
        )
        rows.append(row)
        print(json.dumps(row, indent=1), flush=True)
        args.out.write_text(json.dumps({"rows": rows}, indent=1) + "\n")


if __name__ == "__main__":
    main()
