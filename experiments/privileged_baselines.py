"""Hints against the baselines that give the same privileged signal to the learner in training only (issue 80).

    python experiments/privileged_baselines.py --envs pendulum,acrobot,idp --seeds 20 --workers 3
    python experiments/privileged_baselines.py --envs halfcheetah,ant --seeds 10
                                               --runs runs/privileged_loco
    python experiments/privileged_baselines.py --report
        # -> experiments/results/privileged_baselines.md

Per env, with its privileged signal (`SIGNAL`: the composite hint on the classic envs, the state on
the locomotion ones): PPO-RGB; the asymmetric actor-critic (`asym_ac`), the hint input
dropped out (`pi_dropout`, FiLM) and the hint as an auxiliary target (`hint_aux`), which all act on
pictures alone at deployment; and HINTS-FC, which needs the hint there. Every run at the env's
budget (config.ENV_DEFAULTS), 50 evaluation episodes a seed. Beside them the report puts HINTS-FC
on a learned generator's hints (read off pictures at deployment too) from learned_hints.py's
archived runs, where there is one. Runs are trained as the other table scripts train theirs
(hintsjax/reproduce/sweep.py): finished folders are skipped, an interrupted one resumes.
"""  # noqa: E501

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from hintsjax.models.agents import AGENTS
from hintsjax.reproduce.archive import ARCHIVE, about_lines, read_about
from hintsjax.reproduce.markdown import markdown_table, write_report
from hintsjax.reproduce.report import (
    ORDERINGS_ABOUT,
    footer,
    interval_text,
    load,
    ppo_text,
    seed_means,
    trained_ppo,
    verdict,
)
from hintsjax.reproduce.table_script import TableScript, table_main

RESULTS = Path(__file__).resolve().parent / "results"
OUT = RESULTS / "privileged_baselines.md"
TABLE = "privileged"
ENVS = ("pendulum", "acrobot", "idp", "halfcheetah", "ant")
SIGNAL = {
    "pendulum": "composite",
    "acrobot": "composite",
    "idp": "composite",
    "halfcheetah": "state",
    "ant": "state",
}
# learned_hints.py's archived runs: <env>-<hint>-learned-k2/eval.json
LEARNED = ARCHIVE / "learned_hints"
LEARNED_FRAMES = 2
# What each row's agent sees of the privileged signal in training, and what it needs at deployment.
ROWS = {
    "ppo_rgb": ("PPO-RGB", "nothing", "pictures"),
    "asym_ac": ("asymmetric actor-critic", "the critic, beside the pictures", "pictures"),
    "pi_dropout": (
        "hint input dropout (FiLM)",
        "the policy, dropped with p = ppo.hint_dropout",
        "pictures",
    ),
    "hint_aux": (
        "hint as an auxiliary target",
        "a head predicting it from the features",
        "pictures",
    ),
    "hints": ("HINTS-FC", "the policy and the critic", "pictures + the hint"),
    "learned": (
        "HINTS-FC, learned generator",
        "the policy and the critic (the generator's hint)",
        "pictures (the generator reads them)",
    ),
}


def labels(env: str) -> list[str]:
    """The run labels of an env's rows, in the table's order (HINTS-FC last: the reference of P)."""
    h = SIGNAL[env]
    return ["ppo_rgb", f"asym_ac-{h}", f"pi_dropout-fc-{h}", f"hint_aux-{h}", f"hints-fc-{h}"]


def run_ids(names: list[str]) -> list[str]:
    return [f"{env}/{label}" for env in names for label in labels(env)]


def learned_result(env: str) -> dict | None:
    """HINTS-FC trained and deployed on a learned generator's hints (learned_hints.py), or None."""
    path = LEARNED / f"{env}-{SIGNAL[env]}-learned-k{LEARNED_FRAMES}" / "eval.json"
    return json.loads(path.read_text()) if path.is_file() else None


def env_lines(runs: Path, env: str) -> list[str]:
    """An env's section: its rows and, for each, P(HINTS-FC > it)."""
    from hintsjax.reproduce import stats

    results = [(label.split("-")[0], load(runs, env, label)) for label in labels(env)]
    if all(result is None for _, result in results):
        return []
    learned = learned_result(env)
    if learned is not None:
        results.append(("learned", learned))
    rgb, hints = dict(results)["ppo_rgb"], dict(results)["hints"]

    def poi(x: dict | None, y: dict | None) -> str:
        if x is None or y is None or x is y:
            return "-"
        ci = stats.poi_ci(seed_means(x), seed_means(y))
        return f"{interval_text(ci)} {verdict(ci)}"

    rows = []
    for kind, result in results:
        name, sees, needs = ROWS[kind]
        if result is None:
            rows.append([name, sees, needs, "-", "-", "-", "-", "-"])
            continue
        x = np.asarray(seed_means(result), np.float64)
        rows.append(
            [
                name,
                sees,
                needs,
                f"{x.mean():.1f} ± {x.std():.1f}",
                stats.iqm_cell(x),
                str(len(x)),
                poi(hints, result),
                poi(result, rgb),
            ]
        )
    ppo = trained_ppo(runs, env, labels(env)[0])
    lines = [
        f"## {env}: the privileged signal is the "
        f"{'state' if SIGNAL[env] == 'state' else f'{SIGNAL[env]} hint'}",
        "",
        *markdown_table(
            [
                "agent",
                "what sees the privileged signal in training",
                "needs at deployment",
                "mean ± std over seeds",
                "IQM [95% CI]",
                "seeds",
                "P(HINTS-FC > row) [95% CI]",
                "P(row > PPO-RGB) [95% CI]",
            ],
            rows,
        ),
        "",
    ]
    if ppo is not None:
        lines += [f"PPO: {ppo_text(ppo)}.", ""]
    if learned is not None:
        lines += [
            "The learned generator's row is learned_hints.py's archived "
            f"run {env}-{SIGNAL[env]}-learned-k{LEARNED_FRAMES} "
            "(experiments/results/learned_hints.md), trained apart from this sweep.",
            "",
        ]
        against = [
            f"{ROWS[kind][0]} {poi(learned, result)}"
            for kind, result in results
            if kind in AGENTS and AGENTS[kind].privileged and result is not None
        ]
        if against:
            lines += [
                "P(learned generator > row), both on pictures alone at deployment: "
                + "; ".join(against)
                + f". Its generator reads the last {LEARNED_FRAMES} pictures; every other row "
                "sees one picture a step.",
                "",
            ]
    else:
        lines += [
            f"No learned generator row: learned_hints.py trained none of the {SIGNAL[env]}.",
            "",
        ]
    return lines


def report(runs: Path, force: bool = False) -> None:
    names = [env for env in ENVS if any(load(runs, env, label) for label in labels(env))]
    lines = [
        "# Hints against the privileged-signal baselines",
        "",
        "Written by `python experiments/privileged_baselines.py --report` from the runs of "
        "`python experiments/privileged_baselines.py --envs ... --seeds ...` "
        "(commands and hardware below). Does a hint do more than giving the same privileged signal "
        "to the learner in training only? The baselines see the signal (the hint HINTS-FC gets, or "
        "the state) in training and act on pictures alone; HINTS-FC needs the hint at deployment. "
        "Returns: the mean over each seed's 50 deterministic episodes, then mean ± std over seeds "
        "and the IQM with its 95% bootstrap interval (hintsjax/reproduce/stats.py). P(HINTS-FC > "
        "row): the probability that a seed of HINTS-FC beats a seed of the row; P(row > PPO-RGB): "
        "whether the row gains on pictures alone.",
        "",
        ORDERINGS_ABOUT.split(" The best hint")[0],
        "",
    ]
    for env in names:
        lines += env_lines(runs, env)
    lines += [
        footer(runs, TABLE, run_ids(names)),
        "",
        *about_lines(read_about(ARCHIVE / runs.name)),
    ]
    write_report(OUT, lines, force)


SCRIPT = TableScript(
    __doc__.splitlines()[0], "runs/privileged", ENVS, {TABLE: run_ids}, report, seeds=20
)

if __name__ == "__main__":
    table_main(SCRIPT)
