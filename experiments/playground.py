"""HINTs on MuJoCo Playground's DeepMind Control tasks from pixels, and hintsjax's PPO beside Brax's (issue 48).

    python experiments/playground.py [--envs playground:CartpoleSwingup] [--workers 2]  # item 5
    python experiments/playground.py --versus-brax [--steps 60000000] [--side brax]     # item 6
    python experiments/playground.py --report      # experiments/results/playground.md
    python experiments/playground_vision.py        # pixel PPO beside Playground's (its section)
    python experiments/playground.py --smoke --runs /tmp/pg --versus-brax &&
        python experiments/playground.py --smoke --runs /tmp/pg --report

Item 5: on CartpoleSwingup, CheetahRun, WalkerWalk and ReacherEasy (adapted by envs/adapter.py,
seen as 64x64 renders from each task's table camera, envs/playground.py), PPO-RGB and HINTS-FC
with one natural hint each (the table's), 5 seeds vmapped in one call, at the table's budget (1 M
env steps), 50 evaluation episodes per seed; the report gives each row's IQM [95 % CI] over seeds
and P(HINTS > PPO-RGB) (hintsjax.reproduce.stats). Finished folders are skipped
(hintsjax/reproduce/sweep.py).

Item 6: CartpoleSwingup from its state vector, the same seeds and the same whole number of
updates (training steps) of the same batch on both sides: hintsjax's `ppo_state` (its seeds
vmapped in one program) with Playground's published Brax PPO settings mapped onto hintsjax's
(`hintsjax_values`), and Brax's own `brax.training.agents.ppo.train` with those settings
(mujoco_playground.config.dm_control_suite_params), one seed after another as Brax trains, held to
the same updates (`brax_schedule`). Both step the task with MJX's JAX physics (impl=jax: the
adapter's; Playground's default is MuJoCo Warp). Each side's wall-clock runs from the call to the
trained policies, compilation included; each seed's final policy is then evaluated on 128 fresh
episodes, deterministic and stochastic, by the side's own evaluator. `--side hintsjax|brax` runs
one side (say, each on a GPU of its own); the record is runs/<runs>/versus_brax.json, which each
side fills in, with the settings it ran; --report adds it to the results.
"""  # noqa: E501

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import time
from pathlib import Path

from hintsjax.reproduce.archive import ARCHIVE, about_lines, read_about
from hintsjax.reproduce.markdown import generated_sections, markdown_table, write_report
from hintsjax.reproduce.report import footer, iqm_cell, load, ordering, sweep_hardware, wall_clock
from hintsjax.reproduce.sweep import hints_run
from hintsjax.reproduce.table_script import TableScript, chosen_envs, table_main

RESULTS = Path(__file__).resolve().parent / "results"
REPORT = "playground.md"  # under RESULTS
DEFAULT_RUNS = "runs/playground"
TABLE = "playground"  # the sweep's name in runs/<...>/sweeps.jsonl
ENVS = (
    "playground:CartpoleSwingup",
    "playground:CheetahRun",
    "playground:WalkerWalk",
    "playground:ReacherEasy",
)
HINTS = {  # one natural hint per task (envs/playground.py DEFAULTS)
    "playground:CartpoleSwingup": "pole_angle",
    "playground:CheetahRun": "torso_velocity",
    "playground:WalkerWalk": "torso_height_velocity",
    "playground:ReacherEasy": "fingertip_to_target",
}
VERSUS_TASK = "CartpoleSwingup"
VERSUS_JSON = "versus_brax.json"  # under the runs folder


def run_ids(names) -> list[str]:
    return [f"{env}/{label}" for env in names for label in ("ppo_rgb", hints_run("fc", HINTS[env]))]


# -- item 6: hintsjax's ppo_state beside Brax's PPO ---------------------------------------------

SIDES = ("hintsjax", "brax")
TRAINERS = {"hintsjax": "hintsjax ppo_state", "brax": "brax.training ppo"}
# how each side's final policy is evaluated: mean action, or sampled
MODES = ("deterministic", "stochastic")
EVAL_EPISODES = 128  # fresh episodes per seed and mode, on both sides: Brax's num_eval_envs
# hintsjax's max_grad_norm for Brax's None (no clipping): it clips only a gradient whose norm passes
# 1e9
NO_CLIP = 1e9


def brax_settings(smoke: bool) -> dict:
    """Playground's published Brax PPO settings for the task (a tiny budget with `smoke`)."""
    from mujoco_playground.config import dm_control_suite_params

    settings = dict(dm_control_suite_params.brax_ppo_config(VERSUS_TASK))
    if smoke:
        settings.update(
            num_timesteps=4096,
            num_evals=2,
            num_envs=8,
            batch_size=8,
            num_minibatches=4,
            unroll_length=8,
            num_updates_per_batch=1,
            num_eval_envs=8,
            num_resets_per_eval=0,
        )
    return settings


def steps_per_update(brax: dict) -> int:
    """Env steps of one Brax training step (one hintsjax update): batch_size x num_minibatches x
    unroll_length."""
    return brax["batch_size"] * brax["num_minibatches"] * brax["unroll_length"]


def brax_schedule(updates: int) -> dict:
    """num_evals and num_resets_per_eval that make Brax's `train` take exactly `updates` training
    steps, each followed by a reset of every env, as Playground's settings give on the GPU (one
    training step per epoch). Playground's own (num_evals 10, num_resets_per_eval 10) round any
    budget up to whole evaluation epochs: 9 x 10 training steps, 88.5 M env steps for 60 M."""
    evals = next(e for e in (5, 4, 3, 2) if updates % (e - 1) == 0)
    return {"num_evals": evals, "num_resets_per_eval": updates // (evals - 1)}


def hintsjax_values(brax: dict, seeds: int, steps: int, smoke: bool) -> dict:
    """hintsjax's run config with Brax's settings mapped where hintsjax has the same knob: its
    update collects num_envs rollouts of batch_size * num_minibatches * unroll_length / num_envs
    steps, and takes num_updates_per_batch epochs of num_minibatches minibatches; the discount,
    one learning rate for actor and critic, the entropy cost, the reward scale and the running
    observation normalisation, updated before learning as Brax's is, and Brax's gradient clipping:
    none unless its settings name a max_grad_norm (`NO_CLIP`; hintsjax's own 0.5 over the actor's
    and critic's gradients together made every seed collapse at 60 M, versus_brax_knobs.md). Left
    at hintsjax's: the networks ((256, 256) beside Brax's policy (32,)x4 and value (256,)x5), GAE
    over the whole rollout (Brax's over each unroll), the ratio clip (0.2 beside Brax's 0.3), the
    value loss's weight (0.5 of the mean square beside Brax's 0.25; the critic's own Adam all but
    undoes a constant weight) and the episodes running on across updates (Brax resets every env
    after each: ppo.reset_every_update)."""
    batch = steps_per_update(brax)
    ppo = {
        "total_env_steps": steps,
        "num_envs": brax["num_envs"],
        "batch_size": batch,
        "minibatch_size": batch // brax["num_minibatches"],
        "epochs": brax["num_updates_per_batch"],
        "gamma": brax["discounting"],
        "actor_lr": brax["learning_rate"],
        "critic_lr": brax["learning_rate"],
        "ent_coef": brax["entropy_cost"],
        "reward_scale": brax["reward_scaling"],
        "max_grad_norm": brax.get("max_grad_norm") or NO_CLIP,
        "normalize_state": brax["normalize_observations"],
        # Brax's order: a rollout's states join the statistics before learning on it (issue 61:
        # after it, at 20 updates, cost CartpoleSwingup more than half its return on a CPU)
        "normalize_before_learning": brax["normalize_observations"],
    }
    return {
        "env": f"playground:{VERSUS_TASK}",
        "agent": "ppo_state",
        "seeds": seeds,
        "eval_episodes": 2 if smoke else 50,
        "checkpoint_every": 10**9,
        "ppo": ppo,
    }


def train_hintsjax(
    brax: dict,
    seeds: int,
    updates: int,
    overrides: dict | None = None,
    episodes: int = EVAL_EPISODES,
) -> dict:
    """hintsjax's ppo_state with Brax's settings (`hintsjax_values`, plus `overrides` of its ppo
    section), its seeds vmapped in one program, exactly `updates` updates; the seconds run from the
    call to the trained policies (compilation included, evaluation not); then each seed's final
    policy on `episodes` fresh episodes, both MODES. `curve`: each seed's training return after
    every `every` updates (NaN where no episode ended in them); `kl_curve`: their largest update
    KL."""
    import jax
    import numpy as np

    from hintsjax.algorithms.registry import make_trainer
    from hintsjax.evaluation.evaluator import compile_evaluator, evaluate_variants
    from hintsjax.settings.layers import run_config, to_dict

    values = hintsjax_values(brax, seeds, updates * steps_per_update(brax), False)
    values["ppo"].update(overrides or {})
    values["eval_episodes"] = episodes
    cfg = run_config(values)
    trainer = make_trainer(cfg)
    # updates between progress lines: one compiled chunk
    every = max(d for d in range(1, 9) if updates % d == 0)
    t = time.time()
    state = jax.jit(jax.vmap(trainer.init))(cfg.seed_keys())
    chunk = jax.jit(jax.vmap(lambda s: trainer.run(s, every)))
    curve, kl_curve = [], []
    for _ in range(updates // every):
        state, metrics = chunk(state)
        curve.append(np.asarray(metrics["episode_return"])[:, -1].round(1).tolist())
        # the chunk's largest update KL
        kl_curve.append(np.asarray(metrics["approx_kl"]).max(axis=1).round(4).tolist())
        print(
            f"update {int(np.asarray(state.update)[0])}: training return per seed {curve[-1]}, "
            f"largest KL {kl_curve[-1]}",
            flush=True,
        )
    assert int(np.asarray(state.update)[0]) == updates
    seconds = time.time() - t
    compiled = compile_evaluator(cfg, state.params, None, episodes)
    evals = {
        mode: evaluate_variants(
            cfg, state.params, (None,), episodes, mode == "stochastic", compiled
        )[0][0]
        for mode in MODES
    }
    return {
        "env_steps_per_seed": updates * cfg.ppo.batch_size,
        "seconds": seconds,
        **{mode: [float(x) for x in evals[mode]["seed_means"]] for mode in MODES},
        "curve": curve,
        "kl_curve": kl_curve,
        "every": every,
        "settings": to_dict(cfg)["ppo"],
    }


def mend_brax_for_this_jax() -> None:
    """brax 0.14.2 (the newest) calls `jax.device_put_replicated`, which jax 0.10 removed (an
    AttributeError that names `jax.device_put` as the replacement): put back the drop-in that
    JAX's pmap migration guide gives, one copy of each array per device, stacked on a new axis."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    if "device_put_replicated" in vars(jax):
        return

    def device_put_replicated(x, devices):
        mesh = jax.sharding.Mesh(np.asarray(devices), ("devices",))
        sharding = jax.sharding.NamedSharding(mesh, jax.sharding.PartitionSpec("devices"))
        return jax.device_put(jax.tree.map(lambda a: jnp.stack([a] * len(devices)), x), sharding)

    jax.device_put_replicated = device_put_replicated


def train_brax(brax: dict, seeds: int, updates: int, episodes: int = EVAL_EPISODES) -> dict:
    """Brax's PPO on Playground's task, as Playground's notebooks call it, one seed after another,
    held to exactly `updates` training steps (`brax_schedule`); the seconds run from the first call
    to the last trained policy (compilation and Brax's own evaluations included, ours not); then
    each seed's final policy on `episodes` fresh episodes by Brax's Evaluator, both MODES."""
    import functools

    import jax
    from brax.training import acting
    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo
    from mujoco_playground import registry, wrapper

    mend_brax_for_this_jax()
    run = {
        **brax,
        **brax_schedule(updates),
        "num_timesteps": updates * steps_per_update(brax),
        "num_eval_envs": episodes,
    }
    factory = ppo_networks.make_ppo_networks
    if "network_factory" in run:
        factory = functools.partial(ppo_networks.make_ppo_networks, **run.pop("network_factory"))
    out: dict = {
        "brax_final_eval": [],
        "env_steps_per_seed": [],
        "curve": [],
        **{mode: [] for mode in MODES},
    }
    trained, seconds = [], 0.0
    for seed in range(seeds):
        env = registry.load(VERSUS_TASK, config_overrides={"impl": "jax"})
        seen: list = []

        def progress(step, metrics, seen=seen, seed=seed):
            if "eval/episode_reward" in metrics:
                seen.append((int(step), round(float(metrics["eval/episode_reward"]), 1)))
                print(f"seed {seed} step {step}: eval return {seen[-1][1]}", flush=True)

        t = time.time()
        make_policy, params, _ = ppo.train(
            environment=env,
            wrap_env_fn=wrapper.wrap_for_brax_training,
            network_factory=factory,
            progress_fn=progress,
            seed=seed,
            **run,
        )
        seconds += time.time() - t
        out["brax_final_eval"].append(seen[-1][1])
        out["env_steps_per_seed"].append(seen[-1][0])
        out["curve"].append(seen)
        trained.append((env, make_policy, params))
    for seed, (env, make_policy, params) in enumerate(trained):
        eval_env = wrapper.wrap_for_brax_training(
            env, episode_length=brax["episode_length"], action_repeat=1
        )
        for mode in MODES:
            evaluator = acting.Evaluator(
                eval_env,
                functools.partial(make_policy, deterministic=mode == "deterministic"),
                num_eval_envs=episodes,
                episode_length=brax["episode_length"],
                action_repeat=1,
                key=jax.random.PRNGKey(1000 + seed),
            )
            out[mode].append(float(evaluator.run_evaluation(params, {})["eval/episode_reward"]))
    return {**out, "seconds": seconds, "settings": run}


def versus_brax(
    runs: Path, seeds: int, steps: int | None, smoke: bool, sides: tuple[str, ...] = SIDES
) -> None:
    """Item 6: each side of `sides` in this process, one after the other, at the same whole number
    of updates (`steps` // the update's env steps), into the record runs/versus_brax.json. Each side
    reads the record again when it ends and replaces its own entry only, so the two sides can run
    at once (on two devices); a record of another budget or seed count is started afresh."""

    brax = brax_settings(smoke)
    updates = max((steps or brax["num_timesteps"]) // steps_per_update(brax), 1)
    episodes = 4 if smoke else EVAL_EPISODES
    path = runs / VERSUS_JSON
    budget = {
        "task": VERSUS_TASK,
        "seeds": seeds,
        "updates": updates,
        "env_steps_per_seed": updates * steps_per_update(brax),
        "smoke": smoke,
    }
    for side in sides:
        print(
            f"{TRAINERS[side]}: {seeds} seeds x {updates} updates of {steps_per_update(brax):,} "
            "env steps",
            flush=True,
        )
        result = (
            train_hintsjax(brax, seeds, updates, episodes=episodes)
            if side == "hintsjax"
            else train_brax(brax, seeds, updates, episodes)
        )
        record_side(
            path, budget, side, {"trainer": TRAINERS[side], **result, "eval_episodes": episodes}
        )
        print(
            f"{TRAINERS[side]}: {result['seconds']:.0f} s; final returns (deterministic) "
            f"{[round(x, 1) for x in result['deterministic']]}",
            flush=True,
        )


def record_side(path: Path, budget: dict, side: str, entry: dict) -> None:
    """A side by side's record at `path` with `side`'s `entry` (and the device, date and command
    that made it) in place of its previous one: read again just before, so that sides running at
    once keep each other's entries; a record of another `budget` is started afresh."""
    import jax

    record = json.loads(path.read_text()) if path.exists() else {}
    if {k: record.get(k) for k in budget} != budget:
        record = {**budget, "results": {}}
    record["results"][side] = {
        **entry,
        "device": jax.devices()[0].device_kind,
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "command": " ".join(["python", f"experiments/{Path(sys.argv[0]).name}", *sys.argv[1:]]),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=1))


def seed_steps(result: dict) -> list[int]:
    """Each seed's env steps, as the side's record says it took them (Brax's side lists them;
    hintsjax's gives the one count all its seeds took)."""
    steps = result["env_steps_per_seed"]
    return steps if isinstance(steps, list) else [steps] * len(result["deterministic"])


# -- the report ----------------------------------------------------------------------------------


def versus_record(runs: Path, keep: bool = False) -> Path:
    """The side by side's record: runs/versus_brax.json where it ran here, else its archived copy
    (experiments/results/runs/<runs' name>/); `keep` archives the first (the report does, not a
    smoke run's)."""
    path, archived = runs / VERSUS_JSON, ARCHIVE / runs.name / VERSUS_JSON
    if keep:
        archive_file(path, archived)
    return path if path.exists() else archived


def archive_file(path: Path, archived: Path) -> None:
    """Copy a record that exists to its archived copy, unless it is that copy (the runs folder
    given may be the archive's own)."""
    if path.exists() and not (archived.exists() and archived.samefile(path)):
        archived.parent.mkdir(parents=True, exist_ok=True)
        shutil.copyfile(path, archived)


def versus_lines(runs: Path) -> list[str]:
    from hintsjax.reproduce import stats

    path = versus_record(runs)
    lines = ["## hintsjax's ppo_state beside Brax's PPO (item 6)", ""]
    if not path.exists():
        return lines + [
            f"Not run yet (`python experiments/playground.py --versus-brax`: {VERSUS_JSON}).",
            "",
        ]
    record = json.loads(path.read_text())
    results = record["results"]
    rows = []
    for side in SIDES:
        if side not in results:
            rows.append([TRAINERS[side], "-", "-", "-", "-", "-", "not run yet"])
            continue
        r = results[side]
        steps = seed_steps(r)
        rows.append(
            [
                r["trainer"],
                "/".join(f"{s:,}" for s in sorted(set(steps))),
                stats.iqm_cell(r["deterministic"]),
                stats.iqm_cell(r["stochastic"]),
                f"{r['seconds']:.0f}",
                f"{sum(steps) / r['seconds']:,.0f}",
                f"{r['device']}, {r['date']}: `{r['command']}`",
            ]
        )
    lines += [
        f"{record['task']} from its state, {record['seeds']} seeds x {record['updates']} "
        f"updates of {record['env_steps_per_seed'] // record['updates']:,} "
        f"env steps ({record['env_steps_per_seed']:,} a seed) on each "
        f"side{' (smoke: the numbers mean nothing)' if record['smoke'] else ''}. "
        "Final return: each seed's final policy on "
        f"{max(r['eval_episodes'] for r in results.values()) if results else EVAL_EPISODES} "
        "fresh episodes, deterministic (mean action) and stochastic; wall-clock: from the call "
        "to the last trained policy, compilation included (Brax's seeds one after another, "
        "hintsjax's vmapped in one program).",
        "",
    ]
    lines += markdown_table(
        [
            "trainer",
            "env steps a seed",
            "final return, deterministic: IQM [95% CI]",
            "stochastic",
            "wall-clock (s)",
            "env steps/s",
            "GPU, date, command",
        ],
        rows,
    )
    if all(side in results for side in SIDES):
        first, second = (results[side] for side in SIDES)
        lines.append("")
        for mode in MODES:
            lines.append(
                f"- {mode}: "
                + stats.ordering_text(
                    first["trainer"], second["trainer"], stats.poi_ci(first[mode], second[mode])
                )
            )
    return lines + [""]


def report(runs: Path, force: bool = False, out: Path | None = None) -> None:
    versus_record(runs, keep=out is None)
    hardware = sweep_hardware(runs, TABLE, run_ids(ENVS))
    lines = [
        "# HINTs on MuJoCo Playground's DeepMind Control tasks (issue 48)",
        "",
        *(
            ["Smoke run (`--smoke`): tiny budgets on a CPU, the numbers mean nothing.", ""]
            if out is not None
            else []
        ),
        "Commands: `python experiments/playground.py` (item 5), "
        "`python experiments/playground.py --versus-brax`",
        "(item 6), then `python experiments/playground.py --report`. Hardware: "
        f"{hardware or 'see each wall-clock cell'}.",
        "",
        "Each cell: IQM of the 5 training seeds' mean returns (50 deterministic evaluation "
        "episodes each), with",
        "its 95% stratified-bootstrap CI (hintsjax.reproduce.stats); P(HINTS > PPO-RGB) "
        "over the seeds' mean returns.",
        "The tasks are Playground's, adapted by envs/adapter.py and seen as 64x64 "
        "renders (envs/render3d.py)",
        "from each task's camera (envs/playground.py DEFAULTS); '-': not run yet.",
        "",
        "## PPO-RGB and HINTS-FC (item 5)",
        "",
    ]
    rows = []
    for env in ENVS:
        hints_label = hints_run("fc", HINTS[env])
        rgb, hinted = load(runs, env, "ppo_rgb"), load(runs, env, hints_label)
        rows.append(
            [
                env.split(":", 1)[1],
                HINTS[env],
                iqm_cell(rgb),
                iqm_cell(hinted),
                ordering("HINTS", hinted, "PPO-RGB", rgb) or "-",
                f"{wall_clock(rgb)} / {wall_clock(hinted)}",
            ]
        )
    lines += markdown_table(
        ["task", "hint", "PPO-RGB", "HINTS-FC", "P(HINTS > PPO-RGB)", "wall-clock (s)"], rows
    )
    lines += [
        "",
        *versus_lines(runs),
        *about_lines(read_about(ARCHIVE / runs.name)),
        footer(runs, TABLE, run_ids(ENVS)),
    ]
    path = out or RESULTS / REPORT
    # below: the sections other scripts write (experiments/playground_vision.py's), kept
    kept = generated_sections(path)
    write_report(path, [*lines, *([""] + kept if kept else [])], force)


def extra_arguments(parser: argparse.ArgumentParser) -> None:
    """--versus-brax and its --steps and --side."""
    parser.add_argument(
        "--versus-brax", action="store_true", help="item 6: hintsjax's ppo_state beside Brax's PPO"
    )
    parser.add_argument(
        "--steps",
        type=int,
        default=None,
        help="--versus-brax: env steps per seed, in whole updates (default Playground's: "
        "60 M, 61 updates)",
    )
    parser.add_argument(
        "--side", choices=SIDES, default=None, help="--versus-brax: one side only (default both)"
    )


def extra_mode(parser: argparse.ArgumentParser, args: argparse.Namespace) -> bool:
    """--versus-brax (item 6, on the device), or --smoke --report: the plumbing only, no archive,
    the report beside the runs. False for the other calls (the sweep of item 5, its report)."""
    if args.versus_brax:
        chosen_envs(parser, args, ENVS)  # checks --seeds
        versus_brax(
            args.runs, args.seeds, args.steps, args.smoke, (args.side,) if args.side else SIDES
        )
        return True
    if args.report and args.smoke:
        os.environ["JAX_PLATFORMS"] = "cpu"  # as table_main's reports: the parent only reads
        report(args.runs, True, args.runs / REPORT)
        return True
    return False


SCRIPT = TableScript(
    __doc__.splitlines()[0],
    DEFAULT_RUNS,
    ENVS,
    {TABLE: run_ids},
    report,
    extra_arguments=extra_arguments,
    extra_mode=extra_mode,
)


def main() -> None:
    table_main(SCRIPT)


if __name__ == "__main__":
    main()
