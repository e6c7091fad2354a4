"""The committed archive of finished runs: what the result tables need of each, kept in the
checkout.

runs/ is not committed (checkpoints, full logs). What the tables need of each finished run is
kept in experiments/results/runs/<sweep>/<env>/<label>/ (`archive_runs`, which every `--report`
calls first): eval.json and config.yaml as trained, summary.json (the training-return and KL
cells: `training_seed_means` and `kl_share`, worked out from the full metrics.csv) and a
metrics.csv of the learning curve averaged into runlog.CURVE_POINTS bins, as the plots draw it,
with the learning's DIAGNOSTICS averaged into the same bins;
the sweeps' records go to its sweeps.jsonl (`sweep_records`), and an about.json may say how its
runs were made (`read_about`). `run_folder` takes a run from runs/ when it finished there, else
from the archive, so a report on a fresh checkout rebuilds the committed tables.
"""

from __future__ import annotations

import csv
import json
import shutil
import time
from pathlib import Path

from hintsjax.training.runlog import KL_ABOVE, STORM_UPDATES  # noqa: F401  kl_share's and kl_storms' thresholds

# The checkout's experiments/results/runs: the tables and their archive live beside the table
# scripts, in a checkout (an editable install) rather than in an installed package.
ARCHIVE = Path(__file__).resolve().parents[2] / "experiments" / "results" / "runs"
ABOUT_JSON = "about.json"  # in an archive folder, beside its runs: how they were made
SUMMARY_JSON = "summary.json"
# metrics.csv columns an archived run keeps beside the return (binned as it), where the run logged
# them: what a collapsed seed's policy did (its std, its steps' KL, the critic's loss, the reward,
# the adaptive rate's scale where ppo.kl_adaptive_lr chose one) and hint_aux's prediction error
DIAGNOSTICS = ("entropy", "approx_kl", "value_loss", "step_reward", "lr_scale", "hint_loss")
# What reading a run's files raises when they are damaged (a file missing, cut or garbled), not
# refused by the machine
DAMAGED = (
    FileNotFoundError,
    IsADirectoryError,
    NotADirectoryError,
    ValueError,
    KeyError,
    IndexError,
    TypeError,
)


def run_folder(runs: Path, env: str, label: str) -> Path:
    """Its archived copy when the run finished only there (runs/env/label lacks eval.json, the
    archive has it), else runs/env/label (finished, begun, or never run)."""
    folder = runs / env / label
    archived = ARCHIVE / runs.name / env / label
    if (folder / "eval.json").exists() or not (archived / "eval.json").exists():
        return folder
    return archived


def summary(folder: Path) -> dict | None:
    """An archived run's summary.json (None for a run folder in runs/)."""
    path = folder / SUMMARY_JSON
    return json.loads(path.read_text()) if path.exists() else None


def training_seed_means(folder: Path, last: float = 0.1) -> list[float] | None:
    """Per seed, the mean return of the training episodes (sampled actions) that ended in the
    last `last` of a run's updates; None when not run or no episode ended."""
    from hintsjax.training.runlog import read_curves

    if (kept := summary(folder)) is not None:
        return kept["training_return_seed_means"]
    if not (folder / "metrics.csv").exists():
        return None
    return _tail_means(read_curves(folder / "metrics.csv")[1], last)


def _tail_means(values, last: float = 0.1) -> list[float] | None:
    """[S, U] returns, NaNs carried forward -> per seed, the mean over the last `last` of the
    updates; None when no episode ended there."""
    import numpy as np

    tail = values[:, -max(1, int(last * values.shape[1])) :]
    if np.isnan(tail).all():
        return None
    return [float(x) for x in np.nanmean(tail, axis=1)]


def kl_share(folder: Path, above: float = KL_ABOVE) -> float | None:
    """The share of a run's PPO updates (all seeds) whose approx. KL from the rollout policy (the
    mean over the update's minibatch steps, as logged) exceeds `above`; None when not run or
    not trained by PPO (or, for an archived run, `above` is not KL_ABOVE)."""
    from hintsjax.training.runlog import read_log

    if (kept := summary(folder)) is not None:
        return kept["kl_share"] if above == KL_ABOVE else None
    path = folder / "metrics.csv"
    if not path.exists():
        return None
    kl = read_log(path, ("approx_kl",)).columns.get("approx_kl")
    return None if kl is None else _share_above(kl, above)


def _share_above(kl, above: float = KL_ABOVE) -> float:
    """[S, U] approx. KL as logged -> the share of its entries above `above` (NaN is not)."""
    import numpy as np

    return float(np.mean(kl > above))


def unique_lines(*paths: Path) -> list[str]:
    """The non-empty lines of the files that exist among `paths`, each once, in order."""
    return list(
        dict.fromkeys(
            line
            for path in paths
            if path.exists()
            for line in path.read_text().splitlines()
            if line.strip()
        )
    )


def sweep_records(runs: Path, table: int | str) -> list[dict]:
    """The GPU sweeps of `table` recorded in runs/sweeps.jsonl and in the archive's copy (once
    each). A sweep that trained runs of both tables at once is recorded as table "2+4" and counts
    for each. Sweeps run on a CPU (recorded with "device": "cpu") are left out: their runs are
    marked (CPU)."""
    lines = unique_lines(runs / "sweeps.jsonl", ARCHIVE / runs.name / "sweeps.jsonl")
    return [
        r
        for r in map(json.loads, lines)
        if str(table) in str(r["table"]).split("+") and r.get("device") != "cpu"
    ]


def sweep_seconds(runs: Path, table: int | str) -> float:
    """The GPU wall-clock of `table`'s sweeps: sweeps that ran at the same time (on one machine's
    several GPUs) count once, as the union of their [finished - seconds, finished] spans."""
    records = sweep_records(runs, table)
    total = sum(r["seconds"] for r in records if "finished" not in r)  # no timestamp: counted alone
    reach = -float("inf")  # the end of the union so far
    for start, end in sorted(
        (end - r["seconds"], end)
        for r in records
        if "finished" in r
        for end in [time.mktime(time.strptime(r["finished"], "%Y-%m-%d %H:%M:%S"))]
    ):
        total += max(0.0, end - max(start, reach))
        reach = max(reach, end)
    return total


def kl_storms(folder: Path) -> list[dict] | None:
    """Per seed, its KL storms (hintsjax.training.runlog.kl_storms), from an archived run's
    summary.json or a run's metrics.csv; None when not run, not trained by PPO, or archived before
    they were kept."""
    from hintsjax.training import runlog

    if (kept := summary(folder)) is not None:
        return kept.get("kl_storms")
    return runlog.kl_storms(folder / "metrics.csv")


def archive_run(runs: Path, env: str, label: str, into: Path | None = None) -> Path:
    """Copy what the tables need of the finished run runs/env/label into
    `into` (default ARCHIVE)/<runs' name>/env/label (see the module's docstring); returns that
    folder. A run cut short (no eval.json: its machine went away) keeps its config and its log as
    far as it went."""
    import numpy as np

    from hintsjax.settings.layers import CONFIG_YAML
    from hintsjax.training.runlog import bin_means, carried, read_log, storms_of

    src, dest = runs / env / label, (into or ARCHIVE) / runs.name / env / label
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("eval.json", "metrics.csv"):
        (dest / name).unlink(missing_ok=True)  # the archive mirrors the run as it stands
    shutil.copyfile(src / CONFIG_YAML, dest / CONFIG_YAML)
    if (src / "eval.json").exists():
        shutil.copyfile(src / "eval.json", dest / "eval.json")
    if not (src / "metrics.csv").exists():
        (dest / SUMMARY_JSON).write_text(
            json.dumps({"training_return_seed_means": None, "kl_share": None, "kl_storms": None})
            + "\n"
        )
        return dest
    log = read_log(src / "metrics.csv")  # the one pass over the run's full log
    returns = carried(log.columns["episode_return"])
    kl = log.columns.get("approx_kl")
    kept = {
        "training_return_seed_means": _tail_means(returns),
        "kl_share": None if kl is None else _share_above(kl),
        "kl_storms": storms_of(log),
    }
    logged = [c for c in DIAGNOSTICS if c in log.columns]
    extra = [bin_means(log.steps, carried(log.columns[c]))[1] for c in logged]
    # metrics.csv's updates count from 1 without gaps (a resumed run goes on from its checkpoint);
    # each archived row is a bin of them, numbered by its last update
    updates, _ = bin_means(np.arange(1, len(log.steps) + 1), returns)
    steps, values = bin_means(log.steps, returns)
    with (dest / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["update", "seed", "env_steps", "episode_return", *logged])
        writer.writerows(
            [
                updates[i],
                s,
                f"{steps[i]:.0f}",
                f"{values[s, i]:.6g}",
                *(f"{e[s, i]:.4g}" for e in extra),
            ]
            for i in range(len(steps))
            for s in range(values.shape[0])
        )
    (dest / SUMMARY_JSON).write_text(json.dumps(kept, indent=1) + "\n")
    return dest


def archive_runs(runs: Path, run_ids: list[str], into: Path | None = None) -> list[str]:
    """Archive every run of `run_ids` that finished in `runs` (and the sweeps' records) into
    `into` (default ARCHIVE); the archived ids."""
    from hintsjax.system.errors import UsageError, described

    done = [r for r in run_ids if (runs / r / "eval.json").exists()]
    for r in done:
        try:
            archive_run(runs, *r.split("/"), into=into)
        except DAMAGED as e:  # a run's files as no run leaves them; the machine's refusals pass
            raise UsageError(f"{runs / r} cannot be archived: {described(e)}") from None
    if (runs / "sweeps.jsonl").exists():
        path = (into or ARCHIVE) / runs.name / "sweeps.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(line + "\n" for line in unique_lines(path, runs / "sweeps.jsonl")))
    return done


def read_about(folder: Path) -> dict:
    """How a folder's runs were made (commands, hardware, dates, what shared a GPU): its
    about.json, written by whoever ran them; {} when there is none."""
    path = folder / ABOUT_JSON
    return json.loads(path.read_text()) if path.is_file() else {}


def about_lines(about: dict) -> list[str]:
    """A report's closing section from `read_about`'s entries, a bullet each (a list's items and a
    mapping's entries as bullets under it, a mapping's values as code); [] when there are none."""
    if not about:
        return []
    lines = ["## Where these numbers come from", ""]
    for key, value in about.items():
        if isinstance(value, dict):
            lines += [f"- {key}:", *(f"  - {k}: `{v}`" for k, v in value.items())]
        elif isinstance(value, list):
            lines += [f"- {key}:", *(f"  - {v}" for v in value)]
        else:
            lines.append(f"- {key}: {value}")
    return lines + [""]
