"""Reading finished runs into the cells of the result tables.

The readers (`load`, `cell`, `iqm_cell`, `metric_cell`, `training_cell`, `kl_cell`, `wall_clock`,
`references_note`, `footer`) give the cells and notes of the tables of classic_control.py,
locomotion.py, car_racing.py and playground.py. Each reads a run from runs/ when it finished
there, else from the committed archive (archive.py), so a report on a fresh checkout rebuilds the
committed tables; markdown.py renders the tables and writes the reports.
"""

from __future__ import annotations

import json
from pathlib import Path

from hintsjax.reproduce.archive import (
    KL_ABOVE,
    kl_share,
    run_folder,
    sweep_records,
    sweep_seconds,
    training_seed_means,
)


def load(runs: Path, env: str, label: str) -> dict | None:
    path = run_folder(runs, env, label) / "eval.json"
    return json.loads(path.read_text()) if path.exists() else None


def cell(result: dict | None, variant: int = 0) -> str:
    """'mean ± std (seed std)' of one evaluation, or '-' when not run."""
    if result is None:
        return "-"
    e = result["evaluations"][variant]
    return f"{e['mean']:.1f} ± {e['std']:.1f} ({e['seed_std']:.1f})"


def iqm_cell(result: dict | None, variant: int = 0) -> str:
    """'IQM [low, high]' of one evaluation's per-seed mean returns with a 95% bootstrap CI over
    seeds (hintsjax.reproduce.stats), or '-' when not run."""
    from hintsjax.reproduce import stats

    return "-" if result is None else stats.iqm_cell(seed_means(result, variant))


def ordering(
    name_x: str, x: dict | None, name_y: str, y: dict | None, variant: int = 0
) -> str | None:
    """'P(x > y) = p [low, high]: decided|undecided' over the two runs' per-seed mean returns (95%
    bootstrap CI; decided when it excludes 0.5), or None when either was not run."""
    from hintsjax.reproduce import stats

    if x is None or y is None:
        return None
    return stats.ordering_text(
        name_x, name_y, stats.poi_ci(seed_means(x, variant), seed_means(y, variant))
    )


def seed_means(result: dict, variant: int = 0) -> list[float]:
    """One evaluation's per-seed mean returns."""
    return result["evaluations"][variant]["seed_means"]


def interval_text(ci) -> str:
    return f"{ci.point:.2f} [{ci.low:.2f}, {ci.high:.2f}]"


def verdict(interval) -> str:
    """An interval of P(X > Y) -> 'decided for' (above 0.5), 'decided against' (below) or
    'undecided'."""
    from hintsjax.reproduce import stats

    return {1: "decided for", -1: "decided against", 0: "undecided"}[stats.direction(interval)]


def poi_cell(x: dict | None, y: dict | None, variant: int = 0) -> str:
    """'P [low, high]' of P(x > y) over seeds, or '-'."""
    from hintsjax.reproduce import stats

    return (
        "-"
        if x is None or y is None
        else interval_text(stats.poi_ci(seed_means(x, variant), seed_means(y, variant)))
    )


def ordering_line(tag: str, name_x: str, x: dict, name_y: str, y: dict, variant: int = 0) -> str:
    """'- O1 (...): P(x > y) = p [low, high]: decided for' over the two runs' per-seed mean
    returns."""
    from hintsjax.reproduce import stats

    ci = stats.poi_ci(seed_means(x, variant), seed_means(y, variant))
    return f"- {tag}: P({name_x} > {name_y}) = {interval_text(ci)}: {verdict(ci)}"


ORDERINGS_ABOUT = (
    "Orderings: probabilities of improvement P(X > Y) over the per-seed mean returns with 95 % "
    "bootstrap intervals (hintsjax/reproduce/stats.py). Decided for: the interval lies above 0.5; "
    "decided against: below 0.5; undecided: it contains 0.5. The best hint is the hint row with "
    "the highest IQM, chosen on the same seeds, which favours it a little."
)


def ppo_text(ppo) -> str:
    """A line of the PPO settings (config.PPOConfig) that a report states beside its rows."""
    return (
        f"{ppo.num_envs} envs per seed, batches of {ppo.batch_size}, {ppo.epochs} epochs of "
        f"minibatches of {ppo.minibatch_size}, learning rates encoder {ppo.encoder_lr:g}, actor "
        f"{ppo.actor_lr:g}, critic {ppo.critic_lr:g}"
        + (f", KL early stop at {ppo.target_kl:g}" if ppo.target_kl else "")
        + (" with the learning rates adapted to the KL" if ppo.kl_adaptive_lr else "")
        + (", the encoder trained by the actor alone" if not ppo.critic_trains_encoder else "")
        + (", the critic's own encoder" if ppo.critic_encoder == "own" else "")
        + (
            f", pictures in [-{ppo.pixel_scale:g}, {ppo.pixel_scale:g}]"
            if ppo.pixel_scale != 1.0
            else ""
        )
        + (f", {ppo.activation} MLPs" if ppo.activation != "relu" else "")
        + (f", a {ppo.std_head} std head" if ppo.std_head != "param" else "")
        + (", no bootstrap at the time limit" if not ppo.bootstrap_truncated else "")
        + (f", rewards x {ppo.reward_scale:g}" if ppo.reward_scale != 1.0 else "")
        + (", the state agents' state normalised" if ppo.normalize_state else "")
    )


def metric_of(
    result: dict | None, name: str, variant: int = 0
) -> tuple[float, float, float] | None:
    """(mean, std, std of the per-seed means) of an env metric (e.g. progress) of one
    evaluation; None when not run or not recorded."""
    e = None if result is None else result["evaluations"][variant]
    if e is None or f"{name}_mean" not in e:
        return None
    seed_means = e[f"{name}_seed_means"]
    centre = sum(seed_means) / len(seed_means)
    seed_std = (sum((m - centre) ** 2 for m in seed_means) / len(seed_means)) ** 0.5
    return e[f"{name}_mean"], e[f"{name}_std"], seed_std


def metric_cell(result: dict | None, name: str, variant: int = 0, percent: bool = False) -> str:
    """'mean ± std (seed std)' of an env metric of one evaluation, as `cell`; '-' when not run
    or not recorded."""
    stats = metric_of(result, name, variant)
    if stats is None:
        return "-"
    mean, std, seed_std = stats
    if percent:
        return f"{100 * mean:.0f}% ± {100 * std:.0f} ({100 * seed_std:.0f})"
    return f"{mean:.2f} ± {std:.2f} ({seed_std:.2f})"


def metrics_path(runs: Path, env: str, label: str) -> Path | None:
    """A run's metrics.csv (archived ones hold runlog.CURVE_POINTS bins of updates), or None when
    not run."""
    path = run_folder(runs, env, label) / "metrics.csv"
    return path if path.exists() else None


def training_cell(runs: Path, env: str, label: str) -> str:
    """Mean ± std over seeds of `training_seed_means` (the last 10% of updates): beside
    `cell`'s deterministic evaluation; '-' when not run."""
    import numpy as np

    per_seed = training_seed_means(run_folder(runs, env, label))
    if per_seed is None:
        return "-"
    return f"{np.nanmean(per_seed):.1f} ± {np.nanstd(per_seed):.1f}"


def kl_cell(runs: Path, env: str, label: str, above: float = KL_ABOVE) -> str:
    """`kl_share` as a percentage: a PPO that drifts or blows up shows here (healthy runs stay
    near 0%; inf, an overflowed ratio, counts). '-' when not run or not trained by PPO."""
    share = kl_share(run_folder(runs, env, label), above)
    return "-" if share is None else f"{100 * share:.1f}%"


def trained_config(runs: Path, env: str, label: str):
    """The RunConfig a finished run was trained with (its config.yaml), or None when not run:
    a report states the settings its rows were trained with, not today's defaults."""
    from hintsjax.settings.layers import CONFIG_YAML, load_run_config

    folder = run_folder(runs, env, label)
    return (
        load_run_config(folder)
        if (folder / "eval.json").exists() and (folder / CONFIG_YAML).exists()
        else None
    )


def trained_ppo(runs: Path, env: str, label: str):
    """The PPOConfig a finished run was trained with, or None when not run."""
    cfg = trained_config(runs, env, label)
    return None if cfg is None else cfg.ppo


def references_note(runs: Path, env: str, references: tuple[str, ...]) -> str:
    """The references' budgets (as trained, else today's defaults) and the expert that dagger
    and gail learnt from: the best seed of the runs' own expert_ppo, which their sweep exported
    before they began (so an archived report does not change when the packaged expert is
    replaced), else the packaged expert."""
    from hintsjax.settings.layers import run_config
    from hintsjax.algorithms.experts import EXPERT_JSON, EXPERTS_DIR, best_seed

    cfg = {
        a: trained_config(runs, env, a) or run_config({"env": env, "agent": a}) for a in references
    }
    expert = cfg["expert_ppo"].ppo
    source = "its best seed"
    if (result := load(runs, env, "expert_ppo")) is not None:  # the one its sweep exported
        evaluation = result["evaluations"][0]
        best = best_seed(evaluation)
        source += (
            f" (seed {best}, {evaluation['seed_means'][best]:.0f} over "
            f"{evaluation['episodes_per_seed']} episodes)"
        )
    # not trained here: the packaged expert
    elif (meta := EXPERTS_DIR / env / EXPERT_JSON).exists():
        m = json.loads(meta.read_text())
        source += (
            f" (seed {m['seed_index']}, {m['seed_eval_mean']:.0f} over {m['episodes_per_seed']} "
            f"episodes; hintsjax/experts/{env})"
        )
    text = (
        "References (no budget limit): expert_ppo is PPO on the state for "
        f"{expert.total_env_steps / 1e6:g} M steps ({expert.num_envs} envs per seed, batches of "
        f"{expert.batch_size}, {expert.epochs} epochs of minibatches of {expert.minibatch_size}); "
        f"dagger learns from {source} over {cfg['dagger'].ppo.total_env_steps / 1e3:g} K "
        "expert-labelled steps"
    )
    if "gail" in cfg:
        gail = cfg["gail"]
        reward = (
            "-log(1 - D)" if gail.gail.reward == "original" else "the log odds log D - log(1 - D)"
        )
        text += (
            f"; gail learns from {gail.gail.demonstrations} of that expert's episodes, by PPO for "
            f"{gail.ppo.total_env_steps / 1e6:g} M steps on the discriminator's reward {reward}"
            + (
                ", the discriminator reading the state standardised by the demonstrations' "
                "statistics"
                if gail.gail.normalize_state
                else ""
            )
            + (
                f" and held smooth by an R1 penalty of {gail.gail.grad_penalty:g} on the expert's "
                "pairs"
                if gail.gail.grad_penalty
                else ""
            )
        )
    return text + "."


def mean_of(result: dict | None) -> float | None:
    return None if result is None else result["evaluations"][0]["mean"]


def wall_clock(result: dict | None) -> str:
    """A run's wall-clock in seconds, marked when it ran on a CPU rather than the GPU. A run
    trained outside a sweep (python -m hintsjax.run) recorded only its training seconds."""
    if result is None:
        return "-"
    if "wall_seconds" not in result:
        return f"{result['train_seconds']:.0f} (training only)"
    on_cpu = result.get("device", "").lower() == "cpu"
    return f"{result['wall_seconds']:.0f}" + (" (CPU)" if on_cpu else "")


ARCHIVED_SUFFIX = "_archived"  # curve_lines' figure of the runs beside kept ones


def curve_lines(
    runs: Path, env: str, labels: list[str], out: Path, title: str, kept: tuple[str, ...] = ()
) -> list[str]:
    """Plot the learning curves of `labels`' runs (those with a metrics.csv) into `out`; the
    report's markdown lines for it ([] when none has started). While some rows are `kept` (runs
    that predate the archive, with no curve to draw), `out` is their figure and stays; the other
    runs' curves go to a sibling figure, `out`'s name + ARCHIVED_SUFFIX."""
    from hintsjax.training.runlog import plot_curves, read_curves

    paths = {label: metrics_path(runs, env, label) for label in labels}
    curves = {label: read_curves(path) for label, path in paths.items() if path is not None}
    old = [
        f"![{env} learning curves]({out.name})",
        "",
        "(The curves of the runs kept from the previous report.)",
        "",
    ]
    if not curves:  # a figure of runs that predate the archive stays, said to be theirs
        return old if out.exists() else []
    if kept and out.exists():
        out = out.with_name(out.stem + ARCHIVED_SUFFIX + out.suffix)
        plot_curves(curves, out, f"{title}: runs since the archive")
        return [*old, f"![{env} learning curves of the runs since the archive]({out.name})", ""]
    plot_curves(curves, out, title)
    return [f"![{env} learning curves]({out.name})", ""]


def sweep_hardware(runs: Path, table: str, run_ids: list[str]) -> str:
    """'<device>; 6 runs at once over 2 GPUs' for the GPU sweeps of `table` (from sweeps.jsonl
    and the runs' eval.json), or '' when none ran on a GPU."""
    records = sweep_records(runs, table)
    results = [result for r in run_ids if (result := load(runs, *r.split("/")))]
    devices = sorted({result.get("device", "") for result in results} - {"", "cpu", "Cpu"})
    if not records or not devices:
        return ""
    setups = sorted(
        {
            ("1 run at a time" if r["workers"] == 1 else f"{r['workers']} runs at once")
            + (f" over {len(r['gpus'])} GPUs" if len(r.get("gpus", ())) > 1 else " on one GPU")
            for r in records
        }
    )
    # Runs recorded before this key existed ran with deterministic GPU ops (hintsjax's default).
    fast = [result for result in results if result.get("deterministic", True) is False]
    return f"{', '.join(devices)}; {'; '.join(setups)}" + (
        f"; deterministic GPU ops off ({len(fast)} runs)" if fast else ""
    )


def footer(runs: Path, table: str, run_ids: list[str]) -> str:
    """The report's last line: the sweeps' GPU wall-clock and hardware."""
    return (
        f"Sweep wall-clock recorded in {runs}/sweeps.jsonl on the GPU: "
        f"{sweep_seconds(runs, table):.0f} s "
        f"({sweep_hardware(runs, table, run_ids) or 'none yet'})."
    )
