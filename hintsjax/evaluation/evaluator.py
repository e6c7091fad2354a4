"""Evaluation: every training seed times N fresh episodes in one jitted call.

Each episode stops at its own end (rewards after `terminated | truncated` are not counted),
actions are the policy's mean unless `stochastic`, and deploy variants (e.g. pendulum's
swingto) evaluate an agent trained on the standard task. An env's `metrics` (the car's
progress) are kept from the state each episode ended in. The command on a run folder is
`python -m hintsjax.evaluate` (hintsjax/evaluate.py).
"""

from __future__ import annotations

import time
from typing import Any, Callable

import jax
import jax.numpy as jnp
import numpy as np
from flax import struct

from hintsjax import envs
from hintsjax.system import program_cache
from hintsjax.system.devices import SeedLayout
from hintsjax.settings.config import RunConfig
from hintsjax.algorithms.group import cell_state
from hintsjax.algorithms.ppo import Hyper, deploy_view, make_network, pick_hint
from hintsjax.algorithms.ppo_math import gaussian_sample
from hintsjax.algorithms.trainer import program_identity
from hintsjax.evaluation.outliers import far_below

EVAL_TAG = 0xE7A1  # folded into a seed's key so evaluation draws differ from training's


@struct.dataclass
class EvalResult:
    """Per-episode outcome, [E] for one seed or [S, E] once vmapped over seeds; `metrics` are
    the env's `metrics` of the state each episode ended in ({} for envs without any)."""

    episode_return: jax.Array
    episode_length: jax.Array
    metrics: dict[str, jax.Array] = struct.field(default_factory=dict)


def make_task_evaluator(
    cfg: RunConfig, num_episodes: int, hint: str | None = None
) -> Callable[..., EvalResult]:
    """`evaluate(params, key, task_params, stochastic[, pick]) -> EvalResult[E]` for one seed's
    params on any variant of the env, acting with the policy's mean or, where `stochastic` (a bool,
    or a traced one), sampling around it. Both are arguments, so one compiled program serves every
    variant, and a trained and a sampling agent alike.
    With `hint` (a group's env hint, hintsjax.algorithms.group) the agent sees the hint that `pick`
    (a member's Hyper) picks out of it: one program then evaluates every member of a group."""
    env = cfg.make_env(hint=hint, deploy=True)
    network = make_network(cfg, env)
    metrics_of = jax.vmap(env.metrics, in_axes=(0, None))

    def evaluate(
        params: Any,
        key: jax.Array,
        task_params: Any,
        stochastic: bool | jax.Array,
        pick: Hyper | None = None,
    ) -> EvalResult:
        k_reset, k_run = jax.random.split(key)
        ts = envs.fresh_episodes(k_reset, env, task_params, num_episodes)
        picked = (lambda obs: obs) if pick is None else (lambda obs: pick_hint(obs, pick))  # noqa: E731
        see = lambda obs: deploy_view(picked(obs), cfg.agent_spec)  # noqa: E731  (privileged inputs: zeros)

        def step(carry):
            t, state, obs, ret, length, metrics, alive = carry
            k_act, k_env = jax.random.split(jax.random.fold_in(k_run, t))
            mean, log_std, _ = network.apply(params, see(obs))
            action = jnp.where(stochastic, gaussian_sample(k_act, mean, log_std), mean)
            ts = jax.vmap(env.step, in_axes=(0, 0, 0, None))(
                jax.random.split(k_env, num_episodes), state, action, task_params
            )
            ret = ret + jnp.where(alive, ts.reward, 0.0)
            length = length + alive
            # kept while alive, so the step that ends an episode counts (its state is the one
            # the episode ended in) and later steps do not
            reached = metrics_of(ts.state, task_params)
            metrics = jax.tree.map(lambda new, old: jnp.where(alive, new, old), reached, metrics)
            alive = alive & ~(ts.terminated | ts.truncated)
            return t + 1, ts.state, ts.obs, ret, length, metrics, alive

        # Stop as soon as every episode has ended (early terminations make this much shorter
        # than max_steps); episodes never run past the time limit, which ends them all.
        zeros = jnp.zeros(num_episodes)
        init = (
            jnp.zeros((), jnp.int32),
            ts.state,
            ts.obs,
            zeros,
            zeros.astype(jnp.int32),
            metrics_of(ts.state, task_params),
            jnp.ones(num_episodes, bool),
        )
        _, _, _, ret, length, metrics, _ = jax.lax.while_loop(lambda c: c[-1].any(), step, init)
        return EvalResult(ret, length, metrics)

    return evaluate


def make_evaluator(
    cfg: RunConfig, variant: str | None, num_episodes: int, stochastic: bool = False
) -> Callable[[Any, jax.Array], EvalResult]:
    """`evaluate(params, key) -> EvalResult[E]` for one seed's params on `variant`; vmap it over
    seeds."""
    evaluate = make_task_evaluator(cfg, num_episodes)
    task_params = cfg.task_params(variant, deploy=True)
    return lambda params, key: evaluate(params, key, task_params, stochastic)


def eval_keys(cfg: RunConfig) -> jax.Array:
    """[S] evaluation keys, one per training seed."""
    return jax.vmap(jax.random.fold_in, in_axes=(0, None))(cfg.seed_keys(), EVAL_TAG)


def return_summary(returns: np.ndarray) -> dict[str, Any]:
    """[S, E] episode returns -> their mean and std over all seeds x episodes, per seed, and the
    seeds that ended far below the others (`summarize`'s keys of the returns; reproduce/pool.py
    pools with it)."""
    seed_means = returns.mean(axis=1)
    return {
        "mean": float(returns.mean()),
        "std": float(returns.std()),
        "seed_means": seed_means.tolist(),
        "seed_std": float(seed_means.std()),
        "outlier_seeds": far_below(seed_means),
        "seeds": int(returns.shape[0]),
        "episodes_per_seed": int(returns.shape[1]),
    }


def summarize(result: EvalResult) -> dict[str, Any]:
    """Mean and std over all seeds x episodes, and per seed, as plain JSON-able values, with the
    seeds that ended far below the others (`outlier_seeds`, hintsjax/evaluation/outliers.py); for
    each env metric (e.g. progress) `<name>_mean`, `<name>_std` and `<name>_seed_means`."""
    returns = np.asarray(result.episode_return, dtype=np.float64)
    summary = {
        **return_summary(returns),
        "mean_length": float(np.asarray(result.episode_length).mean()),
    }
    for name, value in sorted(result.metrics.items()):
        value = np.asarray(value, dtype=np.float64)
        summary.update(
            {
                f"{name}_mean": float(value.mean()),
                f"{name}_std": float(value.std()),
                f"{name}_seed_means": value.mean(axis=1).tolist(),
            }
        )
    return {**summary, "returns": returns.tolist()}


def metrics_text(summary: dict[str, Any]) -> str:
    """'  progress 0.78 +- 0.20' for each env metric of a summary ('' for envs without any)."""
    names = [k[: -len("_seed_means")] for k in summary if k.endswith("_seed_means")]
    return "".join(f"  {n} {summary[n + '_mean']:.2f} +- {summary[n + '_std']:.2f}" for n in names)


def one_device(cfg: RunConfig, layout: SeedLayout | None) -> SeedLayout:
    """`layout`, or cfg's seeds on this process's first device (params with exactly the run's
    seeds)."""
    return layout or SeedLayout.of(cfg.seeds, jax.local_devices()[:1])


def compile_evaluator(
    cfg: RunConfig,
    params: Any,
    variant: str | None,
    episodes: int,
    hint: str | None = None,
    pick: Hyper | None = None,
    layout: SeedLayout | None = None,
    compiler_options: dict[str, Any] | None = None,
) -> tuple[Any, float]:
    """The evaluation program for seed-batched params shaped like `params` (arrays, or
    jax.ShapeDtypeStructs with their shardings: it can compile before training has finished, e.g.
    in a thread while it runs), `evaluate(params, keys, task_params, stochastic)` for any variant
    of the env and either way of acting (`stochastic`: a bool array), or with a group's `hint` and
    a member's `pick` (`evaluate_group`) `evaluate(params, keys, task_params, stochastic, pick)`
    for any member; (that executable, seconds spent compiling). With a `layout` of several
    devices, params are its padded seeds, and each device evaluates its share. `compiler_options`
    go to XLA for this program alone."""
    t = time.perf_counter()
    layout = one_device(cfg, layout)
    picked = () if pick is None else (pick,)
    evaluate = jax.vmap(
        make_task_evaluator(cfg, episodes, hint), in_axes=(0, 0, None, None) + (None,) * len(picked)
    )
    evaluate = layout.spread(evaluate, batched=2, shared=2 + len(picked))
    identity = program_identity(cfg, episodes, hint) if layout.count == 1 else None
    compiled = program_cache.lower(
        evaluate,
        params,
        layout.pad(eval_keys(cfg)),
        cfg.task_params(variant, deploy=True),
        jnp.asarray(False),
        *picked,
        name="evaluate",
        context=identity,
    ).compile(compiler_options)
    return compiled, time.perf_counter() - t


def evaluate_variants(
    cfg: RunConfig,
    params: Any,
    variants: tuple[str | None, ...],
    episodes: int,
    stochastic: bool,
    compiled: tuple[Any, float] | None = None,
    layout: SeedLayout | None = None,
) -> tuple[list[dict], float]:
    """Evaluate seed-batched params on each variant, all seeds x episodes in one call per variant
    of one program compiled once (`compiled`, from `compile_evaluator` with the same `layout`, if
    given); (one summary per variant, seconds spent compiling)."""
    layout = one_device(cfg, layout)
    evaluate, compile_seconds = compiled or compile_evaluator(
        cfg, params, variants[0], episodes, layout=layout
    )
    keys, sample = layout.pad(eval_keys(cfg)), jnp.asarray(stochastic)
    summaries = [
        variant_summary(
            cfg,
            v,
            stochastic,
            layout.fetch(evaluate(params, keys, cfg.task_params(v, deploy=True), sample)),
        )
        for v in variants
    ]
    return summaries, compile_seconds


def variant_summary(
    cfg: RunConfig, variant: str | None, stochastic: bool, result: EvalResult
) -> dict[str, Any]:
    """An evaluation's summary (`summarize`) under the name of its variant (None: the env's
    default)."""
    return {
        "variant": variant or envs.variant_names(cfg.env)[0],
        "stochastic": stochastic,
        **summarize(result),
    }


def evaluate_group(
    group: Any, state: Any, layout: SeedLayout | None = None
) -> tuple[list[list[dict]], float]:
    """Evaluate every member of a group (hintsjax.algorithms.group) from the group's seed-batched
    state ([S, K, ...], hint axes padded) with one compiled program, each on its own variants,
    episodes and sampling as its own run would; (per member its summaries per variant, compile
    seconds). With a `layout` of several devices, `state` holds its padded seeds.
    The program is the group env's (every member's hint parts) with the member's hint picked
    and its padded weights (exact zeros) in place: what the member alone computes, its sums
    over the hint axis padded with zero terms."""
    cfg = group.cfgs[0]
    if len({c.eval_episodes for c in group.cfgs}) > 1:  # not one program: each alone
        results = [
            evaluate_variants(
                c,
                cell_state(group, state, k).params,
                (c.variant, *c.eval_variants),
                c.eval_episodes,
                c.stochastic_eval,
                layout=layout,
            )
            for k, c in enumerate(group.cfgs)
        ]
        return [r for r, _ in results], sum(t for _, t in results)
    layout = one_device(cfg, layout)
    keys, params = layout.pad(eval_keys(cfg)), state.params
    member = lambda k: jax.tree.map(lambda x: x[:, k], params)  # noqa: E731
    evaluate, compile_seconds = compile_evaluator(
        cfg, member(0), cfg.variant, cfg.eval_episodes, group.hint, group.hyper(0), layout
    )
    summaries = [
        [
            variant_summary(
                c,
                v,
                c.stochastic_eval,
                layout.fetch(
                    evaluate(
                        member(k),
                        keys,
                        c.task_params(v, deploy=True),
                        jnp.asarray(c.stochastic_eval),
                        group.hyper(k),
                    )
                ),
            )
            for v in (c.variant, *c.eval_variants)
        ]
        for k, c in enumerate(group.cfgs)
    ]
    return summaries, compile_seconds


def evaluate_params(
    cfg: RunConfig, params: Any, variant: str | None, episodes: int, stochastic: bool
) -> dict:
    """Evaluate seed-batched params on one variant: all seeds x episodes in one jitted call."""
    return evaluate_variants(cfg, params, (variant,), episodes, stochastic)[0][0]
