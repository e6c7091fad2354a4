"""hintsjax's pixel PPO beside MuJoCo Playground's vision PPO on CartpoleBalance (issue 83).

    python experiments/playground_vision.py [--seeds 5] [--side playground|mapped|...|defaults]
    python experiments/playground_vision.py --report    # archived, plotted, its section of
                                                        # results/playground.md (the last one)
    python experiments/playground_vision.py --smoke --runs /tmp/pv --side mapped  # plumbing, a CPU
    python experiments/playground_vision.py --side mapped --parts parts.json  # an update's parts

The sides, each in a process of its own (the script starts one per side unless `--side` names
one), one after another on one GPU, every seed at the same env steps (Brax's own count for
Playground's budget: 4 epochs of 31 training steps of 40,960, 5,079,040 a seed):
- `playground`: Brax's `ppo.train` on Playground's CartpoleBalance with `vision=True` (MuJoCo
  Warp's batch renderer: three stacked grey 64x64 frames from the `fixed` camera), its
  `brax_vision_ppo_config` and `make_ppo_networks_vision`, as Playground's vision notebook calls
  them (an evaluation env of its own, its renderer built for `num_eval_envs` worlds), seeds one
  after another. Patched only where jax 0.11 needs it (`PATCHES`).
- `mapped`: hintsjax's `ppo_rgb` on `playground:CartpoleBalance:vision` (the same model, reward
  and ends, envs/playground.py `VisionTask`, stepped by MJX's JAX physics where Playground's uses
  MuJoCo Warp's; its own 64x64 pictures of the same camera, grey and
  the last 3 side by side as Playground's agent sees its last 3, `frames=3 colour=grey`) with
  Playground's settings mapped onto hintsjax's (`mapped_values`), seeds vmapped in one program.
- `mapped_cnn`: the same with Brax's CNN (`ppo.encoder=brax_vision`): the encoder's part;
- `mapped_nets`: Brax's CNN and one for the critic of its own (`ppo.critic_encoder=own`), as
  Brax's policy and value networks each have one;
- `mapped_scale`: those, with the pictures in Playground's range, [-0.5, 0.5] (`ppo.pixel_scale`);
- `mapped_loss`: those, with the value loss weighted as Brax's (`ppo.vf_coef`, `BRAX_VALUE_WEIGHT`);
- `mapped_swish`: those, with swish MLPs (`ppo.activation=swish`); `mapped_std`: and Brax's std
  head, a softplus of the actor's outputs (`ppo.std_head=softplus`); `mapped_timeout`: and no
  bootstrap at the time limit (`ppo.bootstrap_truncated=false`), Brax's defaults all three;
- `mapped_one`: `mapped` with one picture at a time (`frames=1`): the frame stack's part in the
  difference, one knob; `mapped_first`: the mapping as first built, one RGB picture and the
  entropy bonus of the Gaussian before the squash (`ppo.squashed_entropy=false`).
- `defaults`: hintsjax's defaults for the env (one picture).
Each side's seconds run from its start (renderer build or trace) to the trained policies, with
compile and renderer build given apart; each seed's final policy then plays `EVAL_EPISODES` fresh
episodes, deterministic (mean action), in its own pipeline's evaluator on the same reward. The
record is runs/<runs>/versus_vision.json, which each side fills in; --report writes its section.
"""

from __future__ import annotations

import argparse
import functools
import json
import math
import os
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from playground import (  # noqa: E402
    archive_file,
    mend_brax_for_this_jax,
    record_side,
    steps_per_update,
)

from hintsjax.reproduce.markdown import generated_marker  # noqa: E402

TASK = "CartpoleBalance"
ENV = f"playground:{TASK}:vision"
SIDES = (
    "playground",
    "mapped",
    "mapped_cnn",
    "mapped_nets",
    "mapped_scale",
    "mapped_loss",
    "mapped_swish",
    "mapped_std",
    "mapped_timeout",
    "mapped_one",
    "mapped_first",
    "defaults",
)
TRAINERS = {
    "playground": "Playground + brax.training vision PPO",
    "mapped": "hintsjax ppo_rgb, Playground's settings",
    "mapped_cnn": "hintsjax ppo_rgb, Playground's settings, Brax's CNN",
    "mapped_nets": "hintsjax ppo_rgb, Playground's settings, Brax's CNN, one a network",
    "mapped_scale": "hintsjax ppo_rgb, Playground's settings, Brax's CNN, one a network, "
    "Playground's pixel range",
    "mapped_loss": "hintsjax ppo_rgb, Playground's settings, Brax's CNN, one a network, "
    "Playground's pixel range, Brax's value-loss weight",
    "mapped_swish": "hintsjax ppo_rgb, Playground's settings, Brax's CNN, one a network, "
    "Playground's pixel range, Brax's value-loss weight, swish",
    "mapped_std": "hintsjax ppo_rgb, Playground's settings, Brax's CNN, one a network, "
    "Playground's pixel range, Brax's value-loss weight, swish, Brax's std",
    "mapped_timeout": "hintsjax ppo_rgb, Playground's settings, Brax's CNN, one a network, "
    "Playground's pixel range, Brax's value-loss weight, swish, Brax's std, no timeout bootstrap",
    "mapped_one": "hintsjax ppo_rgb, Playground's settings, one picture",
    "mapped_first": "hintsjax ppo_rgb, Playground's settings, one picture, the Gaussian's entropy",
    "defaults": "hintsjax ppo_rgb, its defaults",
}
# Playground's vision cartpole shows its agent its last 3 frames (cartpole.py's `frame_stack`),
# each grey (the mean of its RGB channels)
PLAYGROUND_FRAMES, PLAYGROUND_COLOUR = 3, "grey"
# Brax's value loss is 0.5 x vf_loss_coefficient (its train()'s 0.5; Playground's config keeps it) x
# the mean square error; hintsjax's is ppo.vf_coef x the mean square error
BRAX_VALUE_WEIGHT = 0.5 * 0.5
# Each mapped side's knobs (mapped_values' arguments: the pictures', then PPO settings by name): a
# knob step's are the step before it's and its own, in KNOB_STEPS' order
_CNN = {"encoder": "brax_vision"}
_NETS = {**_CNN, "critic_encoder": "own"}
_SCALE = {**_NETS, "pixel_scale": 0.5}
_LOSS = {**_SCALE, "vf_coef": BRAX_VALUE_WEIGHT}
_SWISH = {**_LOSS, "activation": "swish"}
_STD = {**_SWISH, "std_head": "softplus"}
MAPPED_KNOBS = {
    "mapped": {},
    "mapped_cnn": _CNN,
    "mapped_nets": _NETS,
    "mapped_scale": _SCALE,
    "mapped_loss": _LOSS,
    "mapped_swish": _SWISH,
    "mapped_std": _STD,
    "mapped_timeout": {**_STD, "bootstrap_truncated": False},
    "mapped_one": {"frames": 1},
    "mapped_first": {"frames": 1, "squashed": False, "colour": "rgb"},
}
EVAL_EPISODES = 128
RECORD = "versus_vision.json"  # under the runs folder
# The playground side's finished seeds, a row each (under the runs folder): its 5 seeds take longer
# than one GPU lease, so a later process goes on from them
SEEDS_DONE = "versus_vision_playground_seeds.jsonl"
DEFAULT_RUNS = "runs/playground"
RESULTS = Path(__file__).resolve().parent / "results"
CURVES = "playground_vision_curves.png"  # under RESULTS
REPORT = "playground.md"  # under RESULTS: this script's section, below experiments/playground.py's
SECTION = generated_marker(Path(__file__).name, "--report")
CHUNK_STEPS = 2**17
PATCHES = (
    "jax.device_put_replicated put back (jax 0.10 removed it; brax 0.14.2 calls it once, to "
    "replicate the training state on the one device)",
)


def vision_settings(smoke: bool) -> dict:
    """Playground's published vision PPO settings for the task (tiny with `smoke`)."""
    from mujoco_playground.config import dm_control_suite_params

    # plain dicts all the way down: the record holds them (its init kwargs are ConfigDicts too)
    settings = dm_control_suite_params.brax_vision_ppo_config(TASK).to_dict()
    if smoke:
        settings.update(
            num_timesteps=2048, num_evals=2, num_envs=16, batch_size=16, num_minibatches=2,
            unroll_length=8, num_updates_per_batch=1, num_eval_envs=16,
        )  # fmt: skip
    return settings


def brax_updates(s: dict) -> int:
    """The training steps Brax's `train` takes for `s` (brax/training/agents/ppo/train.py):
    num_evals - 1 epochs (at least 1) x max(num_resets_per_eval, 1) x the ceiling of the budget
    over that product's env steps."""
    epochs = max(s["num_evals"] - 1, 1) * max(s.get("num_resets_per_eval", 0), 1)
    return epochs * math.ceil(s["num_timesteps"] / (epochs * steps_per_update(s)))


def mapped_values(
    s: dict,
    seeds: int,
    smoke: bool,
    frames: int = PLAYGROUND_FRAMES,
    squashed: bool = True,
    colour: str = PLAYGROUND_COLOUR,
    **knobs,
) -> dict:
    """hintsjax's run config with Playground's vision settings where hintsjax has the knob: an
    update of num_envs rollouts of batch_size x num_minibatches x unroll_length / num_envs steps,
    num_updates_per_batch epochs of num_minibatches minibatches; GAE over each unroll (Brax's),
    the discount, one learning rate for encoder, actor and critic, the entropy cost, the ratio
    clip, clipping of the whole gradient, Brax's tanh-squashed Gaussian and its entropy bonus (the
    squashed action's), Adam's epsilon (optax's default), the MLPs' widths, the last `frames`
    pictures side by side (Playground's 3, or one for `mapped_one`) in `colour` (Playground's
    grey). `knobs`, PPO settings by name over those (MAPPED_KNOBS holds each side's), map more:
    Brax's CNN (`encoder`), one for the critic (`critic_encoder`), Playground's pixel range, ...
    Left at hintsjax's: what `UNMAPPED` lists."""
    batch = steps_per_update(s)
    rate = s["learning_rate"]
    ppo = {
        "total_env_steps": brax_updates(s) * batch,
        "num_envs": s["num_envs"],
        "batch_size": batch,
        "minibatch_size": batch // s["num_minibatches"],
        "epochs": s["num_updates_per_batch"],
        "gae_segment": s["unroll_length"],
        "gamma": s["discounting"],
        "encoder_lr": rate,
        "actor_lr": rate,
        "critic_lr": rate,
        "ent_coef": s["entropy_cost"],
        "clip_eps": s["clipping_epsilon"],
        "max_grad_norm": s["max_grad_norm"],
        "grad_clip": "global",
        "action_head": "tanh",
        "squashed_entropy": squashed,  # Brax's tanh-normal bonus: the squashed action's entropy
        "adam_eps": 1e-8,
        "reward_scale": s["reward_scaling"],
        "hidden": list(s["network_factory"]["policy_hidden_layer_sizes"]),
        **knobs,
    }
    return {**common_values(seeds, smoke), "frames": frames, "colour": colour, "ppo": ppo}


def default_values(s: dict, seeds: int, smoke: bool) -> dict:
    """hintsjax's defaults for the env, at the playground side's env steps a seed."""
    return {
        **common_values(seeds, smoke),
        "ppo": {"total_env_steps": brax_updates(s) * steps_per_update(s)},
    }


def common_values(seeds: int, smoke: bool) -> dict:
    values = {"env": ENV, "agent": "ppo_rgb", "seeds": seeds, "checkpoint_every": 10**9}
    return {**values, "image_size": 36} if smoke else values


class MemoryWatch:
    """The device's largest memory in use while the side runs: XLA's own peak (what its allocator
    handed out), and nvidia-smi's reading every half second (the process's whole use, Warp's
    renderer and the CUDA context included; None without nvidia-smi)."""

    def __init__(self) -> None:
        self.smi_mib: int | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._watch, daemon=True)
        self._thread.start()

    def _watch(self) -> None:
        while not self._stop.wait(0.5):
            try:
                out = subprocess.run(
                    ["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                    capture_output=True, text=True, timeout=10, check=True,
                )  # fmt: skip
            except (OSError, subprocess.SubprocessError):
                return
            used = max(int(x) for x in out.stdout.split())
            self.smi_mib = max(self.smi_mib or 0, used)

    def peek(self) -> dict:
        """The peaks so far (the watch goes on)."""
        import jax

        stats = jax.devices()[0].memory_stats() or {}
        peak = stats.get("peak_bytes_in_use")
        return {"xla_peak_mib": peak and round(peak / 2**20), "nvidia_smi_peak_mib": self.smi_mib}

    def result(self) -> dict:
        """The peaks, the watch stopped."""
        self._stop.set()
        return self.peek()


def largest(memories: list[dict]) -> dict:
    """Each peak's largest over `memories` (None where none measured it)."""
    keys = ("xla_peak_mib", "nvidia_smi_peak_mib")
    return {k: max((m[k] for m in memories if m.get(k) is not None), default=None) for k in keys}


def finished_seeds(path: Path, budget: dict) -> dict[int, dict]:
    """The playground side's seeds finished at `budget` by earlier processes (SEEDS_DONE's rows:
    one a seed, appended as each ends), so that a side longer than one GPU lease goes on."""
    if not path.exists():
        return {}
    rows = [json.loads(line) for line in path.read_text().splitlines() if line.strip()]
    return {row["seed"]: row for row in rows if row["budget"] == budget}


def seeds_path(runs: Path) -> Path:
    """The playground side's seed rows: under `runs` where they are, else their archived copy
    (what --report archives), so a fresh checkout goes on from the archived seeds."""
    from hintsjax.reproduce.archive import ARCHIVE

    path = runs / SEEDS_DONE
    archived = ARCHIVE / runs.name / SEEDS_DONE
    return path if path.exists() or not archived.exists() else archived


def train_playground(
    s: dict,
    seeds: int,
    episodes: int,
    done_path: Path,
    budget: dict,
    watch: MemoryWatch | None = None,
) -> dict:
    """Playground's side, as its vision notebook trains it: per seed, the env (its renderer built
    for num_envs worlds) and an evaluation env (for num_eval_envs), then Brax's `train`; Brax's
    progress calls (its own evaluations) timed from the seed's start. Then the seed's policy on
    `episodes` fresh episodes, deterministic, by Brax's Evaluator on an env rendering as many
    (built once), and the seed's row (with the process's memory peaks so far, `watch`'s)
    appended to `done_path`; seeds found there are skipped. The side's memory is the largest of
    its rows'."""
    import jax
    from brax.training import acting
    from brax.training.agents.ppo import networks_vision
    from brax.training.agents.ppo import train as ppo
    from mujoco_playground import registry, wrapper

    from hintsjax.envs.physics import enable_warp

    mend_brax_for_this_jax()
    enable_warp()  # Playground's physics and renderer are MuJoCo Warp's (hintsjax's MJX lacks it)

    def vision_env(worlds: int):
        config = registry.get_default_config(TASK)
        config["vision"] = True
        config.vision_config.nworld = worlds
        return registry.load(TASK, config=config)

    run = dict(s)
    factory = functools.partial(
        networks_vision.make_ppo_networks_vision, **run.pop("network_factory")
    )
    done, final_env = finished_seeds(done_path, budget), None
    process = time.strftime("%Y-%m-%d %H:%M:%S")  # which process trained a seed: its start
    for seed in range(seeds):
        if seed in done:
            print(f"seed {seed}: finished by an earlier process ({done_path}), kept", flush=True)
            continue
        start = time.time()
        env, eval_env = vision_env(run["num_envs"]), vision_env(run["num_eval_envs"])
        built = time.time() - start
        progress: list = []

        def record(step, metrics, progress=progress, start=start, seed=seed):
            row = {"step": int(step), "seconds": round(time.time() - start, 2)}
            for key in ("eval/episode_reward", "training/sps", "training/walltime"):
                if key in metrics:
                    row[key] = round(float(metrics[key]), 3)
            progress.append(row)
            print(f"seed {seed}: {row}", flush=True)

        make_policy, params, _ = ppo.train(
            environment=env,
            eval_env=eval_env,
            wrap_env_fn=wrapper.wrap_for_brax_training,
            network_factory=factory,
            progress_fn=record,
            seed=seed,
            **run,
        )
        seconds = time.time() - start
        if final_env is None:
            final_env = wrapper.wrap_for_brax_training(
                vision_env(episodes), episode_length=run["episode_length"], action_repeat=1
            )
        evaluator = acting.Evaluator(
            final_env,
            functools.partial(make_policy, deterministic=True),
            num_eval_envs=episodes,
            episode_length=run["episode_length"],
            action_repeat=1,
            key=jax.random.PRNGKey(1000 + seed),
        )
        done[seed] = {
            "seed": seed,
            "budget": budget,
            "seconds": seconds,
            "renderer_build_seconds": built,
            "progress": progress,
            "deterministic": float(evaluator.run_evaluation(params, {})["eval/episode_reward"]),
            "device": jax.devices()[0].device_kind,
            "date": time.strftime("%Y-%m-%d %H:%M"),
            "process": process,
            "memory": watch.peek() if watch else {},
        }
        with done_path.open("a") as f:
            f.write(json.dumps(done[seed]) + "\n")
    seeds_out = [
        {
            k: done[seed][k]
            for k in ("seconds", "renderer_build_seconds", "progress", "device", "date", "process")
        }
        for seed in range(seeds)
    ]
    return {
        "seconds": sum(x["seconds"] for x in seeds_out),
        "renderer_build_seconds": sum(x["renderer_build_seconds"] for x in seeds_out),
        "seeds_run": seeds_out,
        "deterministic": [done[seed]["deterministic"] for seed in range(seeds)],
        "env_steps_per_seed": seeds_out[0]["progress"][-1]["step"],
        "settings": {**s, "num_timesteps_taken": brax_updates(s) * steps_per_update(s)},
        "patches": list(PATCHES),
        "memory": largest([done[seed].get("memory", {}) for seed in range(seeds)]),
    }


def train_hintsjax(values: dict, episodes: int, label: str) -> dict:
    """A hintsjax side: its seeds vmapped in one program, compiled ahead (the seconds given
    apart), then run chunk by chunk to the configured updates, each chunk timed; then each seed's
    final policy on `episodes` fresh episodes, deterministic."""
    import jax
    import numpy as np

    from hintsjax.algorithms.registry import make_trainer
    from hintsjax.evaluation.evaluator import compile_evaluator, evaluate_variants
    from hintsjax.settings.layers import run_config, to_dict

    cfg = run_config(values)
    updates = cfg.ppo.num_updates
    # chunks of at most CHUNK_STEPS env steps a seed: a curve of tens of points, few dispatches
    most = max(1, CHUNK_STEPS // cfg.ppo.batch_size)
    every = max(d for d in range(1, min(updates, most) + 1) if updates % d == 0)
    trainer = make_trainer(cfg)
    start = time.time()
    state = jax.jit(jax.vmap(trainer.init))(cfg.seed_keys())
    chunk = jax.jit(jax.vmap(lambda s: trainer.run(s, every))).lower(state).compile()
    compiled = time.time() - start
    progress = []
    for _ in range(updates // every):
        state, metrics = chunk(state)
        returns = np.asarray(metrics["episode_return"])[:, -1]
        progress.append(
            {
                "step": int(np.asarray(state.update)[0]) * cfg.ppo.batch_size,
                "seconds": round(time.time() - start, 2),
                "training_return": [round(float(x), 2) for x in returns],
            }
        )
        print(f"{label}: {progress[-1]}", flush=True)
    seconds = time.time() - start
    evaluator = compile_evaluator(cfg, state.params, None, episodes)
    summary = evaluate_variants(cfg, state.params, (None,), episodes, False, evaluator)[0][0]
    return {
        "seconds": seconds,
        "compile_seconds": compiled,
        "progress": progress,
        "deterministic": [float(x) for x in summary["seed_means"]],
        "env_steps_per_seed": updates * cfg.ppo.batch_size,
        "settings": {
            "frames": cfg.frames,
            "colour": cfg.colour,
            "image_size": cfg.image_size,
            **to_dict(cfg)["ppo"],
        },
    }


def side_values(side: str, s: dict, seeds: int, smoke: bool) -> dict:
    """A hintsjax side's run config values: Playground's settings `s` mapped with its knobs, or
    hintsjax's defaults."""
    if side in MAPPED_KNOBS:
        return mapped_values(s, seeds, smoke, **MAPPED_KNOBS[side])
    return default_values(s, seeds, smoke)


def side_parts(side: str, seeds: int, smoke: bool, out: Path | None) -> dict:
    """One update of a hintsjax side split into its parts, ms (bench.py's `update_parts` on the
    side's own config: the rollout, the learning, the env steps with and without pictures and
    starts, the policy's passes): where its seeds spend what Playground's seed spends faster
    (the section). The env-step parts draw the env's own picture, one RGB, not the side's stack."""
    import jax
    from bench import update_parts  # experiments/bench.py, beside this script

    from hintsjax.algorithms.registry import make_trainer
    from hintsjax.settings.layers import run_config
    from hintsjax.system import xla_flags

    cfg = run_config(side_values(side, vision_settings(smoke), seeds, smoke))
    state = jax.jit(jax.vmap(make_trainer(cfg).init))(cfg.seed_keys())
    parts, _ = update_parts(cfg, state)
    row = {
        "side": side,
        "seeds": seeds,
        "num_envs": cfg.ppo.num_envs,
        "rollout_length": cfg.ppo.rollout_length,
        "env_steps_per_update": seeds * cfg.ppo.batch_size,
        "physics": cfg.physics,
        "deterministic_ops": xla_flags.deterministic_gpu_ops(),
        "device": str(jax.devices()[0].device_kind),
        "date": time.strftime("%Y-%m-%d %H:%M"),
        "parts_ms": {k: round(1e3 * v, 2) for k, v in parts.items()},
    }
    print(f"{TRAINERS[side]}: " + ", ".join(f"{k} {v} ms" for k, v in row["parts_ms"].items()))
    if out is not None:
        out.write_text(json.dumps(row, indent=1) + "\n")
    return row


def train_side(side: str, runs: Path, seeds: int, smoke: bool) -> None:
    """One side in this process, into the record (re-read at the end, so other sides' entries
    stay; a record of another budget is started afresh)."""
    import jax

    s = vision_settings(smoke)
    episodes = 4 if smoke else EVAL_EPISODES
    budget = {
        "task": TASK,
        "seeds": seeds,
        "env_steps_per_seed": brax_updates(s) * steps_per_update(s),
        "smoke": smoke,
    }
    print(
        f"{TRAINERS[side]}: {seeds} seeds x {budget['env_steps_per_seed']:,} env steps", flush=True
    )
    if side == "playground" and jax.default_backend() != "gpu":
        sys.exit("the playground side needs a GPU: MuJoCo Warp's batch renderer runs on CUDA only")
    watch = MemoryWatch()
    if side == "playground":
        runs.mkdir(parents=True, exist_ok=True)
        done = runs / SEEDS_DONE
        if not done.exists() and seeds_path(runs) != done:  # go on from the archived seeds
            shutil.copyfile(seeds_path(runs), done)
        result = train_playground(s, seeds, episodes, done, budget, watch)
    else:
        result = train_hintsjax(side_values(side, s, seeds, smoke), episodes, TRAINERS[side])
    entry = {"trainer": TRAINERS[side], "memory": watch.result(), **result}
    record_side(
        runs / RECORD, budget, side, {**entry, "eval_episodes": episodes, "versions": versions()}
    )
    print(f"{TRAINERS[side]}: {result['seconds']:.0f} s; returns {result['deterministic']}")


def versions() -> dict:
    from importlib import metadata

    names = ("jax", "jaxlib", "mujoco", "mujoco-mjx", "warp-lang", "brax", "playground", "flax")
    found = {}
    for name in names:
        try:
            found[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            found[name] = None
    return found


# -- the report ----------------------------------------------------------------------------------


# Brax's progress rows of a seed: the evaluation before training, then one an epoch. Its first two
# epochs compile (the record's second epoch is about 10 s slower than the later ones in every seed,
# also where the process had compiled a seed before; a CPU run's log showed jit(_fun) compiling in
# both), so its steady rate is from the epochs after them.
COMPILING_EPOCHS = 2


def steady_rate(result: dict, side: str) -> float:
    """Training env steps/s a seed, compile aside: Playground's from Brax's `training/sps` of its
    epochs after the compiling ones, hintsjax's from its chunks after the first."""
    if side == "playground":
        rates = [
            row["training/sps"]
            for run in result["seeds_run"]
            for row in run["progress"][1 + COMPILING_EPOCHS :]
            if "training/sps" in row
        ]
        return sum(rates) / len(rates) if rates else float("nan")
    rows = result["progress"]
    if len(rows) < 2:
        return float("nan")
    return (rows[-1]["step"] - rows[0]["step"]) / (rows[-1]["seconds"] - rows[0]["seconds"])


def playground_overheads(result: dict) -> dict[str, float]:
    """Playground's seconds that are not steady training, summed over its seeds: `before` its
    first epoch (the renderer build, the programs compiled before training, the evaluation at step
    0), the `compiling` epochs' seconds beyond the steady rate, and its `evaluations` between
    epochs (Brax's `training/walltime` counts training alone)."""
    rate = steady_rate(result, "playground")
    out = dict(before=0.0, compiling=0.0, evaluations=0.0)
    for run in result["seeds_run"]:
        rows = run["progress"]
        out["before"] += rows[0]["seconds"]
        walls = [0.0] + [row["training/walltime"] for row in rows[1:]]
        steps = [row["step"] for row in rows]
        for i in range(1, min(1 + COMPILING_EPOCHS, len(rows))):  # a smoke run has one
            out["compiling"] += walls[i] - walls[i - 1] - (steps[i] - steps[i - 1]) / rate
        out["evaluations"] += run["seconds"] - rows[0]["seconds"] - walls[-1]
    return out


def section_lines(runs: Path) -> list[str]:
    """The side by side's section of results/playground.md."""
    from hintsjax.reproduce import stats
    from hintsjax.reproduce.archive import ARCHIVE
    from hintsjax.reproduce.markdown import markdown_table

    lines = ["## Pixel PPO beside Playground's vision PPO (issue 83)", ""]
    path = runs / RECORD
    path = path if path.exists() else ARCHIVE / runs.name / RECORD
    if not path.exists():
        return lines + [f"Not run yet (`python experiments/{Path(__file__).name}`: {RECORD}).", ""]
    record = json.loads(path.read_text())
    results, rows = record["results"], []
    # Playground's seconds that are not steady training (its row's cell, a line below the table)
    overheads = playground_overheads(results["playground"]) if "playground" in results else None
    episodes = max((r["eval_episodes"] for r in results.values()), default=EVAL_EPISODES)
    for side in SIDES:
        if side not in results:
            rows.append([TRAINERS[side], *["-"] * 8, "not run yet"])
            continue
        r = results[side]
        if side == "playground":
            setting_up = overheads["before"] + overheads["compiling"]
            apart = f"{setting_up:.0f} (renderer {r['renderer_build_seconds']:.0f})"
        else:
            apart = f"{r['compile_seconds']:.0f}"
        memory = r["memory"]
        rows.append(
            [
                r["trainer"],
                pictures(r, side),
                f"{r['env_steps_per_seed']:,}",
                stats.iqm_cell(r["deterministic"]),
                " ".join(f"{x:.1f}" for x in r["deterministic"]),
                f"{r['seconds']:.0f}",
                apart,
                f"{steady_rate(r, side):,.0f}",
                f"{memory['nvidia_smi_peak_mib'] or '-'} / {memory['xla_peak_mib'] or '-'}",
                f"{r['device']}, {r['date']}: `{r['command']}`",
            ]
        )
    lines += [
        f"{record['task']} from 64x64 pictures, {record['seeds']} seeds x "
        f"{record['env_steps_per_seed']:,} env steps a seed on every side"
        f"{' (smoke: the numbers mean nothing)' if record['smoke'] else ''}. Final return: each "
        f"seed's final policy on {episodes} fresh episodes, deterministic, in its own pipeline's "
        "evaluator, on the vision task's reward (at most 250 steps). Wall-clock: from "
        "the side's start to the trained policies, Playground's seeds one after another, "
        "hintsjax's vmapped in one program. Given apart: hintsjax's compile; Playground's "
        "seconds before its first epoch (the renderer build, also given alone, its programs' "
        "compiles, its evaluation at step 0) and those of its first "
        f"{COMPILING_EPOCHS} epochs beyond its steady rate (Brax compiles its epoch's program in "
        "each). Training env steps/s: the steady rate, Playground's from its later epochs, "
        "hintsjax's from its chunks after the first. Physics: Playground's side steps with MuJoCo "
        "Warp (its task's default), hintsjax's with MJX's JAX physics, the same model.",
        "",
    ]
    lines += markdown_table(
        [
            "side",
            "pictures a step",
            "env steps a seed",
            "final return: IQM [95% CI]",
            "per seed",
            "wall-clock (s)",
            "of it apart (s)",
            "training env steps/s a seed",
            "peak GPU MiB (nvidia-smi / XLA)",
            "GPU, date, command",
        ],
        rows,
    )
    if "playground" in results:
        lines += [
            "",
            "Patches to Playground's side: " + "; ".join(results["playground"]["patches"]),
            "",
            f"Playground's wall-clock holds at most {overheads['evaluations']:.0f} s of Brax's "
            "evaluations between its epochs (its seeds' seconds less those before the first epoch "
            "and its `training/walltime`, so the seconds around them too); hintsjax's sides "
            "evaluate only after training, outside theirs.",
        ]
        processes = {run.get("process") for run in results["playground"]["seeds_run"]}
        if len(processes) > 1:
            lines += [
                "",
                f"Playground's seeds were trained in {len(processes)} processes, one a GPU lease "
                "(versus_vision_playground_seeds.jsonl): each process's first seed paid its "
                "compile, so its wall-clock is the sum of its seeds', and its peak memory is the "
                "largest its seeds' rows measured (the first rows, of 2026-12-04, measured none).",
            ]
    if "playground" not in results:
        lines += waiting_seeds(runs, record)
    ours = [side for side in SIDES[1:] if side in results]
    if "playground" in results and ours:
        lines += ["", "Each hintsjax side against Playground's:"]
        lines += [against_playground(results, side) for side in ours]
    lines += [
        "",
        f"![return against wall-clock, a line a seed]({CURVES}) Return against the seconds from "
        "each side's start: Playground's from Brax's evaluations between epochs (stochastic, "
        "each seed from its own start), hintsjax's from its training episodes (its seeds at "
        "once); neither is the final deterministic return of the table.",
    ]
    knobs = knob_lines(results)
    if knobs:
        lines += ["", "Knob by knob, from hintsjax's defaults to Playground's settings:", *knobs]
        lines += ["", "What no side maps yet:", *(f"- {item}" for item in UNMAPPED)]
    return lines + [""]


# What no hintsjax side maps of Playground's side, read from Brax 0.14.2 (ppo/losses.py, train.py,
# networks.py, networks_vision.py, distribution.py) and Playground 0.2.0 (brax_vision_ppo_config,
# wrapper.py's BraxAutoResetWrapper, cartpole.py)
UNMAPPED = (
    "the inits: Brax's MLPs LeCun-uniform, its policy's output layer orthogonal at 0.2 and its "
    "CNNs orthogonal at sqrt 2; hintsjax's He-normal, its output layers LeCun-normal, the "
    "actor's x 0.01",
    "the advantages: Brax computes GAE again in every minibatch with the critic as it stands, "
    "minibatches of whole 20-step unrolls, and its advantage bootstraps from the next step's "
    "lambda-return (r + gamma vs(t+1) - v(t)); hintsjax's GAE once an update from the rollout's "
    "values, minibatches of single steps",
    "the resets: Playground's wrapper starts every episode of an env from that env's first start, "
    "and its frame stack carries the ended episode's last 2 pictures into the next one's second "
    "step; hintsjax draws a fresh start and repeats its first picture",
    "the entropy bonus's estimate: Brax one sample of the tanh's log-Jacobian, hintsjax a "
    "32-node quadrature",
    "the pictures' renderer: MuJoCo Warp's ray tracer against hintsjax's ray caster, other "
    "shading; hintsjax's grey pictures rounded to bytes, Playground's floats",
    "the physics: Playground's CartpoleBalance steps with MuJoCo Warp (its default `impl`), "
    "hintsjax's adapter with MJX's JAX physics (`impl=jax`), the same model and timestep",
)
# The sides in the order their knobs take hintsjax's defaults towards Playground's, each with the
# knobs it turns beyond the side before it
KNOB_STEPS = (
    ("defaults", ""),
    ("mapped_first", "Playground's settings mapped (`mapped_values`)"),
    (
        "mapped_one",
        "grey pictures and the squashed action's entropy bonus (mapped_first ran at an earlier "
        "commit)",
    ),
    ("mapped", "its 3 pictures a step, not 1"),
    ("mapped_cnn", "Brax's CNN (`ppo.encoder=brax_vision`), one for actor and critic"),
    ("mapped_nets", "a CNN of the critic's own (`ppo.critic_encoder=own`), as Brax's value net"),
    ("mapped_scale", "the pictures in [-0.5, 0.5] (`ppo.pixel_scale=0.5`), as Playground's"),
    ("mapped_loss", f"the value loss weighted as Brax's (`ppo.vf_coef={BRAX_VALUE_WEIGHT:g}`)"),
    ("mapped_swish", "swish MLPs (`ppo.activation=swish`), as Brax's"),
    (
        "mapped_std",
        "Brax's std, softplus of the actor's outputs + 0.001 (`ppo.std_head=softplus`)",
    ),
    (
        "mapped_timeout",
        "no bootstrap at the time limit (`ppo.bootstrap_truncated=false`), as Brax's default",
    ),
    ("playground", "what is left (below)"),
)


def knob_lines(results: dict) -> list[str]:
    """A line for each two sides in the record next in KNOB_STEPS's order: the knobs between them
    (a side not run passes its knobs on to the next), the IQMs before and after and the ordering
    of the two sides' final returns."""
    from hintsjax.reproduce import stats

    lines, before, knobs = [], None, []
    for side, turns in KNOB_STEPS:
        knobs += [turns] if turns else []
        if side not in results:
            continue
        if before is not None:
            x, y = results[side]["deterministic"], results[before]["deterministic"]
            ordering = stats.ordering_text(side, before, stats.poi_ci(x, y))
            lines.append(
                f"- {before} -> {side}, {'; '.join(knobs)}: IQM {stats.iqm_cell(y)} -> "
                f"{stats.iqm_cell(x)}; {ordering}"
            )
        before, knobs = side, []
    return lines


def against_playground(results: dict, side: str) -> str:
    """A hintsjax side's line against Playground's: the ordering of their final returns, the
    wall-clock of their seeds, and their training rates (hintsjax's seeds at once, Playground's
    one after another); the times only where both sides ran on the same kind of GPU."""
    from hintsjax.reproduce import stats

    ours, theirs = results[side], results["playground"]
    seeds = len(ours["deterministic"])
    ordering = stats.ordering_text(
        TRAINERS[side],
        TRAINERS["playground"],
        stats.poi_ci(ours["deterministic"], theirs["deterministic"]),
    )
    # Playground's seeds may finish over several processes, each on the machine of its day
    their_devices = {theirs.get("device")} | {r.get("device") for r in theirs.get("seeds_run", [])}
    their_devices.discard(None)
    if their_devices != {ours.get("device")}:
        return (
            f"- {side}: {ordering}; its times are not set against Playground's: it ran on "
            f"{ours.get('device')}, Playground on {' and '.join(sorted(their_devices)) or None}"
        )
    times = theirs["seconds"] / ours["seconds"]
    rate, their_rate = steady_rate(ours, side) * seeds, steady_rate(theirs, "playground")
    rates = f" ({rate / their_rate:.1f}x)" if their_rate > 0 else ""
    return (
        f"- {side}: {ordering}; its {seeds} seeds in {ours['seconds']:.0f} s against "
        f"{theirs['seconds']:.0f} s ({max(times, 1 / times):.1f}x "
        f"{'faster' if times >= 1 else 'slower'}), training {rate:,.0f} env steps/s over its "
        f"seeds at once against {their_rate:,.0f}{rates}"
    )


def waiting_seeds(runs: Path, record: dict) -> list[str]:
    """Lines on the playground side's seeds finished at the record's budget whose entry is not
    written yet (SEEDS_DONE's rows, under `runs` or archived): their returns and seconds."""
    budget = {k: record[k] for k in ("task", "seeds", "env_steps_per_seed", "smoke")}
    done = finished_seeds(seeds_path(runs), budget)
    if not done:
        return []
    rows = [done[seed] for seed in sorted(done)]
    returns = " ".join(f"{row['deterministic']:.1f}" for row in rows)
    where = ", ".join(sorted({f"{row['device']}, {row['date'][:10]}" for row in rows}))
    return [
        "",
        f"Playground's side has {len(rows)} of {record['seeds']} seeds finished, its entry not "
        f"written yet ({SEEDS_DONE}; its peak memory is the largest its rows measured): "
        f"final returns {returns}, {sum(row['seconds'] for row in rows):.0f} s in all ({where}).",
    ]


def pictures(result: dict, side: str) -> str:
    """What a side's agent sees a step: its frames and colour (Playground's: 3 grey)."""
    if side == "playground":
        return f"{PLAYGROUND_FRAMES} {PLAYGROUND_COLOUR}"
    settings = result.get("settings", {})
    return f"{settings.get('frames', 1)} {settings.get('colour', 'rgb')}"


def plot(runs: Path, out: Path) -> None:
    """Return against wall-clock per side and seed: Playground's from Brax's evaluations during
    training (num_eval_envs episodes, stochastic), hintsjax's from its training episodes."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    record = json.loads((runs / RECORD).read_text())
    fig, ax = plt.subplots(figsize=(7, 4))
    tab20 = plt.get_cmap("tab20").colors
    colours = tab20[::2] + tab20[1::2]  # the 10 dark ones, then their light twins
    assert len(colours) >= len(SIDES), "a colour for each side"
    for side, colour in zip(SIDES, colours):
        r = record["results"].get(side)
        if r is None:
            continue
        if side == "playground":
            for i, run in enumerate(r["seeds_run"]):
                points = [(p["seconds"], p["eval/episode_reward"]) for p in run["progress"]
                          if "eval/episode_reward" in p]  # fmt: skip
                ax.plot(*zip(*points), color=colour, label=TRAINERS[side] if i == 0 else None)
            continue
        seconds = [p["seconds"] for p in r["progress"]]
        for i in range(len(r["deterministic"])):
            ax.plot(
                seconds,
                [p["training_return"][i] for p in r["progress"]],
                color=colour,
                alpha=0.7,
                label=TRAINERS[side] if i == 0 else None,
            )
    ax.set(
        xlabel="seconds from the side's start (Playground: the seed's)",
        ylabel="episode return",
        title="Playground: Brax's evaluations; hintsjax: its training episodes",
    )
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(out, dpi=120)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", choices=SIDES, default=None, help="one side (default: each)")
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--runs", type=Path, default=Path(DEFAULT_RUNS))
    parser.add_argument("--smoke", action="store_true", help="tiny budgets: the plumbing")
    parser.add_argument("--report", action="store_true", help="archive the record, plot it")
    parser.add_argument(
        "--force", action="store_true", help="--report: rewrite playground.md though rows go"
    )
    parser.add_argument(
        "--parts",
        type=Path,
        default=None,
        metavar="JSON",
        help="with --side (a hintsjax side): one update's parts, ms, into this file; no training",
    )
    args = parser.parse_args()
    if args.seeds < 1:
        parser.error(f"--seeds must be 1 or more, got {args.seeds}")
    if args.parts is not None:
        if args.side in (None, "playground"):
            parser.error("--parts needs --side naming a hintsjax side")
        side_parts(args.side, args.seeds, args.smoke, args.parts)
        return
    if args.report:  # the record archived and plotted, its section of results/playground.md
        from hintsjax.reproduce.archive import ARCHIVE

        path = args.runs / RECORD
        if not path.exists():
            parser.error(f"no record to report: {path} (run the sides first)")
        if args.smoke:
            plot(args.runs, args.runs / CURVES)
            print("\n".join(section_lines(args.runs)))
            return
        for name in (RECORD, SEEDS_DONE):  # the record, and the playground side's seed rows
            archive_file(args.runs / name, ARCHIVE / args.runs.name / name)
        plot(args.runs, RESULTS / CURVES)
        from hintsjax.reproduce.markdown import write_section

        write_section(RESULTS / REPORT, SECTION, section_lines(args.runs), force=args.force)
        return
    if args.side:
        train_side(args.side, args.runs, args.seeds, args.smoke)
        return
    env = {**os.environ, "XLA_PYTHON_CLIENT_PREALLOCATE": "false"}
    for side in SIDES:  # a process each: its own memory peak and compile
        command = [sys.executable, __file__, "--side", side, "--seeds", str(args.seeds)]
        command += ["--runs", str(args.runs), *(["--smoke"] if args.smoke else [])]
        done = subprocess.run(command, env=env)
        if done.returncode:
            sys.exit(f"the {side} side failed (exit {done.returncode}); the others' entries stay")


if __name__ == "__main__":
    main()
