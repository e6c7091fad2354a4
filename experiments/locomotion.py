"""The paper's Table 3, locomotion rows (halfcheetah, ant, humanoid), reproduced.

    python experiments/locomotion.py [--envs halfcheetah,ant] [--workers 2] [--launch-until 300]
    python experiments/locomotion.py --report    # experiments/results/locomotion_table3.md + curves
    python experiments/locomotion.py --learners-report experiments/results/table3_seeds20.md
                                     --runs runs/table3_20

Per env: PPO-RGB, PPO-x (the state) and HINTS-FC with each of the paper's hint columns, at the
paper's budgets (config.ENV_DEFAULTS: 1k, 5k and 10k episodes counted at 1000 steps), 5 seeds
vmapped in one call, 50 evaluation episodes per seed. Finished folders are skipped, so an
interrupted sweep resumes where it stopped (see hintsjax/reproduce/sweep.py). The DAgger column's
expert is PPO on the state at the env's expert budget (config.ENV_DEFAULTS), exported to
hintsjax/experts/<env> when it finishes; dagger and gail start only then.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from hintsjax.reproduce.archive import ARCHIVE, about_lines, read_about, sweep_seconds
from hintsjax.reproduce.markdown import (
    KEPT,
    apart_text,
    cell_stats,
    generated_marker,
    kept_rows,
    markdown_table,
    section_name,
    write_report,
    write_section,
)
from hintsjax.reproduce.report import (
    ORDERINGS_ABOUT,
    cell,
    curve_lines,
    footer,
    iqm_cell,
    kl_cell,
    load,
    metrics_path,
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
ENVS = ("halfcheetah", "ant", "humanoid")
BASELINES = ("ppo_rgb", "ppo_state")
# The converged references (issue 6): the expert's run is exported (its best seed) to the
# package's hintsjax/experts/<env> when it finishes; the env's dagger and gail runs start only then.
# The paper has no GAIL numbers for the locomotion envs.
REFERENCES = ("expert_ppo", "dagger", "gail")
HINTS = {  # the paper's hint columns (Table 3; Table 6 names them)
    "halfcheetah": ("reward", "velocity", "max_velocity", "state"),
    "ant": ("speed", "goal_height", "state"),
    "humanoid": ("velocity", "goal_height"),
}
# The paper's Table 3 (mean ± std over n=50), keyed by our run labels.
PAPER = {
    "halfcheetah": {
        "dagger": "2351.16 ± 109.6",
        "ppo_state": "2327.99 ± 535.8",
        "ppo_rgb": "1.82 ± 18.6",
        "hints-fc-reward": "55.41 ± 24.5",
        "hints-fc-velocity": "138.45 ± 19.3",
        "hints-fc-max_velocity": "21.91 ± 66.5",
        "hints-fc-state": "30.42 ± 13.2",
    },
    "ant": {
        "dagger": "4000.42 ± 152.8",
        "ppo_state": "533.77 ± 254.7",
        "ppo_rgb": "1015.49 ± 3.3",
        "hints-fc-speed": "1313.57 ± 57.6",
        "hints-fc-goal_height": "1442.82 ± 162.6",
        "hints-fc-state": "1007.52 ± 5.1",
    },
    "humanoid": {
        "dagger": "588.00 ± 152.4",
        "ppo_state": "228.30 ± 17.6",
        "ppo_rgb": "310.86 ± 41.7",
        "hints-fc-velocity": "455.95 ± 94.5",
        "hints-fc-goal_height": "306.14 ± 52.5",
    },
}
# What a row's figures alone do not say (measured; the report prints it under the env's references).
NOTES = {
    "ant": (
        "The ant's curves show ppo_rgb's earlier run at Table 5's rates (994); its row is the "
        "retraining at today's settings (2026-11-23, `--only ppo_rgb` alone on an H200)."
    ),
    "humanoid": (
        "expert_ppo and dagger trained beside two other runs on one H200 (2026-11-23; that "
        "sweep's record was lost with the machine). gail trained alone on an H200 by `python "
        "-m hintsjax.run env=humanoid agent=gail` (2026-11-23; its wall-clock is the training "
        "alone); the footer counts the sweep of its first run (900 s), which had no R1 penalty "
        "(gail.grad_penalty 0): there the discriminator told the expert's pairs from the policy's "
        "perfectly from update 200 on (accuracy 1.0, reward -log(1 - D) near 0), the entropy "
        "bonus drove the policy's entropy from 24 to 159, the robot fell after about 78 steps and "
        "gail scored 446.7 ± 125.1. With the penalty of 10 the accuracy is also 1.0 until about "
        "update 600, the reward as small (0.002 to 0.017 a step), yet the training return climbs "
        "(3397 to 6480 at update 600), and by the end the accuracy is 0.44 to 0.74. The learners' "
        "wall-clock is their training time summed over calls, while sharing the GPU (2026-11-23, "
        "H200s): one sweep started all four learners, stopped the two hint runs after 8 minutes "
        "and ppo_rgb after 16 (at update 3450, its checkpoint carried to the next machine), and "
        "let ppo_state finish alone; a second sweep resumed ppo_rgb beside hints-fc-velocity (its "
        "record was lost with the machine: about 1800 s by its log); hints-fc-goal_height trained "
        "alone on an H200 (1108 s). ppo_rgb's log lacks updates 3451 to 8600: each later call "
        "to the machine copied the carried folder over the running one's, and the run, going on "
        "in memory, wrote on into the copy; its parameters and evaluation are whole, its curve "
        "joins update 3450 to 8601 with a straight line, and its training-return and KL cells "
        "cover the 4615 updates logged."
    ),
}
DEFAULT_RUNS = "runs/locomotion"
REPORT = "locomotion_table3.md"  # under RESULTS
# GPU wall-clock of the sweeps before the archive existed (their runs/sweeps.jsonl was lost with
# a fresh checkout on 2026-11-23; the figure is the one the report stated then).
UNARCHIVED_SWEEP_SECONDS = 9745
TABLE = "3-locomotion"  # the sweep's name in runs/<...>/sweeps.jsonl


def run_ids(names) -> list[str]:
    return [f"{env}/{label}" for env in names for label in table_runs(env)]


def table_runs(env: str) -> list[str]:
    return [*REFERENCES, *BASELINES, *(hints_run("fc", h) for h in HINTS[env])]


def kept_row(
    runs: Path, env: str, label: str, kept: dict[tuple[str, str], list[str]]
) -> list[str] | None:
    """The previous report's row of a run that neither runs/ nor the archive holds (not even
    begun)."""
    if load(runs, env, label) is None and metrics_path(runs, env, label) is None:
        return kept.get((env, label))
    return None


def findings(runs: Path, env: str, kept: dict[tuple[str, str], list[str]]) -> str:
    """The paper's claims for these rows, as numbers: hints beat vision only, and (but for the
    cheetah) beat PPO on the state. A row kept from the previous report counts with its mean."""

    def stats(label: str) -> tuple[float, float] | None:
        row = kept_row(runs, env, label, kept)
        return cell_stats(cell(load(runs, env, label)) if row is None else row[1])

    rgb, state = stats("ppo_rgb"), stats("ppo_state")
    hints = {h: stats(hints_run("fc", h)) for h in HINTS[env]}
    hints = {h: v for h, v in hints.items() if v is not None}
    if rgb is None or state is None or not hints:
        return ""
    best = max(hints, key=lambda h: hints[h][0])
    top = hints[best]

    def verdict(other: tuple[float, float]) -> str:
        return (
            f"{'yes' if top[0] > other[0] else 'no'} ({apart_text(top, other)} the seeds' spread)"
        )

    return (
        f"Best HINTS-FC hint `{best}` {top[0]:.1f}; PPO-RGB {rgb[0]:.1f}; PPO-x {state[0]:.1f}. "
        f"Hints beat vision only: {verdict(rgb)}; beat the state: {verdict(state)}. "
        "(Beyond: the means differ by more than the two stds of the per-seed means together.)"
    )


def settings_lines(
    runs: Path,
    env: str,
    labels: list[str],
    kept: dict[tuple[str, str], list[str]] | None = None,
    reported: dict[tuple[str, str], str] | None = None,
) -> list[str]:
    """The PPO settings the rows were trained with (each run's config.yaml), grouped when they
    differ, naming the fields where a row's are not today's defaults; rows not yet run are listed
    at today's defaults (config.ENV_DEFAULTS); kept rows as the previous report listed them
    (`reported`, else today's defaults)."""
    from hintsjax.settings.layers import run_config

    default, kept, reported = run_config({"env": env}).ppo, kept or {}, reported or {}
    groups: dict[str, list[str]] = {}
    for label in labels:
        ppo = trained_ppo(runs, env, label)
        if kept_row(runs, env, label, kept):
            text = reported.get((env, label), reported.get((env, ""), ppo_text(default)))
            groups.setdefault(f"{text} (kept rows {KEPT}; as last reported)", []).append(label)
            continue
        note = (
            "not run yet; config.ENV_DEFAULTS"
            if ppo is None
            else "config.ENV_DEFAULTS"
            if ppo == default
            else f"not today's config.ENV_DEFAULTS: {differ(changed_fields(ppo, default))}"
        )
        groups.setdefault(f"{ppo_text(ppo or default)} ({note})", []).append(label)
    if len(groups) == 1:
        return [f"PPO: {next(iter(groups))}."]
    return [
        "PPO, as each row was trained:",
        "",
        *(f"- {', '.join(rows)}: {text}." for text, rows in groups.items()),
    ]


def reported_settings(path: Path) -> dict[tuple[str, str], str]:
    """The PPO settings the report at `path` gave each row (settings_lines' lines, their notes
    dropped), by (section, label); (section, "") for a section's one 'PPO: ...' line. A kept row
    keeps them: today's defaults may have changed since it trained."""
    found: dict[tuple[str, str], str] = {}
    section, listing = "", False
    for line in (path.read_text() if path.exists() else "").splitlines():
        if line.startswith("## "):
            section, listing = section_name(line), False
        elif line.startswith("PPO: "):
            found[(section, "")] = line[len("PPO: ") :].removesuffix(".").rsplit(" (", 1)[0]
        elif line == "PPO, as each row was trained:":
            listing = True
        elif listing and line.startswith("- "):
            rows, text = line[2:].split(": ", 1)
            found.update(
                {
                    (section, label): text.removesuffix(".").rsplit(" (", 1)[0]
                    for label in rows.split(", ")
                }
            )
        elif line:
            listing = False
    return found


def changed_fields(ppo, default) -> list[str]:
    """The PPOConfig fields in which `ppo` (a row's, as trained) differs from today's `default`."""
    return [
        f.name for f in dataclasses.fields(ppo) if getattr(ppo, f.name) != getattr(default, f.name)
    ]


def differ(names: list[str]) -> str:
    """'epochs, encoder_lr differ' / 'kl_adaptive_lr differs'."""
    return f"{', '.join(names)} {'differs' if len(names) == 1 else 'differ'}"


def report(runs: Path, force: bool = False) -> None:
    from hintsjax.settings.layers import run_config

    kept, reported = kept_rows(RESULTS / REPORT), reported_settings(RESULTS / REPORT)
    lines = [
        "# Locomotion: the paper's Table 3 (Ant, Cheetah, Humanoid rows), reproduced",
        "",
        "Each cell: mean ± std of the episode return over 5 training seeds x 50 "
        "evaluation episodes",
        "(deterministic policy); in brackets the std of the 5 per-seed means. The "
        "paper's cells are",
        "mean ± std over n=50. Wall-clock per run (hardware at the end) includes "
        "compilation and evaluation.",
        "The envs are Gymnasium v5's tasks on MJX (envs/ant.py, halfcheetah.py, humanoid.py), seen",
        "as 64x64 renders from a camera that follows the robot (envs/render3d.py). "
        "'-': not run yet.",
        "Training return: the training episodes (sampled actions) that ended in the last 10% of",
        "updates, mean ± std over the seeds. Updates with KL > 0.5: the share of PPO updates (all",
        "seeds) whose approx. KL from the rollout policy exceeded 0.5, a blown-up "
        "update; healthy runs",
        "stay near 0% (experiments/results/locomotion_ppo_stability.md).",
        "",
    ]
    for env in ENVS:
        # at the table's budget
        learners = [label for label in table_runs(env) if label not in REFERENCES]
        lines += [
            f"## {env} ({run_config({'env': env}).ppo.total_env_steps / 1e6:g} M "
            "env steps per seed)",
            "",
            *settings_lines(runs, env, learners, kept, reported),
            "",
        ]
        rows = []
        for label in table_runs(env):
            if (row := kept_row(runs, env, label, kept)) is not None:
                rows.append(row)
                continue
            result = load(runs, env, label)
            rows.append(
                [
                    label,
                    cell(result),
                    PAPER[env].get(label, "-"),
                    training_cell(runs, env, label),
                    kl_cell(runs, env, label),
                    wall_clock(result),
                ]
            )
        lines += markdown_table(
            [
                "agent",
                "ours",
                "paper",
                "training return, last 10%",
                "updates with KL > 0.5",
                "wall-clock (s)",
            ],
            rows,
        )
        lines += ["", findings(runs, env, kept), "", references_note(runs, env, REFERENCES), ""]
        lines += [NOTES[env], ""] if env in NOTES else []
        lines += curve_lines(
            runs,
            env,
            learners,
            RESULTS / f"locomotion_curves_{env}.png",
            f"{env}: Table 3 agents, 5 seeds",
            kept=tuple(label for label in learners if kept_row(runs, env, label, kept)),
        )
    if any(KEPT in line for line in lines):
        lines.append(
            f"Rows marked {KEPT} are kept from the previous report: their runs predate the results "
            "archive (experiments/results/runs) and their run folders were lost. The sweeps before "
            f"the archive took {UNARCHIVED_SWEEP_SECONDS} s of GPU wall-clock, beside the footer's."
        )
        lines.append("")
    lines.append(footer(runs, TABLE, run_ids(ENVS)))
    write_report(RESULTS / REPORT, lines, force)


# The paper's orderings that Table 3's locomotion rows speak to (section 5): O1, hints beat vision
# only; O4, hints close the gap to the state-based agent (PPO-x, "dominated by all hints on the
# Ant and Humanoid"); O5, a specific hint beats the full state given as a hint.
def ordering_lines(runs: Path, env: str) -> list[str]:
    """O1, O4 and (where the env has the `state` hint) O5 as probabilities of improvement."""
    from hintsjax.reproduce import stats

    run = lambda label: load(runs, env, label)  # noqa: E731
    hints = {h: run(hints_run("fc", h)) for h in HINTS[env]}
    hints = {h: r for h, r in hints.items() if r is not None}
    if not hints:
        return []
    best = max(hints, key=lambda h: stats.iqm(seed_means(hints[h])))
    label = lambda h: hints_run("fc", h)  # noqa: E731
    pairs = [
        ("O1 (hints beat vision only)", label(best), hints[best], "ppo_rgb", run("ppo_rgb")),
        (
            "O4 (hints close the gap to PPO on the state)",
            label(best),
            hints[best],
            "ppo_state",
            run("ppo_state"),
        ),
    ]
    specific = {h: r for h, r in hints.items() if h != "state"}
    if "state" in hints and specific:
        top = max(specific, key=lambda h: stats.iqm(seed_means(specific[h])))
        pairs.append(
            (
                "O5 (a specific hint beats the full state as a hint)",
                label(top),
                specific[top],
                label("state"),
                hints["state"],
            )
        )
    return [ordering_line(*pair) for pair in pairs if pair[2] is not None and pair[4] is not None]


def learners_report(runs: Path, names: list[str], path: Path, force: bool = False) -> None:
    """The learner rows of Table 3 for `names` from a runs folder at any seed count (the 20-seed
    table, issue 46): per row mean ± std, IQM [95 % CI] and P(row > PPO-RGB); the orderings O1,
    O4 and O5; learning curves with bootstrap bands. Written as the section of `path` that
    GENERATED opens (markdown.write_section): the plan above it and the car's section stay."""
    from hintsjax.settings.layers import run_config

    about = {k: v for k, v in read_about(ARCHIVE / runs.name).items() if k in (*ENVS, "references")}
    lines = [
        "Made by `python experiments/locomotion.py --learners-report "
        f"experiments/results/{path.name} --runs runs/{runs.name}` from the archived runs "
        f"(experiments/results/runs/{runs.name}).",
        "Cells: mean ± std over all seeds x 50 evaluation episodes (in brackets the std "
        "of the per-seed means), the",
        "IQM of the per-seed means with a 95 % stratified bootstrap interval, and P(row "
        "> PPO-RGB) over the seeds.",
        f"GPU wall-clock of the sweeps (runs/{runs.name}/sweeps.jsonl): "
        f"{sweep_seconds(runs, TABLE):.0f} s.",
        "",
    ]
    for env in names:
        labels = [*BASELINES, *(hints_run("fc", h) for h in HINTS[env])]
        results = {label: load(runs, env, label) for label in labels}
        trained = {label: r for label, r in results.items() if r is not None}
        budget = run_config({"env": env}).ppo.total_env_steps / 1e6
        if not trained:
            lines += [f"## {env} ({budget:g} M env steps per seed)", "", "Not trained yet.", ""]
            continue
        seeds = sorted({len(seed_means(r)) for r in trained.values()})
        lines += [
            f"## {env} ({budget:g} M env steps per seed, {', '.join(map(str, seeds))} "
            "seeds per row)",
            "",
            *settings_lines(runs, env, labels),
            "",
        ]
        rgb = results["ppo_rgb"]
        rows = [
            [
                label,
                cell(r),
                iqm_cell(r),
                "-" if label == "ppo_rgb" else poi_cell(r, rgb),
                PAPER[env].get(label, "-"),
                wall_clock(r),
            ]
            for label, r in results.items()
        ]
        lines += markdown_table(
            ["agent", "ours", "IQM [95% CI]", "P(row > PPO-RGB)", "paper", "wall-clock (s)"], rows
        )
        lines += ["", ORDERINGS_ABOUT, "", *ordering_lines(runs, env), ""]
        lines += curve_lines(
            runs,
            env,
            list(trained),
            RESULTS / f"table3_seeds20_curves_{env}.png",
            f"{env}: Table 3 learners, {', '.join(map(str, seeds))} seeds",
        )
    write_section(path, GENERATED, [*lines, *about_lines(about)], force)


GENERATED = generated_marker("locomotion.py")


SCRIPT = TableScript(
    __doc__.splitlines()[0], DEFAULT_RUNS, ENVS, {TABLE: run_ids}, report, learners_report
)


def main() -> None:
    table_main(SCRIPT)


if __name__ == "__main__":
    main()
