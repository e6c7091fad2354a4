"""HINTs on MuJoCo Playground's DeepMind Control tasks from pixels, and hintsjax's PPO beside Brax's (issue 48).

    python experiments/playground.py [--envs playground:CartpoleSwingup] [--workers 2]   # item 5: the sweep
    python experiments/playground.py --versus-brax [--steps 60000000]                     # item 6: the side by side
    python experiments/playground.py --report      # experiments/results/playground.md
    python experiments/playground.py --smoke --runs /tmp/pg --versus-brax && python experiments/playground.py --smoke --runs /tmp/pg --report

Item 5: on CartpoleSwingup, CheetahRun, WalkerWalk and ReacherEasy (adapted by envs/adapter.py,
seen as 64x64 renders from each task's table camera, envs/playground.py), PPO-RGB and HINTS-FC
with one natural hint each (the table's), 5 seeds vmapped in one call, at the table's budget (1 M
env steps), 50 evaluation episodes per seed; the report gives each row's IQM [95 % CI] over seeds
and P(HINTS > PPO-RGB) (hintsjax.reproduce.stats). Finished folders are skipped (hintsjax/reproduce/sweep.py).

Item 6: CartpoleSwingup from its state vector, one process on one device, the same env-step
budget and seeds: hintsjax's `ppo_state` (its seeds vmapped in one program) with Playground's
published Brax PPO settings mapped onto hintsjax's (`hintsjax_values`), then Brax's own
`brax.training.agents.ppo.train` with those settings (mujoco_playground.config.dm_control_suite_params),
one seed after another, as Brax trains. Both step the task with MJX's JAX physics (impl=jax: the
adapter's; Playground's default is MuJoCo Warp). Each side's wall-clock runs from the call to the
trained policy, compilation included; its final return is the mean return of its last evaluation
per seed (hintsjax: 50 deterministic episodes; Brax: its own final evaluation, 128 episodes).
The record is runs/<runs>/versus_brax.json; --report adds it to the results.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path

from hintsjax.reproduce.markdown import markdown_table, write_report
from hintsjax.reproduce.report import footer, iqm_cell, load, ordering, sweep_hardware, wall_clock
from hintsjax.reproduce.sweep import hints_run
from hintsjax.reproduce.table_script import TableScript, chosen_envs, table_main

RESULTS = Path(__file__).resolve().parent / "results"
REPORT = "playground.md"  # under RESULTS
DEFAULT_RUNS = "runs/playground"
TABLE = "playground"  # the sweep's name in runs/<...>/sweeps.jsonl
ENVS = ("playground:CartpoleSwingup", "playground:CheetahRun", "playground:WalkerWalk", "playground:ReacherEasy")
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


@dataclass(frozen=True)
class SideResult:
    """One trainer's run of the side by side: its per-seed final returns, its wall-clock from
    the call to the trained policies (compilation included) and the env steps it took in all."""

    trainer: str
    seed_returns: list[float]
    seconds: float
    env_steps: int
    settings: dict

    @property
    def steps_per_second(self) -> float:
        return self.env_steps / self.seconds


def brax_settings(smoke: bool) -> dict:
    """Playground's published Brax PPO settings for the task (a tiny budget with `smoke`)."""
    from mujoco_playground.config import dm_control_suite_params

    settings = dict(dm_control_suite_params.brax_ppo_config(VERSUS_TASK))
    if smoke:
        settings.update(num_timesteps=4096, num_evals=2, num_envs=8, batch_size=8, num_minibatches=4, unroll_length=8,
                        num_updates_per_batch=1, num_eval_envs=8, num_resets_per_eval=0)
    return settings


def hintsjax_values(brax: dict, seeds: int, steps: int, smoke: bool) -> dict:
    """hintsjax's run config with Brax's settings mapped where hintsjax has the same knob: its
    update collects num_envs rollouts of batch_size * num_minibatches * unroll_length / num_envs
    steps, and takes num_updates_per_batch epochs of num_minibatches minibatches; the discount,
    one learning rate for actor and critic, the entropy cost, the reward scale and the running
    observation normalisation, updated before learning as Brax's is. Left at hintsjax's: the networks ((256, 256) beside Brax's
    policy (32,)x4 and value (256,)x5), GAE over the whole rollout (Brax's over each unroll) and
    the clipping (0.2 and 0.5 beside Brax's 0.3 and 1.0)."""
    batch = brax["batch_size"] * brax["num_minibatches"] * brax["unroll_length"]
    ppo = {"total_env_steps": steps, "num_envs": brax["num_envs"], "batch_size": batch,
           "minibatch_size": batch // brax["num_minibatches"], "epochs": brax["num_updates_per_batch"],
           "gamma": brax["discounting"], "actor_lr": brax["learning_rate"], "critic_lr": brax["learning_rate"],
           "ent_coef": brax["entropy_cost"], "reward_scale": brax["reward_scaling"],
           "normalize_state": brax["normalize_observations"],
           # Brax's order: a rollout's states join the statistics before learning on it (issue 61:
           # after it, at 20 updates, cost CartpoleSwingup more than half its return on a CPU)
           "normalize_before_learning": brax["normalize_observations"]}
    return {"env": f"playground:{VERSUS_TASK}", "agent": "ppo_state", "seeds": seeds, "eval_episodes": 2 if smoke else 50,
            "checkpoint_every": 10 ** 9, "ppo": ppo}


def train_hintsjax(runs: Path, brax: dict, seeds: int, steps: int, smoke: bool) -> SideResult:
    from hintsjax.settings.layers import run_config, to_dict
    from hintsjax.training import pipeline

    cfg = run_config(hintsjax_values(brax, seeds, steps, smoke))
    folder = runs / "versus_brax" / "hintsjax"
    if folder.exists():
        import shutil

        shutil.rmtree(folder)
    folder.mkdir(parents=True)
    t = time.time()
    result = pipeline.train(cfg, folder, progress=False)
    seconds = time.time() - t
    evaluation = result["evaluations"][0]
    return SideResult("hintsjax ppo_state", list(evaluation["seed_means"]), seconds,
                      cfg.seeds * cfg.ppo.num_updates * cfg.ppo.batch_size, to_dict(cfg)["ppo"])


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


def train_brax(brax: dict, seeds: int, steps: int) -> SideResult:
    """Brax's PPO on Playground's task, as Playground's notebooks call it, one seed after another."""
    import functools

    from brax.training.agents.ppo import networks as ppo_networks
    from brax.training.agents.ppo import train as ppo
    from mujoco_playground import registry, wrapper

    mend_brax_for_this_jax()
    settings = {**brax, "num_timesteps": steps}
    factory = ppo_networks.make_ppo_networks
    if "network_factory" in settings:
        factory = functools.partial(ppo_networks.make_ppo_networks, **settings.pop("network_factory"))
    returns, taken = [], 0
    t = time.time()
    for seed in range(seeds):
        env = registry.load(VERSUS_TASK, config_overrides={"impl": "jax"})
        evals: list[float] = []
        steps_seen: list[int] = []

        def progress(step, metrics, evals=evals, steps_seen=steps_seen):
            if "eval/episode_reward" in metrics:
                evals.append(float(metrics["eval/episode_reward"]))
                steps_seen.append(int(step))

        ppo.train(environment=env, wrap_env_fn=wrapper.wrap_for_brax_training, network_factory=factory,
                  progress_fn=progress, seed=seed, **settings)
        returns.append(evals[-1])
        taken += steps_seen[-1]
    return SideResult("brax.training ppo", returns, time.time() - t, taken, {k: v for k, v in brax.items() if k != "network_factory"})


def versus_brax(runs: Path, seeds: int, steps: int | None, smoke: bool) -> None:
    """Item 6: both trainers in this process, one after the other; the record to runs/versus_brax.json."""
    import jax

    brax = brax_settings(smoke)
    steps = steps or brax["num_timesteps"]
    results = [train_hintsjax(runs, brax, seeds, steps, smoke), train_brax(brax, seeds, steps)]
    record = {"task": VERSUS_TASK, "seeds": seeds, "env_steps_per_seed": steps, "smoke": smoke,
              "device": jax.devices()[0].device_kind, "date": time.strftime("%Y-%m-%d"),
              "command": " ".join(["python", *sys.argv]),
              "results": [{**asdict(r), "steps_per_second": r.steps_per_second} for r in results]}
    runs.mkdir(parents=True, exist_ok=True)
    (runs / VERSUS_JSON).write_text(json.dumps(record, indent=1))
    for r in results:
        print(f"{r.trainer}: {r.env_steps} env steps in {r.seconds:.0f} s ({r.steps_per_second:,.0f} steps/s); "
              f"final returns {[round(x, 1) for x in r.seed_returns]}", flush=True)


# -- the report ----------------------------------------------------------------------------------


def versus_lines(runs: Path) -> list[str]:
    from hintsjax.reproduce import stats

    path = runs / VERSUS_JSON
    lines = ["## hintsjax's ppo_state beside Brax's PPO (item 6)", ""]
    if not path.exists():
        return lines + [f"Not run yet (`python experiments/playground.py --versus-brax`: {VERSUS_JSON}).", ""]
    record = json.loads(path.read_text())
    rows = [[r["trainer"], stats.iqm_cell(r["seed_returns"]), f"{r['env_steps']:,}", f"{r['seconds']:.0f}",
             f"{r['steps_per_second']:,.0f}"] for r in record["results"]]
    lines += [f"{record['task']} from its state, {record['seeds']} seeds x {record['env_steps_per_seed']:,} env steps "
              f"each, on one {record['device']} ({record['date']}){' (smoke: the numbers mean nothing)' if record['smoke'] else ''}; "
              f"command: `{record['command']}`.", ""]
    lines += markdown_table(["trainer", "final return, IQM [95% CI]", "env steps", "wall-clock (s)", "env steps/s"], rows)
    first, second = record["results"]
    lines += ["", stats.ordering_text(first["trainer"], second["trainer"], stats.poi_ci(first["seed_returns"], second["seed_returns"])), ""]
    return lines


def report(runs: Path, force: bool = False, out: Path | None = None) -> None:
    hardware = sweep_hardware(runs, TABLE, run_ids(ENVS))
    lines = [
        "# HINTs on MuJoCo Playground's DeepMind Control tasks (issue 48)", "",
        *(["Smoke run (`--smoke`): tiny budgets on a CPU, the numbers mean nothing.", ""] if out is not None else []),
        "Commands: `python experiments/playground.py` (item 5), `python experiments/playground.py --versus-brax`",
        f"(item 6), then `python experiments/playground.py --report`. Hardware: {hardware or 'see each wall-clock cell'}.", "",
        "Each cell: IQM of the 5 training seeds' mean returns (50 deterministic evaluation episodes each), with",
        "its 95% stratified-bootstrap CI (hintsjax.reproduce.stats); P(HINTS > PPO-RGB) over the seeds' mean returns.",
        "The tasks are Playground's, adapted by envs/adapter.py and seen as 64x64 renders (envs/render3d.py)",
        "from each task's camera (envs/playground.py DEFAULTS); '-': not run yet.", "",
        "## PPO-RGB and HINTS-FC (item 5)", "",
    ]
    rows = []
    for env in ENVS:
        hints_label = hints_run("fc", HINTS[env])
        rgb, hinted = load(runs, env, "ppo_rgb"), load(runs, env, hints_label)
        rows.append([env.split(":", 1)[1], HINTS[env], iqm_cell(rgb), iqm_cell(hinted),
                     ordering("HINTS", hinted, "PPO-RGB", rgb) or "-", f"{wall_clock(rgb)} / {wall_clock(hinted)}"])
    lines += markdown_table(["task", "hint", "PPO-RGB", "HINTS-FC", "P(HINTS > PPO-RGB)", "wall-clock (s)"], rows)
    lines += ["", *versus_lines(runs), footer(runs, TABLE, run_ids(ENVS))]
    write_report(out or RESULTS / REPORT, lines, force)


def extra_arguments(parser: argparse.ArgumentParser) -> None:
    """--versus-brax and its --steps."""
    parser.add_argument("--versus-brax", action="store_true", help="item 6: hintsjax's ppo_state beside Brax's PPO")
    parser.add_argument("--steps", type=int, default=None, help="--versus-brax: env steps per seed (default Playground's)")


def extra_mode(parser: argparse.ArgumentParser, args: argparse.Namespace) -> bool:
    """--versus-brax (item 6, on the device), or --smoke --report: the plumbing only, no archive, the
    report beside the runs. False for the other calls (the sweep of item 5, its report)."""
    if args.versus_brax:
        chosen_envs(parser, args, ENVS)  # checks --seeds
        versus_brax(args.runs, args.seeds, args.steps, args.smoke)
        return True
    if args.report and args.smoke:
        os.environ["JAX_PLATFORMS"] = "cpu"  # as table_main's reports: the parent only reads
        report(args.runs, True, args.runs / REPORT)
        return True
    return False


SCRIPT = TableScript(__doc__.splitlines()[0], DEFAULT_RUNS, ENVS, {TABLE: run_ids}, report,
                     extra_arguments=extra_arguments, extra_mode=extra_mode)


def main() -> None:
    table_main(SCRIPT)


if __name__ == "__main__":
    main()
