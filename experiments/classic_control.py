"""The paper's classic control tables (pendulum, acrobot, idp): Table 2 and Table 4, reproduced.

    python experiments/classic_control.py --table 2 [--envs acrobot,idp] [--seeds 20] [--workers 3]
    python experiments/classic_control.py --table 4 [--workers 3] [--launch-until 300]
    python experiments/classic_control.py --report       # markdown tables and learning curves
    python experiments/classic_control.py --learners-report FILE --runs runs/classic20
        --envs pendulum

Table 2: per env the converged references (expert PPO, DAgger, GAIL), PPO-RGB, PPO-x,
PPO-x+N(0,1) and HINTS-FC with every hint the env registers. The expert's run exports its best
seed as the env's expert (--experts, default the package's hintsjax/experts/<env>) when it
finishes; that env's dagger and gail runs start only then.
Table 4: HINTS with each scheme (fc, lc, ac, mc) times the table's hint columns.
Every configuration is trained at the env's default budget (config.ENV_DEFAULTS) with --seeds
seeds (default 20), then evaluated on 50 episodes per seed; its folder under --runs holds
config.yaml, metrics.csv and eval.json. Runs that share a network's shapes train as one group,
all their seeds in one compiled program (hintsjax/algorithms/group.py; e.g. HINTS-FC with every
hint), and `--alone` trains each in its own. Finished folders are skipped and groups resume from
their checkpoints, so an interrupted sweep resumes where it stopped. `--workers N` trains N groups
at once in separate processes (each gets 1/N of the GPU's memory, and a group that does not fit is
split in halves). `--report` only reads finished folders and writes
experiments/results/classic_table{2,4}.md and classic_curves_<env>.png (the 5-seed tables);
`--learners-report` writes the learner rows of --envs at any seed count (the 20-seed tables).
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Callable

from hintsjax.reproduce.archive import sweep_seconds
from hintsjax.reproduce.markdown import markdown_table, refuse_lost_cells, write_report
from hintsjax.reproduce.report import (
    cell,
    iqm_cell,
    load,
    mean_of,
    metrics_path,
    ordering,
    wall_clock,
)
from hintsjax.reproduce.sweep import hints_run
from hintsjax.reproduce.table_script import TableScript, table_main

RESULTS = Path(__file__).resolve().parent / "results"
ENVS = ("pendulum", "acrobot", "idp")
BASELINES = ("ppo_rgb", "ppo_state", "ppo_noisy_state")
# The converged references: the expert's run is exported (its best seed) to --experts/<env>
# as soon as it finishes, and dagger and gail of that env start only then and learn from it.
REFERENCES = ("expert_ppo", "dagger", "gail")
SCHEMES = ("fc", "lc", "ac", "mc")

# The hint columns of each table, per env (Table 2: every registered hint; Table 4: the paper's).
TABLE2_HINTS = {
    "pendulum": (
        "angular_velocity",
        "torque",
        "goal_distance",
        "composite",
        "partial_state",
        "state",
    ),
    "acrobot": (
        "angular_velocity_1",
        "angular_velocity_2",
        "joint",
        "goal_distance",
        "composite",
        "partial_state",
        "state",
    ),
    "idp": (
        "angular_velocity_1",
        "angular_velocity_2",
        "joint",
        "goal_distance",
        "composite",
        "partial_state",
        "state",
    ),
}
TABLE4_HINTS = {
    "pendulum": ("angular_velocity", "composite", "partial_state", "state"),
    "acrobot": ("angular_velocity_1", "angular_velocity_2", "composite", "state"),
    "idp": ("angular_velocity_1", "angular_velocity_2", "composite", "state"),
}

# The paper's Table 2 (mean ± std over n=50), keyed by our run labels; "-" where it has no cell.
PAPER_TABLE2 = {
    "pendulum": {
        "expert_ppo": "-174.77 ± 96.7",
        "dagger": "-253.93 ± 216.4",
        "gail": "-191.99 ± 118.9",
        "ppo_state": "-1270.86 ± 77.3",
        "ppo_noisy_state": "-1100.96 ± 66.8",
        "ppo_rgb": "-1352.82 ± 169.6",
        "hints-fc-angular_velocity": "-250.31 ± 164.0",
        "hints-fc-torque": "-1236.58 ± 256.8",
        "hints-fc-goal_distance": "-1203.08 ± 307.6",
        "hints-fc-composite": "-241.14 ± 178.5",
        "hints-fc-partial_state": "-1304.77 ± 180.1",
        "hints-fc-state": "-1248.46 ± 150.5",
    },
    "acrobot": {
        "expert_ppo": "-72.44 ± 13.1",
        "dagger": "-67.30 ± 0.0",
        "gail": "-500.00 ± 0.0",
        "ppo_state": "-197.90 ± 36.4",
        "ppo_noisy_state": "-201.60 ± 41.1",
        "ppo_rgb": "-500.00 ± 0.0",
        "hints-fc-angular_velocity_1": "-212.38 ± 52.2",
        "hints-fc-angular_velocity_2": "-228.98 ± 63.2",
        "hints-fc-joint": "-302.24 ± 75.7",
        "hints-fc-composite": "-197.40 ± 41.4",
        "hints-fc-partial_state": "-241.66 ± 46.5",
        "hints-fc-state": "-500.00 ± 0.0",
    },
    "idp": {
        "expert_ppo": "906.34 ± 150.2",
        "dagger": "943.85 ± 0.8",
        "gail": "943.26 ± 0.7",
        "ppo_state": "944.67 ± 0.2",
        "ppo_noisy_state": "109.98 ± 25.9",
        "ppo_rgb": "130.99 ± 41.8",
        "hints-fc-angular_velocity_1": "281.14 ± 99.6",
        "hints-fc-angular_velocity_2": "400.34 ± 215.6",
        "hints-fc-goal_distance": "40.07 ± 9.7",
        "hints-fc-composite": "680.84 ± 659.8",
        "hints-fc-partial_state": "70.35 ± 19.0",
        "hints-fc-state": "88.56 ± 14.4",
    },
}
PAPER_SWINGTO = {  # Table 2's "Swingto deploy" row
    "dagger": "111.82 ± 137.8",
    "ppo_state": "120.15 ± 85.3",
    "ppo_noisy_state": "115.20 ± 44.5",
    "ppo_rgb": "21.26 ± 138.9",
    "hints-fc-angular_velocity": "111.08 ± 186.4",
    "hints-fc-composite": "-118.48 ± 72.0",
    "hints-fc-state": "18.76 ± 105.5",
}
# The paper's Table 4, [scheme][env][hint column]. Its scale differs from Table 2's (acrobot's
# floor is -2500 = 5 x -500), so only orderings compare with ours.
_T4 = {
    "fc": (
        "-2895.88 ± 1767.0",
        "-2550.84 ± 1812.2",
        "-6445.25 ± 755.1",
        "-6423.87 ± 597.8",
        "-1414.50 ± 408.3",
        "-1703.50 ± 458.0",
        "-1429.17 ± 528.2",
        "-2500.00 ± 0.0",
        "612.94 ± 165.0",
        "817.53 ± 403.8",
        "1998.69 ± 1288.0",
        "443.80 ± 72.9",
    ),
    "lc": (
        "-5900.90 ± 638.9",
        "-3801.58 ± 1142.6",
        "-6166.61 ± 1026.3",
        "-6419.55 ± 668.3",
        "-2008.83 ± 303.4",
        "-2258.17 ± 254.7",
        "-1534.00 ± 498.7",
        "-2499.33 ± 1.5",
        "592.78 ± 145.2",
        "753.34 ± 274.7",
        "1334.98 ± 927.0",
        "462.45 ± 112.2",
    ),
    "ac": (
        "-6194.73 ± 365.9",
        "-5087.93 ± 875.5",
        "-6227.93 ± 907.5",
        "-6357.87 ± 916.2",
        "-1922.83 ± 351.4",
        "-2104.00 ± 298.9",
        "-1432.50 ± 536.1",
        "-2500.00 ± 0.0",
        "636.26 ± 207.0",
        "683.84 ± 216.7",
        "1690.04 ± 1191.5",
        "437.73 ± 53.7",
    ),
    "mc": (
        "-6473.45 ± 629.3",
        "-6379.08 ± 688.7",
        "-6408.13 ± 818.5",
        "-6439.26 ± 788.6",
        "-2363.83 ± 111.0",
        "-1934.33 ± 316.0",
        "-2350.00 ± 155.3",
        "-2500.00 ± 0.0",
        "640.28 ± 182.7",
        "745.28 ± 284.9",
        "983.13 ± 798.7",
        "404.53 ± 67.5",
    ),
}
PAPER_TABLE4 = {
    scheme: {
        env: dict(zip(TABLE4_HINTS[env], cells[4 * i : 4 * i + 4])) for i, env in enumerate(ENVS)
    }
    for scheme, cells in _T4.items()
}


def table_runs(table: int, env: str) -> list[str]:
    """The run labels a table needs for one env (labels are RunConfig.label)."""
    if table == 2:
        return [*REFERENCES, *BASELINES, *(hints_run("fc", h) for h in TABLE2_HINTS[env])]
    return [hints_run(s, h) for s in SCHEMES for h in TABLE4_HINTS[env]]


# -- the report ----------------------------------------------------------------------------------


# The rows a Table 4 shows per scheme: (row label after the scheme's name, the cell of a run).
ROW_OURS = (" (ours)", cell)
ROW_OURS_IQM = (" (ours, IQM [95% CI])", iqm_cell)
ROW_IQM = ("", iqm_cell)
ROW_PAPER = (" (paper)", None)  # the paper's cell (PAPER_TABLE4), not a run's


def scheme_table(
    runs: Path, env: str, *kinds: tuple[str, Callable[[dict | None], str] | None]
) -> list[str]:
    """Table 4 of one env as markdown: its hint columns across, and per scheme one row of each of
    `kinds`."""
    cols = TABLE4_HINTS[env]

    def row(scheme: str, suffix: str, cell_of) -> list[str]:
        if cell_of is None:
            return [scheme + suffix, *(PAPER_TABLE4[scheme][env][h] for h in cols)]
        return [scheme + suffix, *(cell_of(load(runs, env, hints_run(scheme, h))) for h in cols)]

    return markdown_table(
        ["scheme", *cols], [row(scheme, *kind) for scheme in SCHEMES for kind in kinds]
    )


def findings(runs: Path, env: str) -> str:
    """O1 (hints vs vision only) and O5 (composite vs partial and full state), as numbers."""
    rgb = mean_of(load(runs, env, "ppo_rgb"))
    hints = {h: mean_of(load(runs, env, hints_run("fc", h))) for h in TABLE2_HINTS[env]}
    hints = {h: v for h, v in hints.items() if v is not None}
    if rgb is None or not hints:
        return ""
    best = max(hints, key=hints.get)
    gain = (hints[best] - rgb) / abs(rgb) if rgb else float("nan")
    text = (
        f"O1: best HINTS-FC hint `{best}` {hints[best]:.1f} vs PPO-RGB {rgb:.1f} "
        f"({gain:+.0%} of |PPO-RGB|)."
    )
    if "composite" in hints:
        others = [f"{h} {hints[h]:.1f}" for h in ("partial_state", "state") if h in hints]
        text += f" O5: composite {hints['composite']:.1f} vs " + ", ".join(others) + "."
    return text + orderings(runs, env, best)


def orderings(runs: Path, env: str, best: str) -> str:
    """The paper's orderings that Table 2 touches, as probabilities of improvement over seeds:
    O1 (the best hint and the composite over PPO-RGB), O5 (the composite over partial and full
    state as hints) and, on the pendulum, O6 (on swingto, angular velocity over the composite)."""
    run = lambda h: load(runs, env, hints_run("fc", h))  # noqa: E731
    rgb = load(runs, env, "ppo_rgb")
    pairs = [
        ("O1", ordering(best, run(best), "ppo_rgb", rgb)),
        (
            "O1",
            ordering("composite", run("composite"), "ppo_rgb", rgb)
            if best != "composite"
            else None,
        ),
        *(
            ("O5", ordering("composite", run("composite"), h, run(h)))
            for h in ("partial_state", "state")
        ),
        (
            "O6",
            ordering(
                "angular_velocity",
                run("angular_velocity"),
                "composite",
                run("composite"),
                variant=1,
            )
            if env == "pendulum"
            else None,
        ),
    ]
    lines = [
        f"- {tag}: {text}" + (" (on swingto)" if tag == "O6" else "") for tag, text in pairs if text
    ]
    if not lines:
        return ""
    return (
        "\n\nOrderings as probabilities of improvement over the per-seed mean returns, "
        "with 95% bootstrap intervals (hintsjax/reproduce/stats.py); "
        "decided where the interval excludes 0.5:\n\n" + "\n".join(lines)
    )


def paper_mean(value: str) -> float:
    return float(value.split("±")[0])


def scheme_findings(runs: Path, env: str) -> str:
    """Per hint column, the best scheme in our runs and in the paper's Table 4."""
    parts, agree = [], 0
    for h in TABLE4_HINTS[env]:
        ours = {s: mean_of(load(runs, env, hints_run(s, h))) for s in SCHEMES}
        if any(v is None for v in ours.values()):
            return ""
        paper = {s: paper_mean(PAPER_TABLE4[s][env][h]) for s in SCHEMES}
        best, paper_best = max(ours, key=ours.get), max(paper, key=paper.get)
        agree += best == paper_best
        parts.append(f"{h}: {best} (paper {paper_best})")
    return (
        "Best scheme per hint column by mean return, as the paper ranks, ours (paper): "
        + "; ".join(parts)
        + f". The best scheme agrees with the paper's in {agree} of {len(parts)} columns."
    )


def report(runs: Path, force: bool = False) -> None:
    from hintsjax.training.runlog import plot_curves, read_curves

    RESULTS.mkdir(exist_ok=True)
    head = [
        "Each cell: mean ± std of the episode return over all 5 training seeds x 50 evaluation "
        "episodes",
        "(deterministic policy); in brackets the std of the 5 per-seed means, which is the honest",
        "error bar for comparing agents. Budgets (env steps per seed): "
        "pendulum 200 K (1000 episodes),",
        "acrobot 350 K (700 episodes of 500 steps), idp 200 K (see TRAINING in envs/<env>.py).",
        "The paper's cells are mean ± std over n=50; where the paper has no cell, '-'; "
        "where we have",
        "not run a configuration yet, '-'. Per-run wall-clock (one H100) includes compilation and",
        "evaluation, with 3 to 10 runs sharing the GPU (time-sliced) "
        "in the sweeps of 2026-11-22 05:30-08:25,",
        "so it overstates a run's cost alone; the pendulum rows trained before then (all but "
        "torque and",
        "ppo_noisy_state) ran one at a time. '(CPU)': trained on a 2-core CPU when the GPU time "
        "was spent.",
        "The last column is the interquartile mean of the per-seed mean returns with a 95% "
        "percentile",
        "bootstrap interval over seeds (hintsjax/reproduce/stats.py, as rliable computes it); "
        "with 5 seeds the IQM",
        "is the mean of the middle 3 and the interval is wide.",
        "",
    ]
    lines, curves = ["# Classic control: the paper's Table 2, reproduced", "", *head], {}
    for env in ENVS:
        lines += [f"## {env}", ""]
        deploy = env == "pendulum"
        header = [
            "agent",
            "ours",
            "paper",
            *(["swingto deploy (ours)", "swingto (paper)"] if deploy else []),
            "wall-clock (s)",
            "IQM of seed means [95% CI]",
        ]
        rows = []
        for label in table_runs(2, env):
            result = load(runs, env, label)
            deployed = [cell(result, 1), PAPER_SWINGTO.get(label, "-")] if deploy else []
            rows.append(
                [
                    label,
                    cell(result),
                    PAPER_TABLE2[env].get(label, "-"),
                    *deployed,
                    wall_clock(result),
                    iqm_cell(result),
                ]
            )
        lines += markdown_table(header, rows)
        lines += [
            "",
            findings(runs, env),
            "",
            f"![{env} learning curves](classic_curves_{env}.png)",
            "",
        ]
        curves[env] = {
            label: read_curves(path)
            for label in table_runs(2, env)
            if label not in REFERENCES and (path := metrics_path(runs, env, label)) is not None
        }
    lines += [
        f"Sweep wall-clock recorded in {runs}/sweeps.jsonl for `--table 2` on the GPU: "
        f"{sweep_seconds(runs, 2):.0f} s (it includes runs that the 10-minute limit of a GPU call "
        "interrupted and a later call retrained; the (CPU) rows' sweeps are not in it).",
        "",
        "The references (TRAINING['references'] in envs/<env>.py): expert_ppo is PPO on the state "
        "for",
        "1 M env steps per seed; its best seed (by its 50-episode evaluation) "
        "is the env's packaged expert",
        "(hintsjax/experts/<env>/expert.json). dagger (100 K env steps, rounds of 1024, "
        "beta 0.5^i) and",
        "gail (1 M env steps, 16 expert episodes) learn from that expert. "
        "GAIL's reward is the log odds",
        "log D - log(1 - D) on pendulum and acrobot and Ho and Ermon's -log(1 - D) on idp: "
        "with the log",
        "odds, mostly negative at first, ending an episode early pays, "
        "and idp's episodes end by falling",
        "(idp gail with the log odds: "
        f"{cell(load(runs.parent / 'classic_extra', 'idp', 'gail-logit'))}, in",
        "runs/classic_extra/idp/gail-logit); with -log(1 - D) > 0 every step alive pays, "
        "which on acrobot",
        "keeps an agent from its terminating goal (the paper's GAIL scored -500 there).",
        "",
        "The pendulum's references were retrained on 2026-11-22 (one H100, two runs at a time, "
        "outside",
        "the sweep) with the PPO tuned for the state pendulum (ENV_DEFAULTS: "
        "one 200-step episode per",
        "rollout, gamma 0.95, entropy 0.01); dagger learnt from that expert. "
        "Without the entropy bonus:",
        f"expert_ppo {cell(load(runs.parent / 'classic_extra', 'pendulum', 'expert_ppo-ent0'))}, "
        f"gail {cell(load(runs.parent / 'classic_extra', 'pendulum', 'gail-ent0'))} "
        "(runs/classic_extra/pendulum).",
    ]
    table2 = lines

    lines = [
        "# Classic control: the paper's Table 4 (conditioning schemes), reproduced",
        "",
        *head,
        "The paper's Table 4 is on another scale than its Table 2 "
        "(its acrobot floor is -2500 = 5 x -500),",
        "so compare orderings, not values. The fc row shares its runs with Table 2.",
        "",
    ]
    for env in ENVS:
        lines += [f"## {env}", "", *scheme_table(runs, env, ROW_OURS, ROW_OURS_IQM, ROW_PAPER), ""]
        lines += [scheme_findings(runs, env), ""]
    lines.append(
        "Sweep wall-clock recorded for the Table 4 runs not already in Table 2: "
        f"{sweep_seconds(runs, 4):.0f} s over the GPU calls that trained them (one call also "
        "trained Table 2's references and counts for both)."
    )
    reports = ((RESULTS / "classic_table2.md", table2), (RESULTS / "classic_table4.md", lines))
    for path, table in reports if not force else ():
        refuse_lost_cells(path, table)  # before anything is written
    for path, table in reports:
        write_report(path, table, force=True)
    # only after the tables: a refused report redraws nothing
    for env, env_curves in curves.items():
        if env_curves:
            plot_curves(
                env_curves, RESULTS / f"classic_curves_{env}.png", f"{env}: Table 2 agents, 5 seeds"
            )


def learners_report(runs: Path, envs: list[str], path: Path, force: bool = False) -> None:
    """The learner rows of Table 2 (and of Table 4 where run) of `envs` from a runs folder at any
    seed count, with IQM [95% CI] and the orderings as probabilities of improvement."""
    lines = [
        f"# Classic control at more seeds: the learner rows of Tables 2 and 4 ({runs})",
        "",
        "Cells: mean ± std over all seeds x 50 evaluation episodes (in brackets the std of the "
        "per-seed means),",
        "then the IQM of the per-seed means with a 95% stratified bootstrap interval "
        "(hintsjax/reproduce/stats.py).",
        "Wall-clock: the whole group's (compiles and evaluation included); "
        "the runs of a group train in one",
        "program (hintsjax/algorithms/group.py) and share it. "
        "Command and hardware: experiments/results/table_in_one_call.json.",
        f"Recorded sweep wall-clock in {runs}/sweeps.jsonl: "
        f"Table 2 {sweep_seconds(runs, 2):.0f} s, Table 4 {sweep_seconds(runs, 4):.0f} s "
        "(a sweep stopped by a time limit and resumed counts its resumed call only).",
        "",
    ]
    for env in envs:
        labels = [label for label in table_runs(2, env) if label not in REFERENCES]
        results = {label: load(runs, env, label) for label in labels}
        seeds = sorted({len(r["evaluations"][0]["seed_means"]) for r in results.values() if r})
        deploy = env == "pendulum"
        header = [
            "agent",
            "ours",
            "IQM [95% CI]",
            "paper",
            *(["swingto (ours)", "swingto IQM", "swingto (paper)"] if deploy else []),
            "group wall-clock (s)",
        ]
        rows = []
        for label, result in results.items():
            deployed = (
                [cell(result, 1), iqm_cell(result, 1), PAPER_SWINGTO.get(label, "-")]
                if deploy
                else []
            )
            rows.append(
                [
                    label,
                    cell(result),
                    iqm_cell(result),
                    PAPER_TABLE2[env].get(label, "-"),
                    *deployed,
                    wall_clock(result),
                ]
            )
        lines += [
            f"## {env} ({', '.join(map(str, seeds))} seeds per row)",
            "",
            *markdown_table(header, rows),
            "",
        ]
        lines += [findings(runs, env), ""]
        missing = [
            hints_run(s, h)
            for s in SCHEMES
            for h in TABLE4_HINTS[env]
            if load(runs, env, hints_run(s, h)) is None
        ]
        # some run beyond the fc row, Table 2's
        if len(missing) < len(SCHEMES[1:]) * len(TABLE4_HINTS[env]):
            lines += [
                f"### {env}: Table 4 (conditioning schemes), IQM [95% CI] of the per-seed means",
                "",
                *(
                    [f"Not trained at this seed count yet ('-' below): {', '.join(missing)}.", ""]
                    if missing
                    else []
                ),
                *scheme_table(runs, env, ROW_IQM),
                "",
                "Mean ± std (std of the seed means), for comparison with the paper's cells:",
                "",
                *scheme_table(runs, env, ROW_OURS, ROW_PAPER),
            ]
            found = scheme_findings(runs, env)
            lines += ["", *([found, ""] if found else []), scheme_orderings(runs, env), ""]
    write_report(path, lines, force)


def scheme_orderings(runs: Path, env: str) -> str:
    """Per hint column of Table 4, the best scheme by IQM against each other scheme (of those
    trained), as probabilities of improvement over seeds."""
    from hintsjax.reproduce import stats

    lines = []
    for h in TABLE4_HINTS[env]:
        results = {s: load(runs, env, hints_run(s, h)) for s in SCHEMES}
        results = {s: r for s, r in results.items() if r is not None}
        best = max(results, key=lambda s: stats.iqm(results[s]["evaluations"][0]["seed_means"]))
        lines += [
            f"- {h}: {ordering(best, results[best], other, results[other])}"
            for other in results
            if other != best
        ]
    return (
        "Best scheme per hint column (by IQM) against the others, P(best > other) [95% CI]:\n\n"
        + "\n".join(lines)
    )


def run_ids(table: int, names: list[str]) -> list[str]:
    """The runs `env/label` a table needs for the envs `names`."""
    return [f"{env}/{label}" for env in names for label in table_runs(table, env)]


# --table 2 or 4 picks the table to train (Table 4's fc row is Table 2's runs: once finished, its
# sweep leaves them out).
SCRIPT = TableScript(
    __doc__.splitlines()[0],
    "runs/classic",
    ENVS,
    {t: partial(run_ids, t) for t in (2, 4)},
    report,
    learners_report,
    seeds=20,
)


def main() -> None:
    table_main(SCRIPT)


if __name__ == "__main__":
    main()
