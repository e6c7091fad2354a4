"""The paper's Table 3, Car Racing rows (standard and hairpin), reproduced.

    python experiments/car_racing.py [--workers 2] [--launch-until 300]
    python experiments/car_racing.py --report     # experiments/results/car_table3.md + curves
    python experiments/car_racing.py --learners-report experiments/results/table3_seeds20.md
        --runs runs/table3_20

PPO-RGB and HINTS-MC with each of the paper's car hint columns (curvature, on_track and their
composite), trained on the standard tracks at the paper's budget (config.ENV_DEFAULTS: 1000
episodes of 1000 steps), 5 seeds vmapped in one call, 50 evaluation episodes per seed on the
standard tracks and on the hairpin deploy variant (ENV_DEFAULTS' eval_variants). Besides the
return the report gives the paper's progress P = visited tiles / all tiles, of the state each
evaluation episode ended in. The converged references (expert PPO on the state, DAgger and GAIL
learning from it) come first; the paper has no car numbers for them. Finished folders are
skipped, so an interrupted sweep resumes where it stopped (see hintsjax/reproduce/sweep.py).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from hintsjax.reproduce.archive import ARCHIVE, about_lines, read_about, sweep_seconds
from hintsjax.reproduce.markdown import (
    generated_marker,
    markdown_table,
    write_report,
    write_section,
)
from hintsjax.reproduce.report import (
    ORDERINGS_ABOUT,
    cell,
    curve_lines,
    footer,
    iqm_cell,
    load,
    metric_cell,
    ordering_line,
    poi_cell,
    ppo_text,
    references_note,
    seed_means,
    trained_ppo,
    training_cell,
    wall_clock,
)
from hintsjax.reproduce.sweep import hints_run
from hintsjax.reproduce.table_script import TableScript, table_main

RESULTS = Path(__file__).resolve().parent / "results"
ENVS = ("car_racing",)
BASELINES = ("ppo_rgb",)
# The converged references (issue 6): the expert's run exports its best seed, then dagger and
# gail learn from it (sweep.prerequisite). The paper has no car numbers for them.
REFERENCES = ("expert_ppo", "dagger", "gail")
# the paper's hint columns (Table 3; Table 6)
HINTS = {"car_racing": ("curvature", "on_track", "composite")}
VARIANTS = ("standard", "hairpin")  # evaluations[0] and [1]: the training task, then eval_variants
# The paper's Table 3 car rows (mean ± std over n=50; "CR Standard trn/evl MC", "CR Hairpin deploy
# MC"), keyed by our run labels, and the hairpin progress of section 5 (O3). "-": not given.
PAPER = {
    "ppo_rgb": {
        "standard": "461.17 ± 238.6",
        "hairpin": "419.95 ± 302.3",
        "P standard": "-",
        "P hairpin": "46%",
    },
    "hints-mc-curvature": {
        "standard": "539.27 ± 284.5",
        "hairpin": "479.76 ± 296.4",
        "P standard": "-",
        "P hairpin": "-",
    },
    "hints-mc-on_track": {
        "standard": "532.02 ± 269.0",
        "hairpin": "366.51 ± 281.2",
        "P standard": "-",
        "P hairpin": "-",
    },
    "hints-mc-composite": {
        "standard": "590.22 ± 261.9",
        "hairpin": "720.45 ± 272.1",
        "P standard": "-",
        "P hairpin": "78%",
    },
}
DEFAULT_RUNS = "runs/car_racing"
TABLE = "3-car"  # the sweep's name in runs/<...>/sweeps.jsonl


def run_ids(names) -> list[str]:
    return [f"{env}/{label}" for env in names for label in table_runs(env)]


def table_runs(env: str) -> list[str]:
    return [*REFERENCES, *BASELINES, *(hints_run("mc", h) for h in HINTS[env])]


def hairpin_progress(result: dict | None) -> list[float] | None:
    """The per-seed mean hairpin progress, or None when not recorded."""
    e = None if result is None else result["evaluations"][VARIANTS.index("hairpin")]
    return None if e is None or "progress_seed_means" not in e else e["progress_seed_means"]


def findings(runs: Path, env: str) -> str:
    """The paper's claim for these rows (O3), as numbers: composite hints lift the car's hairpin
    progress above vision only (46% -> 78% in the paper); decided when the 95% bootstrap interval
    of the difference in mean progress over seeds excludes 0."""
    from hintsjax.reproduce import stats

    rgb = hairpin_progress(load(runs, env, "ppo_rgb"))
    composite = hairpin_progress(load(runs, env, hints_run("mc", "composite")))
    if rgb is None or composite is None:
        return ""
    d = stats.difference_ci(composite, rgb)
    verdict = "decided" if stats.difference_decided(d) else "undecided"
    return (
        f"Hairpin progress (O3): HINTS-MC composite {100 * np.mean(composite):.0f}% "
        f"({len(composite)} seeds), PPO-RGB {100 * np.mean(rgb):.0f}% ({len(rgb)} seeds); paper "
        f"78% against 46%. Composite minus vision only: {100 * d.point:+.1f} points "
        f"[{100 * d.low:+.1f}, {100 * d.high:+.1f}] (95% bootstrap interval over seeds): {verdict}."
    )


def protocol(runs: Path, env: str) -> str:
    """How the table's rows were evaluated ('5 training seeds x 50 evaluation episodes (sampled
    actions)'), or each row's where they differ."""
    found: dict[str, list[str]] = {}  # the text of a protocol -> the rows evaluated so
    for label in table_runs(env):
        if (result := load(runs, env, label)) is not None:
            e = result["evaluations"][0]
            text = (
                f"{len(e['seed_means'])} training seeds x {e.get('episodes_per_seed', '?')} "
                "evaluation episodes "
                f"({'sampled actions' if e.get('stochastic') else 'the policy mean'})"
            )
            found.setdefault(text, []).append(label)
    if len(found) <= 1:
        return next(iter(found), "training seeds x evaluation episodes")
    return (
        "the row's training seeds x evaluation episodes ("
        + "; ".join(f"{', '.join(labels)}: {text}" for text, labels in found.items())
        + ")"
    )


def report(runs: Path, force: bool = False) -> None:
    from hintsjax.settings.layers import run_config

    lines = [
        "# Car Racing: the paper's Table 3 (CR Standard and CR Hairpin rows), reproduced",
        "",
        f"Each cell: mean ± std over {protocol(runs, ENVS[0])};",
        "in brackets the std of the per-seed means. "
        "Return: the episode return; P: progress, visited",
        "tiles / all tiles of the state an episode ended in. "
        "Agents train on standard tracks and are",
        "deployed on hairpin ones (first corner at most 45 degrees). "
        "The paper's cells are mean ± std",
        "over n=50; its P values are section 5's (O3); "
        "it gives no expert, DAgger, GAIL or PPO-x car numbers.",
        "Wall-clock per run (hardware at the end) includes compilation and both evaluations. '-': "
        "not run yet",
        "(or not given by the paper). Training return: "
        "the training episodes (sampled actions, standard",
        "tracks) that ended in the last 10% of updates, mean ± std over the seeds.",
        "",
    ]
    for env in ENVS:
        steps = run_config({"env": env}).ppo.total_env_steps
        rows = []
        for label in table_runs(env):
            result, paper = load(runs, env, label), PAPER.get(label, {})
            row = [label]
            for i, variant in enumerate(VARIANTS):
                row += [cell(result, i), paper.get(variant, "-")]
            for i, variant in enumerate(VARIANTS):
                row += [
                    metric_cell(result, "progress", i, percent=True),
                    paper.get(f"P {variant}", "-"),
                ]
            rows.append([*row, training_cell(runs, env, label), wall_clock(result)])
        lines += [f"## {env} ({steps / 1e6:g} M env steps per seed)", ""]
        lines += markdown_table(
            [
                "agent",
                "return standard",
                "paper",
                "return hairpin",
                "paper",
                "P standard",
                "paper",
                "P hairpin",
                "paper",
                "training return, last 10%",
                "wall-clock (s)",
            ],
            rows,
        )
        lines += ["", findings(runs, env), "", references_note(runs, env, REFERENCES), ""]
        # at the table's budget
        learners = [label for label in table_runs(env) if label not in REFERENCES]
        lines += curve_lines(
            runs,
            env,
            learners,
            RESULTS / f"car_curves_{env}.png",
            f"{env} (standard tracks): Table 3 agents",
        )
    lines += about_lines(read_about(ARCHIVE / runs.name))
    lines.append(footer(runs, TABLE, run_ids(ENVS)))
    write_report(RESULTS / "car_table3.md", lines, force)


def ordering_lines(runs: Path, env: str) -> list[str]:
    """O1 on the standard tracks (the best hint by IQM over PPO-RGB) and O3 on the hairpin ones
    (the composite over PPO-RGB), as probabilities of improvement of the per-seed mean returns."""
    from hintsjax.reproduce import stats

    rgb = load(runs, env, "ppo_rgb")
    hints = {hints_run("mc", h): load(runs, env, hints_run("mc", h)) for h in HINTS[env]}
    hints = {label: r for label, r in hints.items() if r is not None}
    if rgb is None or not hints:
        return []
    best = max(hints, key=lambda label: stats.iqm(seed_means(hints[label])))
    lines = [
        ordering_line(
            "O1 (hints beat vision only; standard tracks)", best, hints[best], "ppo_rgb", rgb
        )
    ]
    composite = hints_run("mc", "composite")
    if composite in hints:
        lines.append(
            ordering_line(
                "O3 (composite hints carry the car round hairpins; hairpin tracks)",
                composite,
                hints[composite],
                "ppo_rgb",
                rgb,
                VARIANTS.index("hairpin"),
            )
        )
    return lines


def learners_report(runs: Path, names: list[str], path: Path, force: bool = False) -> None:
    """The car's learner rows of Table 3 (PPO-RGB and HINTS-MC with each hint column) from a runs
    folder at any seed count (the 20-seed table, issue 46): per row and track variant the IQM
    [95 % CI] of the per-seed mean returns, P(row > PPO-RGB) and the progress; O1 and O3; learning
    curves with bootstrap bands. Written as the section of `path` that GENERATED opens
    (markdown.write_section): the plan and the locomotion section stay. `names` is the car alone."""
    from hintsjax.settings.layers import run_config

    env = ENVS[0]
    labels = [*BASELINES, *(hints_run("mc", h) for h in HINTS[env])]
    results = {label: load(runs, env, label) for label in labels}
    trained = {label: r for label, r in results.items() if r is not None}
    ppo = run_config({"env": env}).ppo
    heading = f"## {env} ({ppo.total_env_steps / 1e6:g} M env steps per seed"
    lines = [
        "Made by `python experiments/car_racing.py --learners-report "
        f"experiments/results/{path.name} --runs runs/{runs.name}` from the archived runs "
        f"(experiments/results/runs/{runs.name}).",
        "Agents train on standard tracks and are deployed on standard and hairpin ones. "
        "Cells per track variant:",
        "the IQM of the per-seed mean returns with a 95 % stratified bootstrap interval, "
        "P(row > PPO-RGB) over the",
        "seeds, and the progress P (visited tiles / all tiles at an episode's end), "
        "mean ± std over all seeds x",
        "50 evaluation episodes (in brackets the std of the per-seed means).",
        f"GPU wall-clock of the sweeps (runs/{runs.name}/sweeps.jsonl): "
        f"{sweep_seconds(runs, TABLE):.0f} s.",
        "",
    ]
    if not trained:
        lines += [heading + ")", "", "Not trained yet.", ""]
    else:
        seeds = ", ".join(map(str, sorted({len(seed_means(r)) for r in trained.values()})))
        rgb = results["ppo_rgb"]
        rows = [
            [
                label,
                *(
                    c
                    for i in range(len(VARIANTS))
                    for c in (
                        iqm_cell(r, i),
                        "-" if label == "ppo_rgb" else poi_cell(r, rgb, i),
                        metric_cell(r, "progress", i, percent=True),
                    )
                ),
                " / ".join(PAPER[label][v] for v in VARIANTS),
                wall_clock(r),
            ]
            for label, r in results.items()
        ]
        header = [
            "agent",
            *(
                f"{v} {what}"
                for v in VARIANTS
                for what in ("IQM [95% CI]", "P(row > PPO-RGB)", "P")
            ),
            "paper standard / hairpin",
            "wall-clock (s)",
        ]
        lines += [
            f"{heading}, {seeds} seeds per row)",
            "",
            f"PPO: {ppo_text(trained_ppo(runs, env, next(iter(trained))) or ppo)}.",
            "",
            *markdown_table(header, rows),
            "",
            ORDERINGS_ABOUT,
            "",
            *ordering_lines(runs, env),
            "",
            findings(runs, env),
            "",
        ]
        lines += curve_lines(
            runs,
            env,
            list(trained),
            RESULTS / f"table3_seeds20_curves_{env}.png",
            f"{env} (standard tracks): Table 3 learners, {seeds} seeds",
        )
    lines += references_lines(runs, env)
    # and "<env> references"
    about = {k: v for k, v in read_about(ARCHIVE / runs.name).items() if k.split()[0] in ENVS}
    write_section(path, GENERATED, [*lines, *about_lines(about)], force)


def references_lines(runs: Path, env: str) -> list[str]:
    """The references of a learners report (expert_ppo, dagger, gail; upper bounds, in no
    ordering): per track variant the IQM [95 % CI] and the progress; [] when none trained."""
    refs = {label: load(runs, env, label) for label in REFERENCES}
    trained = [r for r in refs.values() if r is not None]
    if not trained:
        return []
    seeds = ", ".join(map(str, sorted({len(seed_means(r)) for r in trained})))
    rows = [
        [
            label,
            *(
                c
                for i in range(len(VARIANTS))
                for c in (iqm_cell(r, i), metric_cell(r, "progress", i, percent=True))
            ),
            wall_clock(r),
        ]
        for label, r in refs.items()
    ]
    header = [
        "reference",
        *(f"{v} {what}" for v in VARIANTS for what in ("IQM [95% CI]", "P")),
        "wall-clock (s)",
    ]
    return [
        f"References ({seeds} seeds; upper bounds, not in any ordering):",
        "",
        *markdown_table(header, rows),
        "",
        references_note(runs, env, REFERENCES),
        "",
    ]


GENERATED = generated_marker("car_racing.py")


SCRIPT = TableScript(
    __doc__.splitlines()[0], DEFAULT_RUNS, ENVS, {TABLE: run_ids}, report, learners_report
)


def main() -> None:
    table_main(SCRIPT)


if __name__ == "__main__":
    main()
