"""Trained experts: the policy of an `expert_ppo` run, exported for DAgger and GAIL to learn from.

    python -m hintsjax.run env=pendulum agent=expert_ppo name=expert-pendulum   # train (5 seeds)
    python -m hintsjax.expert runs/expert-pendulum  # -> hintsjax/experts/pendulum

Export keeps the seed with the best evaluation (eval.json's 50-episode mean, not a training
episode) and only what acting needs: the actor MLP's parameters, the learnt log std and, for a
run with ppo.normalize_state, the state normaliser's mean and variance, as an orbax checkpoint
beside `expert.json` (env, sizes, scores, the run's config). `load(env)` gives
the packaged expert of an env; DAgger and GAIL take any object with the same two methods
(`mean`, `sample`), which is how the tests give them a known linear expert.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import orbax.checkpoint as ocp
from flax import struct

from hintsjax.system import checkpoint, folder_lock, paths
from hintsjax.system.checkpoint import on_this_device, require_same_arrays
from hintsjax.system.errors import UsageError
from hintsjax.models import normalization
from hintsjax.models.networks import MLP
from hintsjax.settings.config import RunConfig, unreplayable
from hintsjax.settings.layers import load_run_config, to_dict
from hintsjax.algorithms import ppo

# the packaged experts, one folder per env
EXPERTS_DIR = Path(__file__).resolve().parents[1] / "experts"
EXPERT_JSON = "expert.json"
POLICY = "policy"  # the orbax checkpoint inside an expert folder
# What orbax writes into a checkpoint about the machine that wrote it, which a restore here does not
# read: the folder's absolute path (commit_success.txt) and the device each array was on (_sharding;
# `load` names its own). An exported expert drops them, so a packaged one ships only what a restore
# needs.
MACHINE_FILES = ("commit_success.txt", "_sharding")


@struct.dataclass
class Expert:
    """A state-based Gaussian policy: mean = actor(normalised state), std = exp(log_std)."""

    actor: Any  # the MLP's parameters
    log_std: jax.Array  # [A]
    hidden: tuple[int, ...] = struct.field(pytree_node=False)
    state_norm: Any = None  # {"mean", "var"} [n] of a run with ppo.normalize_state, else None

    def mean(self, state: jax.Array) -> jax.Array:
        """The expert's action (its Gaussian's mean) for a state [..., n] -> [..., A]."""
        if self.state_norm is not None:
            state = normalization.normalize(self.state_norm["mean"], self.state_norm["var"], state)
        return _actor(self.hidden, self.log_std.shape[-1]).apply({"params": self.actor}, state)

    def sample(self, key: jax.Array, state: jax.Array) -> jax.Array:
        """An action drawn from the expert's Gaussian."""
        mean = self.mean(state)
        return mean + jnp.exp(self.log_std) * jax.random.normal(key, mean.shape)


def _actor(hidden: tuple[int, ...], action_size: int) -> MLP:
    # ActorCritic's actor, parameter for parameter
    return MLP((*hidden, action_size), out_scale=0.01)


def packaged() -> list[str]:
    """The envs that have a packaged expert."""
    return (
        sorted(p.name for p in EXPERTS_DIR.iterdir() if (p / EXPERT_JSON).is_file())
        if EXPERTS_DIR.is_dir()
        else []
    )


def best_seed(evaluation: dict) -> int:
    """The seed an export keeps: the highest mean return of an eval.json evaluation."""
    means = evaluation["seed_means"]
    return max(range(len(means)), key=means.__getitem__)


def export(run_dir: Path, out_dir: Path | None = None, force: bool = False) -> Path:
    """Export the best seed of a finished state-based run as an expert folder; returns its path.
    An expert that is there already (a packaged one, by default) is replaced only with `force`."""
    cfg = load_run_config(run_dir)
    folder_lock.say_if_training(run_dir)
    if cfg.agent_spec.observe != ("state",) or cfg.agent_spec.algorithm != "ppo":
        raise UsageError(
            f"{run_dir} trained {cfg.agent}; an expert comes from a state PPO run "
            "(agent=expert_ppo)"
        )
    odd = unreplayable(cfg.ppo)  # what Expert cannot replay
    if odd:
        name, value, kept = odd
        raise UsageError(
            f"{run_dir} trained with ppo.{name}={value}; an expert replays ppo.{name}={kept} "
            "(train it so, e.g. agent=expert_ppo)"
        )
    eval_json = Path(run_dir) / "eval.json"
    if not eval_json.is_file():
        raise UsageError(
            f"{run_dir} has no eval.json: let the run finish (or resume it) before exporting"
        )
    out = Path(out_dir or EXPERTS_DIR / cfg.env).absolute()
    paths.check_folder(out, "--out")
    if (out / EXPERT_JSON).exists() and not force:
        raise UsageError(
            f"{out} holds an expert already "
            f"({cfg.env}'s{' packaged' if out.parent == EXPERTS_DIR.absolute() else ''} one); give "
            "--out another folder, or --force to replace it"
        )
    try:
        results = json.loads(eval_json.read_text())
        evaluation = results["evaluations"][0]
        best = best_seed(evaluation)
        scored = int(results.get("env_steps", cfg.ppo.num_updates * cfg.ppo.batch_size))
        scored //= cfg.ppo.batch_size
    except (ValueError, KeyError, IndexError, TypeError) as e:  # a damaged file, not a bug
        raise UsageError(
            f"{eval_json} is not a run's evaluation ({type(e).__name__}); resume the run to "
            f"write it again (python -m hintsjax.run resume={run_dir}), then export"
        ) from None
    state, update = checkpoint.restore_latest(run_dir, ppo.make_trainer(cfg).abstract_state())
    if update != scored:  # the newest could not be read: eval.json scored another
        raise UsageError(
            f"{run_dir}'s checkpoint of update {scored}, the policy eval.json scored, "
            f"cannot be read (the newest that can is update {update}): train its last updates "
            f"again (python -m hintsjax.run resume={run_dir}), then export"
        )
    params = jax.tree.map(lambda x: x[best], state.params["params"])
    policy = {"actor": params["actor"], "log_std": params["log_std"]}
    if normalization.COLLECTION in state.params:
        stats = jax.tree.map(
            lambda x: x[best], state.params[normalization.COLLECTION][normalization.NAME]
        )
        policy["state_norm"] = {"mean": stats["mean"], "var": stats["var"]}
    out.mkdir(parents=True, exist_ok=True)
    with ocp.StandardCheckpointer() as saver:
        saver.save(out / POLICY, policy, force=True)
    for name in MACHINE_FILES:
        (out / POLICY / name).unlink(missing_ok=True)
    meta = {
        "env": cfg.env,
        "state_size": int(params["actor"]["Dense_0"]["kernel"].shape[0]),
        "action_size": int(params["log_std"].shape[0]),
        "hidden": list(cfg.ppo.hidden),
        "normalize_state": "state_norm" in policy,
        "seed_index": best,
        "seed_eval_mean": evaluation["seed_means"][best],
        "run_eval_mean": evaluation["mean"],
        "run_eval_std": evaluation["std"],
        "episodes_per_seed": evaluation["episodes_per_seed"],
        "env_steps": update * cfg.ppo.batch_size,
        "source_run": Path(run_dir).name,
        "config": to_dict(cfg),
    }
    (out / EXPERT_JSON).write_text(json.dumps(meta, indent=1))
    return out


def describe(env: str, path: str | Path | None = None) -> tuple[Path, dict]:
    """The folder and expert.json of `env`'s expert at `path` (None: the packaged one);
    UsageError if it is missing, unreadable or for another env."""
    folder = Path(path) if path is not None else EXPERTS_DIR / env
    retrain = (
        f"train one with: python -m hintsjax.run env={env} agent=expert_ppo name=expert-{env} "
        f"&& python -m hintsjax.expert runs/expert-{env}"
    )
    if not (folder / EXPERT_JSON).is_file():
        raise UsageError(
            f"no expert for {env} at {folder} (packaged: {', '.join(packaged()) or 'none'}); "
            f"{retrain}"
        )
    try:
        meta = json.loads((folder / EXPERT_JSON).read_text())
        meta["hidden"], meta["state_size"], meta["action_size"] = (
            tuple(meta["hidden"]),
            int(meta["state_size"]),
            int(meta["action_size"]),
        )
    except (ValueError, KeyError, TypeError) as e:
        raise UsageError(
            f"{folder / EXPERT_JSON} is not an expert's description: {type(e).__name__}"
        ) from None
    if meta.get("env") != env:
        raise UsageError(f"the expert at {folder} is for {meta.get('env')}, not {env}; {retrain}")
    return folder, meta


def load(env: str, path: str | Path | None = None) -> Expert:
    """The expert at `path` (None: the env's packaged one); UsageError if missing, foreign or
    corrupt."""
    folder, meta = describe(env, path)
    hidden, sizes = meta["hidden"], (meta["state_size"], meta["action_size"])
    shapes = {
        "actor": jax.eval_shape(
            lambda: _actor(hidden, sizes[1]).init(jax.random.key(0), jnp.zeros((1, sizes[0])))[
                "params"
            ]
        ),
        "log_std": jax.ShapeDtypeStruct((sizes[1],), jnp.float32),
    }
    if meta.get("normalize_state"):
        shapes["state_norm"] = {
            k: jax.ShapeDtypeStruct((sizes[0],), jnp.float32) for k in ("mean", "var")
        }
    abstract = on_this_device(shapes)
    try:
        with ocp.StandardCheckpointer() as loader:
            require_same_arrays(
                loader.metadata((folder / POLICY).absolute()).item_metadata,
                abstract,
                "it describes",
            )
            params = loader.restore((folder / POLICY).absolute(), abstract)
    except Exception as e:  # orbax raises many types for unreadable or mismatched files
        reason = str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__
        raise UsageError(
            f"the expert checkpoint in {folder} is corrupt or does not match {EXPERT_JSON}: "
            f"{reason}"
        ) from None
    return Expert(params["actor"], params["log_std"], hidden, params.get("state_norm"))


def check_state_size(expert: Any, cfg: RunConfig, state_size: int) -> None:
    """UsageError unless a loaded expert reads states of the env's size."""
    if isinstance(expert, Expert):
        n = expert.actor["Dense_0"]["kernel"].shape[0]
        if n != state_size:
            raise UsageError(f"the expert reads {n} state numbers but {cfg.env} has {state_size}")
