"""How far each locomotion task is from Gymnasium v5, per solver setting and physics, and what each costs.

    python experiments/fidelity.py [--envs halfcheetah,ant,humanoid] [--physics jax,warp]
                                   [--settings newton_4_8,newton_8_16,...] [--states 200]
                                   [--cost] [--cost-updates 40] [--experts 60]
                                   [--out experiments/results/fidelity.json]
    python experiments/fidelity.py --report      # experiments/results/fidelity.md from the JSON

Issue 50 asks for the most faithful solver settings whose training costs at most 1.5x today's.
Three measures, each a row of the JSON (a rerun replaces the rows it measures and keeps the rest):

  one_step  Along Gymnasium's own trajectories, from three sources of states: `random` (uniform
            in-range actions), `saturated` (each action at +-1 of its range, signs drawn afresh
            every step) and `expert` (the env's packaged expert, closed loop, on Gymnasium).
            Episodes run up to HORIZON steps; every STRIDE-th step is kept. From each kept state
            (rounded to float32, as tests/envs/gym_parity.py does) and its action, one control step
            of (a) MuJoCo C with the setting (float64: the setting's own share of the error) and
            (b) MJX with the setting (`--physics`: MJX's JAX solver, MJX-Warp) is compared with
            Gymnasium as shipped: per state the largest |d qvel| and the |d reward|; the row gives
            their maximum, 99th percentile and mean over states, and the steps whose termination
            differs. `<physics>_vs_mujoco_c` compares MJX with MuJoCo C at the same setting: the
            implementation's own share.
  cost      (`--cost`) Training env steps/s of the env's default cell (hints/fc with its default
            hint, the env's training settings, 5 seeds): the command's compiled training chunks
            back to back for `--cost-updates` updates (`cost_row`). The traced-program cache is
            off (a setting changes the program but not its source).
  expert    (`--experts N`) The packaged expert, mean actions, N full episodes from the same
            starts (our reset's qpos and qvel, set into Gymnasium's env) on our env with the
            setting and on Gymnasium v5 as shipped: mean return [95 % bootstrap CI], falls, and
            ours - Gymnasium [95 % CI, episodes resampled independently].

A setting is a set of `mj_model.opt` overrides on top of the env's registered class; a row's
`default` says whether they are what the class registers. See SETTINGS.
"""  # noqa: E501

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import sys
import time
from pathlib import Path

import gymnasium as gym
import jax
import jax.numpy as jnp
import mujoco
import numpy as np

from hintsjax import envs
from hintsjax.system import xla_flags
from hintsjax.algorithms.experts import load
from hintsjax.reproduce import stats

HERE = Path(__file__).resolve().parent
OUT = HERE / "results" / "fidelity.json"
GYM_IDS = {
    "halfcheetah": "HalfCheetah-v5",
    "ant": "Ant-v5",
    "ant_fast": "Ant-v5",
    "humanoid": "Humanoid-v5",
}
EXPERTS = {"ant_fast": "ant"}  # ant_fast (the ant's body, cheaper physics) has no expert of its own
SOURCES = ("random", "saturated", "expert")
HORIZON, STRIDE = 500, 5
KEY = jax.random.key(0)

NEWTON, CG = mujoco.mjtSolver.mjSOL_NEWTON, mujoco.mjtSolver.mjSOL_CG
EULER, RK4 = mujoco.mjtIntegrator.mjINT_EULER, mujoco.mjtIntegrator.mjINT_RK4
ELLIPTIC = mujoco.mjtCone.mjCONE_ELLIPTIC


def newton(iterations: int, ls_iterations: int, **more) -> dict:
    return dict(solver=NEWTON, iterations=iterations, ls_iterations=ls_iterations, **more)


# Candidate settings per env, each the `mj_model.opt` fields set on top of the env's registered
# class (the row's `default` says whether they are what the class registers). Gymnasium's files:
# HalfCheetah Euler, Ant RK4, both with MuJoCo's default Newton (100 iterations, 50 line-search
# steps); Humanoid RK4 with PGS at 50 iterations, which MJX does not offer (its solvers are CG and
# Newton; every converged solver solves the same convex problem).
NEWTONS = {f"newton_{i}_{ls}": newton(i, ls) for i, ls in ((4, 8), (8, 16), (16, 32), (100, 50))}
SETTINGS = {
    "halfcheetah": NEWTONS,
    # elliptic friction cones instead of the file's pyramidal ones: MJX's pyramid is oriented
    # unlike MuJoCo C's (tests/envs/test_locomotion.py), its elliptic cones match C's to 0.018
    "ant": {
        **NEWTONS,
        "elliptic_newton_8_16": newton(8, 16, cone=ELLIPTIC),
        "elliptic_newton_100_50": newton(100, 50, cone=ELLIPTIC),
    },
    "ant_fast": {"ant_fast": {}},
    "humanoid": {
        **{f"euler_{k}": {**v, "integrator": EULER} for k, v in NEWTONS.items()},
        **{
            f"rk4_newton_{i}_{ls}": newton(i, ls, integrator=RK4)
            for i, ls in ((4, 8), (8, 16), (16, 32), (100, 50))
        },
        "rk4_cg_50": dict(solver=CG, iterations=50, ls_iterations=50, integrator=RK4),
    },
}


def env_class(name: str, setting: str) -> type:
    cls = envs.REGISTRY[name].cls
    options = SETTINGS[name][setting]
    return cls.with_options(**options) if options else cls


def described(name: str, setting: str) -> dict:
    """The setting's name, its options in full, and whether they are the registered env's."""
    options = env_class(name, setting).options
    return {
        "setting": setting,
        "options": {k: (v.name if hasattr(v, "name") else v) for k, v in options.items()},
        "default": options == envs.REGISTRY[name].cls.options,
    }


# -- Gymnasium's trajectories ----------------------------------------------------------------------


@dataclasses.dataclass
class Records:
    """Kept states of Gymnasium's trajectories (float32-rounded), the action taken from each, and
    what Gymnasium as shipped computed for that step."""

    qpos: np.ndarray
    qvel: np.ndarray
    action: np.ndarray
    next_qvel: np.ndarray
    reward: np.ndarray
    terminated: np.ndarray


def f32(x) -> np.ndarray:
    return np.asarray(x, np.float32).astype(np.float64)


def gym_records(name: str, source: str, states: int, seed: int = 0) -> Records:
    """`states` kept states of Gymnasium-as-shipped trajectories driven by `source`."""
    env = gym.make(GYM_IDS[name]).unwrapped
    rng = np.random.default_rng(seed)
    low, high = env.action_space.low, env.action_space.high
    expert = jax.jit(load(EXPERTS.get(name, name)).mean) if source == "expert" else None
    kept: dict[str, list] = {f.name: [] for f in dataclasses.fields(Records)}
    episode, t, obs = 0, 0, None
    while len(kept["qpos"]) < states:
        if obs is None or t == HORIZON:
            obs, _ = env.reset(seed=seed * 10_000 + episode)
            episode, t = episode + 1, 0
        qpos, qvel = f32(env.data.qpos), f32(env.data.qvel)
        env.set_state(qpos, qvel)
        obs = env._get_obs()
        if source == "random":
            action = rng.uniform(low, high)
        elif source == "saturated":
            action = np.where(rng.random(low.shape) < 0.5, low, high)
        else:
            action = np.clip(np.asarray(expert(jnp.asarray(obs, jnp.float32))), low, high)
        action = action.astype(np.float32)
        obs, reward, terminated, _, _ = env.step(action)
        if t % STRIDE == 0:
            for field, value in zip(
                kept, (qpos, qvel, action, env.data.qvel.copy(), reward, terminated)
            ):
                kept[field].append(value)
        t += 1
        if terminated:
            obs = None
    return Records(**{k: np.asarray(v) for k, v in kept.items()})


def mujoco_c_step(name: str, cls, records: Records) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MuJoCo C (float64) with the setting's model from each kept state: (qvel, reward,
    terminated)."""
    env = gym.make(GYM_IDS[name]).unwrapped
    cls.adapt(env.model)
    qvel, reward, terminated = [], [], []
    for i in range(len(records.qpos)):
        env.set_state(records.qpos[i], records.qvel[i])
        _, r, term, _, _ = env.step(records.action[i])
        qvel.append(env.data.qvel.copy())
        reward.append(r)
        terminated.append(term)
    return np.asarray(qvel), np.asarray(reward), np.asarray(terminated)


def mjx_step(cls, physics: str, records: Records) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """MJX (`physics`) with the setting from each kept state, all states in one vmapped call."""
    env = cls(envs.make_hint(cls.name, envs.NO_HINT), ("state",), physics)
    params = env.default_params()
    step = jax.jit(jax.vmap(lambda q, v, a: env.transition(KEY, env.state_at(q, v), a, params)))
    out = step(
        jnp.asarray(records.qpos, jnp.float32),
        jnp.asarray(records.qvel, jnp.float32),
        jnp.asarray(records.action),
    )
    return (
        np.asarray(out.state.qvel, np.float64),
        np.asarray(out.reward, np.float64),
        np.asarray(out.terminated),
    )


def errors(records: Records, qvel: np.ndarray, reward: np.ndarray, terminated: np.ndarray) -> dict:
    dq = np.abs(qvel - records.next_qvel).max(axis=1)
    dr = np.abs(reward - records.reward)

    def summary(x):
        return {
            "max": float(x.max()),
            "p99": float(np.percentile(x, 99)),
            "mean": float(x.mean()),
        }

    return {
        "qvel": summary(dq),
        "reward": summary(dr),
        "termination_differs": int((terminated != records.terminated).sum()),
        "nonfinite": int((~np.isfinite(dq)).sum()),
    }


def one_step_rows(name: str, settings: list[str], physics: list[str], states: int) -> list[dict]:
    """Rows per (setting, source); each setting's MJX step compiles once, for every source's
    states."""
    records = {source: gym_records(name, source, states) for source in SOURCES}
    every = Records(
        *(
            np.concatenate([getattr(r, f.name) for r in records.values()])
            for f in dataclasses.fields(Records)
        )
    )
    part = lambda x, i: x[i * states : (i + 1) * states]  # noqa: E731  source i's share of an all-sources result
    rows = []
    for setting in settings:
        cls = env_class(name, setting)
        stepped = {"mujoco_c": mujoco_c_step(name, cls, every)}
        seconds = {}
        for p in physics:
            start = time.perf_counter()
            stepped[p] = mjx_step(cls, p, every)
            seconds[p] = round(time.perf_counter() - start, 1)
        for i, (source, rec) in enumerate(records.items()):
            row = {
                "measure": "one_step",
                "env": name,
                **described(name, setting),
                "source": source,
                "states": states,
                "mean_abs_reward": float(np.abs(rec.reward).mean()),
                "mean_abs_qvel": float(np.abs(rec.next_qvel).mean()),
            }
            for side, out in stepped.items():
                row[side] = errors(rec, *(part(x, i) for x in out))
                if side in seconds:
                    row[side]["seconds"] = seconds[side]
            c_qvel, c_reward, c_terminated = (part(x, i) for x in stepped["mujoco_c"])
            as_c = dataclasses.replace(
                rec, next_qvel=c_qvel, reward=c_reward, terminated=c_terminated
            )
            for p in physics:
                row[f"{p}_vs_mujoco_c"] = errors(as_c, *(part(x, i) for x in stepped[p]))
            rows.append(row)
            print(json.dumps(row), flush=True)
    return rows


# -- training cost ---------------------------------------------------------------------------------


def cost_row(name: str, setting: str, physics: str, updates: int, seeds: int = 5) -> dict:
    """Training env steps/s of the env's default cell with the setting: the training program
    that `python -m hintsjax.run` compiles (chunks of 10 updates), called back to back after a
    warm-up chunk, nothing else on the host (experiments/bench.py's `scan_env_steps_per_s`;
    the command delivers 81-96 % of it, docs/throughput.md)."""
    from hintsjax.settings.layers import run_config
    from hintsjax.algorithms.registry import make_trainer
    from hintsjax.training import compilation

    entry = envs.REGISTRY[name]
    envs.REGISTRY[name] = dataclasses.replace(entry, cls=env_class(name, setting))
    try:
        cfg = run_config(
            {"env": name, "agent": "hints", "scheme": "fc", "seeds": seeds, "physics": physics}
        )
        start = time.perf_counter()
        compiled = compilation.compile_training(make_trainer(cfg), cfg.seed_keys(), 10)
        state = compiled.init(cfg.seed_keys())
        # warm-up
        state, _ = jax.block_until_ready(compiled.run_chunk(state, np.int32(compiled.chunk)))
        compile_s = time.perf_counter() - start
        chunks = max(1, updates // compiled.chunk)
        start = time.perf_counter()
        for _ in range(chunks):
            state, metrics = compiled.run_chunk(state, np.int32(compiled.chunk))
        jax.block_until_ready(metrics)
        seconds = time.perf_counter() - start
    finally:
        envs.REGISTRY[name] = entry
    env_steps = seeds * chunks * compiled.chunk * cfg.ppo.batch_size
    row = {
        "measure": "cost",
        "env": name,
        **described(name, setting),
        "physics": physics,
        "deterministic_ops": xla_flags.deterministic_gpu_ops(),
        "seeds": seeds,
        "updates": chunks * compiled.chunk,
        "batch_size": cfg.ppo.batch_size,
        "train_env_steps_per_s": env_steps / seconds,
        "compile_and_first_chunk_s": round(compile_s, 1),
    }
    print(json.dumps(row), flush=True)
    return row


# -- the expert in closed loop ---------------------------------------------------------------------


def expert_row(name: str, setting: str, physics: str, episodes: int) -> dict:
    """The packaged expert on our env (the setting) and on Gymnasium v5 from the same starts,
    its mean actions clipped to the control range before Gymnasium sees them (as Stable-Baselines3
    clips), so that both charge the control cost on the same action. Ours is also reported as
    `raw_action_ctrl_cost` would charge it (the trajectory is the same; the cost differs by the
    weight times the clipped-away part of |a|^2, tests/envs/test_locomotion.py): what the
    expert would score where Gymnasium is handed its raw actions."""
    cls, expert = env_class(name, setting), load(EXPERTS.get(name, name))
    env = cls(envs.make_hint(name, envs.NO_HINT), ("state",), physics)
    params = env.default_params()
    low, high = env.action_range(params)
    keys = jax.random.split(jax.random.key(2026), episodes)

    def episode(key):
        first = env.reset(key, params)

        def step(carry, _):
            ts, total, raw_total, alive, fell = carry
            action = expert.mean(ts.obs["state"])
            nxt = env.step(key, ts.state, action, params)
            clipped_away = params.ctrl_cost_weight * (
                jnp.sum(action**2) - jnp.sum(jnp.clip(action, low, high) ** 2)
            )
            return (
                nxt,
                total + jnp.where(alive, nxt.reward, 0.0),
                raw_total + jnp.where(alive, nxt.reward - clipped_away, 0.0),
                alive & ~nxt.terminated & ~nxt.truncated,
                fell | (alive & nxt.terminated),
            ), None

        zero = jnp.zeros((), jnp.float32)
        (_, total, raw_total, _, fell), _ = jax.lax.scan(
            step, (first, zero, zero, True, False), None, env.max_steps
        )
        return total, raw_total, fell, first.state.qpos, first.state.qvel

    start = time.perf_counter()
    ours, ours_raw, our_falls, qpos0, qvel0 = map(np.asarray, jax.jit(jax.vmap(episode))(keys))
    ours_s = time.perf_counter() - start
    start = time.perf_counter()
    theirs, their_falls = gym_episodes(name, expert, qpos0, qvel0, env.max_steps)
    theirs_s = time.perf_counter() - start

    def summary(returns, falls, seconds):
        ci = stats.bootstrap_ci(returns, np.mean)
        return {
            "mean_return": float(returns.mean()),
            "ci": [float(ci.low), float(ci.high)],
            "std": float(returns.std()),
            "falls": int(falls.sum()),
            "seconds": round(seconds, 1),
        }

    def minus_gymnasium(returns):
        diff = stats.difference_ci(returns, theirs)
        return {
            "mean": float(diff.point),
            "ci": [float(diff.low), float(diff.high)],
            "decided": bool(stats.difference_decided(diff)),
        }

    row = {
        "measure": "expert",
        "env": name,
        **described(name, setting),
        "physics": physics,
        "episodes": episodes,
        "ours": summary(ours, our_falls, ours_s),
        "ours_raw_action_cost": summary(ours_raw, our_falls, ours_s),
        "gymnasium": summary(theirs, their_falls, theirs_s),
        "ours_minus_gymnasium": minus_gymnasium(ours),
        "raw_minus_clipped_action_cost": float((ours_raw - ours).mean()),
    }
    print(json.dumps(row), flush=True)
    return row


def gym_episodes(
    name: str, expert, qpos0: np.ndarray, qvel0: np.ndarray, max_steps: int
) -> tuple[np.ndarray, np.ndarray]:
    """Gymnasium v5 as shipped, the expert's mean actions clipped to the control range, from the
    given starts, in lockstep."""
    act = jax.jit(jax.vmap(expert.mean))
    gyms = [gym.make(GYM_IDS[name]).unwrapped for _ in qpos0]
    obs = []
    for g, q, v in zip(gyms, qpos0, qvel0):
        g.reset(seed=0)
        g.set_state(np.asarray(q, np.float64), np.asarray(v, np.float64))
        obs.append(g._get_obs())
    total, alive, fell = np.zeros(len(gyms)), np.ones(len(gyms), bool), np.zeros(len(gyms), bool)
    for _ in range(max_steps):
        actions = np.asarray(act(jnp.asarray(np.stack(obs), jnp.float32)))
        actions = np.clip(actions, gyms[0].action_space.low, gyms[0].action_space.high)
        for i, g in enumerate(gyms):
            if alive[i]:
                obs[i], reward, terminated, _, _ = g.step(actions[i])
                total[i] += reward
                fell[i] |= terminated
                alive[i] = not terminated
        if not alive.any():
            break
    return total, fell


def report(path: Path) -> None:
    """experiments/results/fidelity.md: the JSON's rows as tables, one section per measure."""
    from hintsjax.reproduce.markdown import markdown_table

    rows = json.loads(path.read_text())["rows"]
    by = lambda measure: [r for r in rows if r["measure"] == measure]  # noqa: E731
    mark = lambda r: f"{r['setting']}{' (default)' if r['default'] else ''}"  # noqa: E731
    pair = lambda e, k: f"{e[k]['max']:.2g} / {e[k]['mean']:.2g}" if e else "-"  # noqa: E731
    lines = [
        "# Fidelity of the locomotion tasks to Gymnasium v5, per solver setting (issue 50)",
        "",
        "Made by `python experiments/fidelity.py` (commands below) and `--report`; rows in "
        "[fidelity.json](fidelity.json). Gymnasium 1.4.0, MuJoCo 3.17.0, MJX 3.17.0, warp-lang "
        "1.18.0. `default`: what the env registers today.",
        "",
        "## One control step along Gymnasium's own trajectories",
        "",
        "From each kept state of Gymnasium-as-shipped (float32-rounded; 200 per source: every 5th "
        "step of episodes of up to 500 steps driven by uniform random actions, saturated actions "
        "at the range's ends, or the packaged expert), one step of MuJoCo C with the setting "
        "(float64: the setting's own share), MJX's JAX solver and MJX-Warp with the setting, "
        "against Gymnasium as shipped. Cells: max / mean over the states of the largest |d qvel| "
        "of a state, and of |d reward|. `MJX vs C`: MJX-JAX against MuJoCo C at the same setting "
        "(MJX's own share); `Warp vs C` likewise. Two-core CPU (the development machine), "
        "2026-11-26.",
        "",
    ]
    for env in dict.fromkeys(r["env"] for r in by("one_step")):
        table = []
        for r in (r for r in by("one_step") if r["env"] == env):
            table.append(
                [
                    mark(r),
                    r["source"],
                    f"{r['mean_abs_reward']:.2f}",
                    pair(r["mujoco_c"], "qvel"),
                    pair(r["mujoco_c"], "reward"),
                    pair(r.get("jax"), "qvel"),
                    pair(r.get("jax"), "reward"),
                    pair(r.get("warp"), "qvel"),
                    pair(r.get("warp"), "reward"),
                    pair(r.get("jax_vs_mujoco_c"), "qvel"),
                    pair(r.get("warp_vs_mujoco_c"), "qvel"),
                ]
            )
        lines += [
            f"### {env}",
            "",
            *markdown_table(
                [
                    "setting",
                    "states",
                    "mean abs reward",
                    "C qvel",
                    "C reward",
                    "JAX qvel",
                    "JAX reward",
                    "Warp qvel",
                    "Warp reward",
                    "MJX vs C qvel",
                    "Warp vs C qvel",
                ],
                table,
            ),
            "",
        ]
    cost = by("cost")
    if cost:
        base = {
            (r["env"], r["physics"]): r["train_env_steps_per_s"]
            for r in cost
            if r["setting"] in ("newton_4_8", "euler_newton_4_8")
        }
        table = [
            [
                r["env"],
                mark(r),
                r["physics"],
                "on" if r["deterministic_ops"] else "off",
                f"{r['train_env_steps_per_s'] / 1e3:.1f} K",
                f"{base[r['env'], r['physics']] / r['train_env_steps_per_s']:.2f}x"
                if (r["env"], r["physics"]) in base
                else "-",
            ]
            for r in cost
        ]
        lines += [
            "## Training cost",
            "",
            f"`{cost[0]['command'].split(' --envs')[0]} --envs <env> --settings <settings> "
            "--physics <physics> --states 0 --cost --cost-updates 40` on one H100 (`device` says "
            "which), 2026-11-26: the env's default cell (hints/fc with its default hint, 5 seeds), "
            "its compiled training chunks back to back. Deterministic GPU ops as the physics' "
            "default runs them (Warp: off). Cost: the time of an env step relative to Newton at 4 "
            "iterations and 8 line-search steps (the cap until 2026-11-26).",
            "",
            *markdown_table(
                ["env", "setting", "physics", "deterministic ops", "training env steps/s", "cost"],
                table,
            ),
            "",
        ]
    experts = by("expert")
    if experts:

        def ci(e):
            return (
                f"{e['mean_return']:.0f} [{e['ci'][0]:.0f}, {e['ci'][1]:.0f}], {e['falls']} falls"
            )

        table = [
            [
                r["env"],
                mark(r),
                r["physics"],
                str(r["episodes"]),
                ci(r["ours"]),
                ci(r["gymnasium"]),
                f"{r['ours_minus_gymnasium']['mean']:+.0f} "
                f"[{r['ours_minus_gymnasium']['ci'][0]:+.0f}, "
                f"{r['ours_minus_gymnasium']['ci'][1]:+.0f}]",
                f"{r['raw_minus_clipped_action_cost']:+.4g}",
            ]
            for r in experts
        ]
        lines += [
            "## The packaged experts in closed loop",
            "",
            "`--experts 60` (2-core CPU, 2026-11-26): each env's packaged expert (ant_fast: the "
            "ant's), mean actions clipped to the control range, 60 full episodes from the same "
            "starts (our reset's, set into Gymnasium's env) on ours with the setting and on "
            "Gymnasium v5 as shipped. Return: mean [95 % bootstrap CI]. Ours - Gymnasium: 95 % CI, "
            "episodes resampled independently. Last column: what charging the control cost on the "
            "raw action (Gymnasium's rule; `raw_action_ctrl_cost`) instead of the clipped one "
            "changes in the mean return: the experts' mean actions lie outside the control range.",
            "",
            *markdown_table(
                [
                    "env",
                    "setting",
                    "physics",
                    "episodes",
                    "ours",
                    "Gymnasium v5",
                    "ours - Gymnasium",
                    "raw - clipped cost",
                ],
                table,
            ),
            "",
        ]
    lines += [
        "## Commands",
        "",
        "Each row's `command` in the JSON, with its device. They wrote to scratch files whose rows "
        "were merged into fidelity.json; `today`, in the earliest, was the name of the env's "
        "registered setting then (Newton 4 / 8: newton_4_8, the humanoid's euler_newton_4_8), and "
        "the humanoid's `newton_8_16` was Euler's.",
        "",
        *sorted({f"- `{r['command']}` ({r['device']})" for r in rows}),
        "",
    ]
    (HERE / "results" / "fidelity.md").write_text("\n".join(lines))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--envs", default="halfcheetah,ant,humanoid")
    parser.add_argument("--physics", default="jax", help="comma-separated: jax, warp")
    parser.add_argument(
        "--settings",
        default=None,
        help="comma-separated subset of each env's SETTINGS (default: all)",
    )
    parser.add_argument(
        "--states",
        type=int,
        default=200,
        help="kept states per source for the one-step rows (0: none)",
    )
    parser.add_argument(
        "--cost", action="store_true", help="training env steps/s per setting (a GPU's work)"
    )
    parser.add_argument("--cost-updates", type=int, default=40)
    parser.add_argument(
        "--experts", type=int, default=0, help="closed-loop expert episodes per setting (0: none)"
    )
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument(
        "--report",
        action="store_true",
        help="only write experiments/results/fidelity.md from --out",
    )
    args = parser.parse_args()
    if args.report:
        report(args.out)
        return
    if args.cost:
        os.environ["HINTSJAX_TRACE_CACHE"] = "off"  # a setting changes the program, not its source
    physics = args.physics.split(",")
    rows = json.loads(args.out.read_text())["rows"] if args.out.exists() else []
    about = {
        "device": jax.devices()[0].device_kind,
        "jax_version": jax.__version__,
        "mujoco": mujoco.__version__,
        "gymnasium_version": gym.__version__,
        "date": time.strftime("%Y-%m-%d"),
        "command": "python " + " ".join(sys.argv),
    }
    for name in args.envs.split(","):
        settings = args.settings.split(",") if args.settings else list(SETTINGS[name])
        unknown = sorted(set(settings) - set(SETTINGS[name]))
        if unknown:
            raise SystemExit(
                f"unknown setting(s) {unknown} for {name}; valid choices: "
                f"{', '.join(SETTINGS[name])}"
            )
        new = one_step_rows(name, settings, physics, args.states) if args.states else []
        for setting in settings:
            new += (
                [cost_row(name, setting, p, args.cost_updates) for p in physics]
                if args.cost
                else []
            )
            new += (
                [expert_row(name, setting, p, args.experts) for p in physics]
                if args.experts
                else []
            )
        new = [{**r, **about} for r in new]

        def same(a, b):
            keys = ("measure", "env", "setting", "source", "physics", "device")
            return all(a.get(k) == b.get(k) for k in keys)

        rows = [r for r in rows if not any(same(r, n) for n in new)] + new
        args.out.write_text(
            json.dumps({"about": __doc__.split("\n\n")[2], "rows": rows}, indent=1) + "\n"
        )


if __name__ == "__main__":
    main()
