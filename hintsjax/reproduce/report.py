"""Reading finished runs into the result tables, and the committed archive of what they need.

The readers (`load`, `cell`, `metric_cell`, `training_cell`, `kl_cell`, `wall_clock`,
`sweep_seconds`) give the cells of the tables of classic_control.py, locomotion.py and
car_racing.py; `markdown_table` renders every table of them, and `write_report` writes a report,
refusing to blank cells that the committed one fills.

runs/ is not committed (checkpoints, full logs). What the tables need of each finished run is
kept in the committed archive experiments/results/runs/<sweep>/<env>/<label>/ (`archive_runs`,
which every `--report` calls first): eval.json and config.yaml as trained, summary.json (the
training-return and KL cells, worked out from the full metrics.csv) and a metrics.csv of the
learning curve averaged into runlog.CURVE_POINTS bins, as the plots draw it; the sweeps' records
go to its sweeps.jsonl. The readers take a run from runs/ when it finished there, else from the
archive, so a report on a fresh checkout rebuilds the committed tables.
"""

from __future__ import annotations

import csv
import json
import shutil
import sys
import time
from pathlib import Path

# The checkout's experiments/results/runs: the tables and their archive live beside the table
# scripts, in a checkout (an editable install) rather than in an installed package.
ARCHIVE = Path(__file__).resolve().parents[2] / "experiments" / "results" / "runs"
ABOUT_JSON = "about.json"  # in an archive folder, beside its runs: how they were made
SUMMARY_JSON = "summary.json"
KL_ABOVE = 0.5  # kl_cell's threshold: an update whose approx. KL exceeds it blew up


def run_folder(runs: Path, env: str, label: str) -> Path:
    """Its archived copy when the run finished only there (runs/env/label lacks eval.json, the
    archive has it), else runs/env/label (finished, begun, or never run)."""
    folder = runs / env / label
    archived = ARCHIVE / runs.name / env / label
    if (folder / "eval.json").exists() or not (archived / "eval.json").exists():
        return folder
    return archived


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


def ordering(name_x: str, x: dict | None, name_y: str, y: dict | None, variant: int = 0) -> str | None:
    """'P(x > y) = p [low, high]: decided|undecided' over the two runs' per-seed mean returns (95%
    bootstrap CI; decided when it excludes 0.5), or None when either was not run."""
    from hintsjax.reproduce import stats

    if x is None or y is None:
        return None
    return stats.ordering_text(name_x, name_y, stats.poi_ci(seed_means(x, variant), seed_means(y, variant)))


def seed_means(result: dict, variant: int = 0) -> list[float]:
    """One evaluation's per-seed mean returns."""
    return result["evaluations"][variant]["seed_means"]


def interval_text(ci) -> str:
    return f"{ci.point:.2f} [{ci.low:.2f}, {ci.high:.2f}]"


def verdict(interval) -> str:
    """An interval of P(X > Y) -> 'decided for' (above 0.5), 'decided against' (below) or 'undecided'."""
    from hintsjax.reproduce import stats

    return {1: "decided for", -1: "decided against", 0: "undecided"}[stats.direction(interval)]


def poi_cell(x: dict | None, y: dict | None, variant: int = 0) -> str:
    """'P [low, high]' of P(x > y) over seeds, or '-'."""
    from hintsjax.reproduce import stats

    return "-" if x is None or y is None else interval_text(stats.poi_ci(seed_means(x, variant), seed_means(y, variant)))


def ordering_line(tag: str, name_x: str, x: dict, name_y: str, y: dict, variant: int = 0) -> str:
    """'- O1 (...): P(x > y) = p [low, high]: decided for' over the two runs' per-seed mean returns."""
    from hintsjax.reproduce import stats

    ci = stats.poi_ci(seed_means(x, variant), seed_means(y, variant))
    return f"- {tag}: P({name_x} > {name_y}) = {interval_text(ci)}: {verdict(ci)}"


ORDERINGS_ABOUT = (
    "Orderings: probabilities of improvement P(X > Y) over the per-seed mean returns with 95 % bootstrap intervals "
    "(hintsjax/reproduce/stats.py). Decided for: the interval lies above 0.5; decided against: below 0.5; undecided: it "
    "contains 0.5. The best hint is the hint row with the highest IQM, chosen on the same seeds, which favours "
    "it a little.")


def ppo_text(ppo) -> str:
    """A line of the PPO settings (config.PPOConfig) that a report states beside its rows."""
    return (f"{ppo.num_envs} envs per seed, batches of {ppo.batch_size}, {ppo.epochs} epochs of minibatches of "
            f"{ppo.minibatch_size}, learning rates encoder {ppo.encoder_lr:g}, actor {ppo.actor_lr:g}, critic {ppo.critic_lr:g}"
            + (f", KL early stop at {ppo.target_kl:g}" if ppo.target_kl else "")
            + (f", rewards x {ppo.reward_scale:g}" if ppo.reward_scale != 1.0 else "")
            + (", the state normalised" if ppo.normalize_state else ""))


def metric_of(result: dict | None, name: str, variant: int = 0) -> tuple[float, float, float] | None:
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
    """A run's metrics.csv (archived ones hold runlog.CURVE_POINTS bins of updates), or None when not run."""
    path = run_folder(runs, env, label) / "metrics.csv"
    return path if path.exists() else None


def summary(folder: Path) -> dict | None:
    """An archived run's summary.json (None for a run folder in runs/)."""
    path = folder / SUMMARY_JSON
    return json.loads(path.read_text()) if path.exists() else None


def training_seed_means(folder: Path, last: float = 0.1) -> list[float] | None:
    """Per seed, the mean return of the training episodes (sampled actions) that ended in the
    last `last` of a run's updates; None when not run or no episode ended."""
    import numpy as np

    from hintsjax.training.runlog import read_curves

    if (kept := summary(folder)) is not None:
        return kept["training_return_seed_means"]
    if not (folder / "metrics.csv").exists():
        return None
    _, values = read_curves(folder / "metrics.csv")
    tail = values[:, -max(1, int(last * values.shape[1])):]
    if np.isnan(tail).all():
        return None
    return [float(x) for x in np.nanmean(tail, axis=1)]


def training_cell(runs: Path, env: str, label: str) -> str:
    """Mean ± std over seeds of `training_seed_means` (the last 10% of updates): beside
    `cell`'s deterministic evaluation; '-' when not run."""
    import numpy as np

    per_seed = training_seed_means(run_folder(runs, env, label))
    if per_seed is None:
        return "-"
    return f"{np.nanmean(per_seed):.1f} ± {np.nanstd(per_seed):.1f}"


def kl_share(folder: Path, above: float = KL_ABOVE) -> float | None:
    """The share of a run's PPO updates (all seeds) whose approx. KL from the rollout policy (the
    mean over the update's minibatch steps, as logged) exceeds `above`; None when not run or
    not trained by PPO (or, for an archived run, `above` is not KL_ABOVE)."""
    import numpy as np

    if (kept := summary(folder)) is not None:
        return kept["kl_share"] if above == KL_ABOVE else None
    path = folder / "metrics.csv"
    if not path.exists():
        return None
    with path.open() as f:
        reader = csv.DictReader(f)
        if "approx_kl" not in (reader.fieldnames or ()):
            return None
        kl = np.array([float(row["approx_kl"]) for row in reader])
    return float(np.mean(kl > above))


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
    return load_run_config(folder) if (folder / "eval.json").exists() and (folder / CONFIG_YAML).exists() else None


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

    cfg = {a: trained_config(runs, env, a) or run_config({"env": env, "agent": a}) for a in references}
    expert = cfg["expert_ppo"].ppo
    source = "its best seed"
    if (result := load(runs, env, "expert_ppo")) is not None:  # the one its sweep exported
        evaluation = result["evaluations"][0]
        best = best_seed(evaluation)
        source += f" (seed {best}, {evaluation['seed_means'][best]:.0f} over {evaluation['episodes_per_seed']} episodes)"
    elif (meta := EXPERTS_DIR / env / EXPERT_JSON).exists():  # not trained here: the packaged expert
        m = json.loads(meta.read_text())
        source += f" (seed {m['seed_index']}, {m['seed_eval_mean']:.0f} over {m['episodes_per_seed']} episodes; hintsjax/experts/{env})"
    text = (f"References (no budget limit): expert_ppo is PPO on the state for {expert.total_env_steps / 1e6:g} M steps "
            f"({expert.num_envs} envs per seed, batches of {expert.batch_size}, {expert.epochs} epochs of minibatches of "
            f"{expert.minibatch_size}); dagger learns from {source} over {cfg['dagger'].ppo.total_env_steps / 1e3:g} K "
            f"expert-labelled steps")
    if "gail" in cfg:
        gail = cfg["gail"]
        reward = "-log(1 - D)" if gail.gail.reward == "original" else "the log odds log D - log(1 - D)"
        text += (f"; gail learns from {gail.gail.demonstrations} of that expert's episodes, by PPO for "
                 f"{gail.ppo.total_env_steps / 1e6:g} M steps on the discriminator's reward {reward}"
                 + (", the discriminator reading the state standardised by the demonstrations' statistics"
                    if gail.gail.normalize_state else "")
                 + (f" and held smooth by an R1 penalty of {gail.gail.grad_penalty:g} on the expert's pairs"
                    if gail.gail.grad_penalty else ""))
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


def unique_lines(*paths: Path) -> list[str]:
    """The non-empty lines of the files that exist among `paths`, each once, in order."""
    return list(dict.fromkeys(line for path in paths if path.exists() for line in path.read_text().splitlines() if line.strip()))


def sweep_records(runs: Path, table: int | str) -> list[dict]:
    """The GPU sweeps of `table` recorded in runs/sweeps.jsonl and in the archive's copy (once
    each). A sweep that trained runs of both tables at once is recorded as table "2+4" and counts
    for each. Sweeps run on a CPU (recorded with "device": "cpu") are left out: their runs are
    marked (CPU)."""
    lines = unique_lines(runs / "sweeps.jsonl", ARCHIVE / runs.name / "sweeps.jsonl")
    return [r for r in map(json.loads, lines) if str(table) in str(r["table"]).split("+") and r.get("device") != "cpu"]


def sweep_seconds(runs: Path, table: int | str) -> float:
    """The GPU wall-clock of `table`'s sweeps: sweeps that ran at the same time (on one machine's
    several GPUs) count once, as the union of their [finished - seconds, finished] spans."""
    records = sweep_records(runs, table)
    total = sum(r["seconds"] for r in records if "finished" not in r)  # no timestamp: counted alone
    reach = -float("inf")  # the end of the union so far
    for start, end in sorted((end - r["seconds"], end) for r in records if "finished" in r
                             for end in [time.mktime(time.strptime(r["finished"], "%Y-%m-%d %H:%M:%S"))]):
        total += max(0.0, end - max(start, reach))
        reach = max(reach, end)
    return total


def archive_run(runs: Path, env: str, label: str) -> Path:
    """Copy what the tables need of the finished run runs/env/label into
    ARCHIVE/<runs' name>/env/label (see the module's docstring); returns that folder."""
    import numpy as np

    from hintsjax.settings.layers import CONFIG_YAML
    from hintsjax.training.runlog import bin_means, read_curves

    src, dest = runs / env / label, ARCHIVE / runs.name / env / label
    dest.mkdir(parents=True, exist_ok=True)
    for name in ("eval.json", CONFIG_YAML):
        shutil.copyfile(src / name, dest / name)
    (dest / "metrics.csv").unlink(missing_ok=True)
    if not (src / "metrics.csv").exists():
        (dest / SUMMARY_JSON).write_text(json.dumps({"training_return_seed_means": None, "kl_share": None}) + "\n")
        return dest
    kept = {"training_return_seed_means": training_seed_means(src), "kl_share": kl_share(src)}
    steps, values = read_curves(src / "metrics.csv")
    # metrics.csv's updates count from 1 without gaps (a resumed run goes on from its checkpoint);
    # each archived row is a bin of them, numbered by its last update
    updates, _ = bin_means(np.arange(1, len(steps) + 1), values)
    steps, values = bin_means(steps, values)
    with (dest / "metrics.csv").open("w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["update", "seed", "env_steps", "episode_return"])
        writer.writerows([updates[i], s, f"{steps[i]:.0f}", f"{values[s, i]:.6g}"]
                         for i in range(len(steps)) for s in range(values.shape[0]))
    (dest / SUMMARY_JSON).write_text(json.dumps(kept, indent=1) + "\n")
    return dest


def archive_runs(runs: Path, run_ids: list[str]) -> list[str]:
    """Archive every run of `run_ids` that finished in `runs` (and the sweeps' records); the
    archived ids."""
    done = [r for r in run_ids if (runs / r / "eval.json").exists()]
    for r in done:
        archive_run(runs, *r.split("/"))
    if (runs / "sweeps.jsonl").exists():
        path = ARCHIVE / runs.name / "sweeps.jsonl"
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text("".join(line + "\n" for line in unique_lines(path, runs / "sweeps.jsonl")))
    return done


def curve_lines(runs: Path, env: str, labels: list[str], out: Path, title: str, kept: tuple[str, ...] = ()) -> list[str]:
    """Plot the learning curves of `labels`' runs (those with a metrics.csv) into `out`; the
    report's markdown lines for it ([] when none has started). While some rows are `kept` (runs
    that predate the archive, with no curve to draw), `out` is their figure and stays; the other
    runs' curves go to a sibling figure, `out`'s name + ARCHIVED_SUFFIX."""
    from hintsjax.training.runlog import plot_curves, read_curves

    paths = {label: metrics_path(runs, env, label) for label in labels}
    curves = {label: read_curves(path) for label, path in paths.items() if path is not None}
    old = [f"![{env} learning curves]({out.name})", "", "(The curves of the runs kept from the previous report.)", ""]
    if not curves:  # a figure of runs that predate the archive stays, said to be theirs
        return old if out.exists() else []
    if kept and out.exists():
        out = out.with_name(out.stem + ARCHIVED_SUFFIX + out.suffix)
        plot_curves(curves, out, f"{title}: runs since the archive")
        return [*old, f"![{env} learning curves of the runs since the archive]({out.name})", ""]
    plot_curves(curves, out, title)
    return [f"![{env} learning curves]({out.name})", ""]


def read_about(folder: Path) -> dict:
    """How a folder's runs were made (commands, hardware, dates, what shared a GPU): its
    about.json, written by whoever ran them; {} when there is none."""
    path = folder / ABOUT_JSON
    return json.loads(path.read_text()) if path.is_file() else {}


def about_lines(about: dict) -> list[str]:
    """A report's closing section from `read_about`'s entries; [] when there are none."""
    return ["## Where these numbers come from", "", *(f"- {k}: {v}" for k, v in about.items()), ""] if about else []


def footer(runs: Path, table: str, run_ids: list[str]) -> str:
    """The report's last line: the sweeps' GPU wall-clock and hardware."""
    return (f"Sweep wall-clock recorded in {runs}/sweeps.jsonl on the GPU: {sweep_seconds(runs, table):.0f} s"
            f" ({sweep_hardware(runs, table, run_ids) or 'none yet'}).")


KEPT = "†"  # marks a row kept from the committed report: its run predates the archive
ARCHIVED_SUFFIX = "_archived"  # curve_lines' figure of the runs beside kept ones


def table_line(cells: list[str]) -> str:
    """One line of a markdown table: `| a | b |`."""
    return "| " + " | ".join(cells) + " |"


def markdown_table(header: list[str], rows: list[list[str]]) -> list[str]:
    """The lines of a markdown table: its header, the rule under it, then one line per row of cells."""
    return [table_line(header), "|" + "---|" * len(header), *map(table_line, rows)]


def table_rows(text: str):
    """(section heading, row label without KEPT, its cells) of every row of a report's markdown
    tables, header rows included."""
    section = ""
    for line in text.splitlines():
        if line.startswith("## "):
            section = line[3:].split(" (")[0]
        elif line.startswith("| ") and not line.startswith("|---"):
            label, *cells = [part.strip() for part in line.strip().strip("|").split("|")]
            yield section, label.removesuffix(KEPT).strip(), cells


def kept_rows(path: Path) -> dict[tuple[str, str], list[str]]:
    """The table rows (label, then cells) of the committed report at `path`, by (section heading,
    agent label), each with its label marked KEPT. A report keeps the row of a run that is neither
    in runs/ nor in the archive (one trained before the archive existed, whose run folder was lost)
    instead of blanking it."""
    text = path.read_text() if path.exists() else ""
    return {(section, label): [f"{label} {KEPT}", *cells]
            for section, label, cells in table_rows(text) if label != "agent" and cells[0] != "-"}


def cell_stats(text: str) -> tuple[float, float] | None:
    """(mean, std of the per-seed means) of a 'mean ± std (seed std)' cell; None for '-'."""
    if text.strip() == "-":
        return None
    mean, rest = text.split("±")
    return float(mean), float(rest.split("(")[1].rstrip(") "))


def apart_text(a: tuple[float, float], b: tuple[float, float]) -> str:
    """Whether two agents' means differ by more than their seed stds together."""
    return "beyond" if abs(a[0] - b[0]) > a[1] + b[1] else "within"


def table_cells(text: str) -> dict[tuple[str, str, int], str]:
    """Every cell of a report's markdown tables, by (section heading, row label, column)."""
    return {(section, label, i): c for section, label, cells in table_rows(text) for i, c in enumerate(cells, 1)}


def lost_cells(old: str, new: str) -> list[str]:
    """'section/label' of every row with a cell that the report `old` filled and `new` leaves '-'."""
    after = table_cells(new)
    return list(dict.fromkeys(f"{section}/{label}" for (section, label, i), c in table_cells(old).items()
                              if c != "-" and after.get((section, label, i), "-") == "-"))


def refuse_lost_cells(path: Path, lines: list[str]) -> None:
    """Exit 2, naming them, if the report `lines` would blank cells that the committed report at
    `path` fills: their runs are neither in runs/ nor in the archive (e.g. a checkout whose runs
    were lost). --force skips this check."""
    if path.exists() and (lost := lost_cells(path.read_text(), "\n".join(lines))):
        sys.stderr.write(f"error: {path.name} not rewritten: it would blank {len(lost)} rows whose runs are in neither "
                         f"--runs nor {ARCHIVE} ({', '.join(lost[:5])}{', ...' if len(lost) > 5 else ''}); "
                         "--force rewrites it anyway\n")
        raise SystemExit(2)


GENERATED_OPENING = "<!-- generated by "  # how every generated section's marker line begins


def generated_marker(script: str) -> str:
    """The line that opens `script`'s generated section of a report that several scripts share."""
    return f"{GENERATED_OPENING}experiments/{script} --learners-report, down to the next such line -->"


def write_section(path: Path, marker: str, lines: list[str]) -> None:
    """Write `lines` as the section of `path` that `marker` opens, from the marker down to the
    next generated marker (or the end); the text above it and the other scripts' sections stay.
    A file without the marker gets the section at its end."""
    text = path.read_text() if path.exists() else ""
    before, after = text, ""
    if marker in text:
        start = text.index(marker)
        end = text.find("\n" + GENERATED_OPENING, start + len(marker))
        before, after = text[:start], "" if end < 0 else text[end + 1:]
    while lines and not lines[-1]:  # one blank line between sections, none at the end
        lines = lines[:-1]
    rest = ["", *after.rstrip("\n").splitlines()] if after else []
    write_report(path, [*before.rstrip("\n").splitlines(), "", marker, "", *lines, *rest], force=True)


def write_report(path: Path, lines: list[str], force: bool = False) -> None:
    """Write a report (refused as `refuse_lost_cells` says unless `force`) and print it."""
    if not force:
        refuse_lost_cells(path, lines)
    path.parent.mkdir(exist_ok=True)
    path.write_text("\n".join(lines) + "\n")
    print(path.read_text())


def sweep_hardware(runs: Path, table: str, run_ids: list[str]) -> str:
    """'NVIDIA H200; 6 runs at once over 2 GPUs' for the GPU sweeps of `table` (from sweeps.jsonl
    and the runs' eval.json), or '' when none ran on a GPU."""
    records = sweep_records(runs, table)
    results = [result for r in run_ids if (result := load(runs, *r.split("/")))]
    devices = sorted({result.get("device", "") for result in results} - {"", "cpu", "Cpu"})
    if not records or not devices:
        return ""
    setups = sorted({("1 run at a time" if r["workers"] == 1 else f"{r['workers']} runs at once")
                     + (f" over {len(r['gpus'])} GPUs" if len(r.get("gpus", ())) > 1 else " on one GPU") for r in records})
    # Runs recorded before this key existed ran with deterministic GPU ops (hintsjax's default).
    fast = [result for result in results if result.get("deterministic", True) is False]
    return f"{', '.join(devices)}; {'; '.join(setups)}" + (f"; deterministic GPU ops off ({len(fast)} runs)" if fast else "")
