"""A table row trained in parts of its seeds, pooled into one archived run of all of them.

A row too long for one machine's lease trains in parts: each part a `--set seed=K` sweep into a
--runs folder of its own (seeds 0-9 in runs/car20_s0, `--set seed=10` seeds 10-19 in
runs/car20_s10; seed i of a run is key(seed + i), config.RunConfig.seed_keys, so the parts are
the whole row's seeds). `pool_runs` archives each part's finished runs (archive.py) and writes,
for every run finished in all the parts, one archived run of their seeds into the archive of
another --runs folder, as `archive_run` would have kept the whole row: eval.json (each
evaluation's statistics worked out again over all the seeds, from the episodes' returns),
config.yaml (`seed` the first part's, `seeds` the sum), the binned metrics.csv with each part's
seeds numbered after the parts before it, and summary.json. Every report then reads it as a row
trained whole. The parts' other settings must be the same (as a run reads them, defaults
filled in) and their seeds must follow on without gap or overlap; a pooled eval.json lists its
parts (folder, seeds, device, seconds), its `train_seconds` and `wall_seconds` the parts' sums,
its `device` theirs joined by " + ", its per-seed lists (`kl_storms`) theirs in seed order.
"""

from __future__ import annotations

import csv
import io
import json
import os
import shutil
import tempfile
from pathlib import Path

import numpy as np
import yaml

from hintsjax.evaluation.evaluator import return_summary
from hintsjax.reproduce import archive
from hintsjax.reproduce.archive import SUMMARY_JSON, archive_runs, unique_lines
from hintsjax.settings import layers
from hintsjax.settings.layers import CONFIG_YAML
from hintsjax.system.errors import UsageError, described

SUMMED = ("train_seconds", "wall_seconds")  # an eval.json's seconds: the parts' total
PER_PART = (
    "train_seconds_this_call",
    "compile_seconds",
    "trace_seconds",
    "traced_programs_loaded",
    "train_env_steps_per_s",
    "chunks_env_steps_per_s",
    "wall_split_seconds",
    "device",
    "devices",
    "parts",
    # each part's own: in "parts" (group_*: a run trained in a group)
    "group_dir",
    "group_env_steps_per_s",
)
# an eval.json's lists of one entry a seed: the parts' joined in seed order
PER_SEED = ("kl_storms",)
POOLED_EVAL = (
    "mean",
    "std",
    "seed_means",
    "seed_std",
    "outlier_seeds",
    "seeds",
    "mean_length",
    "returns",
)


class PoolError(ValueError):
    """Parts that cannot be one row (another setting, seeds that overlap or leave a gap, other
    evaluations or curves) or no parts at all. The message is the one line a command prints."""


def pool_runs(parts: list[Path], into: Path, run_ids: list[str]) -> list[str]:
    """Archive the parts' finished runs, then pool each run of `run_ids` finished in every part into
    ARCHIVE/<into's name>/env/label; the parts' sweeps.jsonl go to its sweeps.jsonl. Returns the
    pooled ids. Everything is checked first, on the parts archived into a folder of their own:
    parts that cannot be pooled (PoolError) leave the archive as it was."""
    kept = archive.ARCHIVE
    names = [p.name for p in parts]
    if len(parts) < 2 or len(set(names)) < len(names) or into.name in names:
        raise PoolError(
            f"give two or more parts with other folder names than --runs ({into.name}); got "
            f"{', '.join(names) or 'none'}"
        )
    missing = [part for part in parts if not part.is_dir() and not (kept / part.name).is_dir()]
    if missing:
        raise PoolError(
            f"no runs folder at {missing[0]} and no archived one at {kept / missing[0].name}"
        )
    with tempfile.TemporaryDirectory(prefix="hintsjax-pool-") as staging:
        stage = Path(staging)
        try:
            files = _checked(parts, into, run_ids, stage)
        except PoolError as e:  # named by the parts' own folders, not the staging one
            text = str(e)
            for part in sorted(parts, key=lambda p: -len(p.name)):
                text = text.replace(f"{stage / part.name}{os.sep}", f"{_source(part)}{os.sep}")
            raise PoolError(text) from None
    for part in parts:  # all checked: now into the archive
        archive_runs(part, run_ids)
    for run, contents in files.items():
        dest = kept / into.name / run
        dest.mkdir(parents=True, exist_ok=True)
        # the archive mirrors the pooled run as it stands
        (dest / "metrics.csv").unlink(missing_ok=True)
        for name, text in contents.items():
            (dest / name).write_text(text)
    records = unique_lines(
        *(kept / p.name / "sweeps.jsonl" for p in parts), kept / into.name / "sweeps.jsonl"
    )
    if files and records:
        (kept / into.name / "sweeps.jsonl").write_text("".join(line + "\n" for line in records))
    return list(files)


def _source(part: Path) -> Path:
    """Where a part's runs are read from: its runs folder, else its archived copy."""
    return part if part.is_dir() else archive.ARCHIVE / part.name


def _checked(parts: list[Path], into: Path, run_ids: list[str], stage: Path) -> dict:
    """The pooled runs' files by run id, worked out on the parts as they would stand archived
    (their archived copies, with their runs here archived over them, in `stage`); PoolError
    naming the first part that cannot be pooled."""
    kept = archive.ARCHIVE
    for part in parts:
        if (kept / part.name).is_dir():
            shutil.copytree(kept / part.name, stage / part.name)
        if part.is_dir():
            try:
                archive_runs(part, run_ids, into=stage)
            except UsageError as e:  # a damaged run, named
                raise PoolError(str(e)) from None
    pooled = [r for r in run_ids if all((stage / p.name / r / "eval.json").exists() for p in parts)]
    shadowed = [r for r in pooled if (into / r / "eval.json").exists()]
    if shadowed:
        raise PoolError(
            f"{into / shadowed[0]} finished there, and the reports would read it rather than the "
            "pooled run: give --runs another folder"
        )
    files = {}
    for run in pooled:
        folders = [stage / p.name / run for p in parts]
        try:
            files[run] = pool_run(folders)
        except PoolError:
            raise
        except (*archive.DAMAGED, ZeroDivisionError) as e:
            shown = ", ".join(map(str, folders))
            why = described(e)
            raise PoolError(f"the parts of {run} ({shown}) cannot be pooled: {why}") from None
    return files


def _read(path: Path, parse) -> dict:
    """A part's file read as a mapping by `parse` (json.loads, yaml.safe_load); PoolError naming
    it when it is missing, unreadable or not a mapping."""
    try:
        value = parse(path.read_text())
    except (*archive.DAMAGED, yaml.YAMLError) as e:
        raise PoolError(f"{path} cannot be read: {described(e)}") from None
    if not isinstance(value, dict):
        raise PoolError(f"{path} is not a mapping: {type(value).__name__}")
    return value


def pool_run(folders: list[Path]) -> dict[str, str]:
    """The archived runs `folders` (parts of one row's seeds, in any order) pooled: the files of the
    pooled run's archive folder, by name."""
    configs = [_read(f / CONFIG_YAML, yaml.safe_load) for f in folders]
    for folder, cfg in zip(folders, configs):
        seed, seeds = cfg.get("seed"), cfg.get("seeds")
        if not (type(seed) is int and type(seeds) is int and seed >= 0 and seeds >= 1):
            raise PoolError(
                f"{folder / CONFIG_YAML} names no seeds to pool (seed {seed!r}, seeds {seeds!r})"
            )
    order = sorted(range(len(folders)), key=lambda i: configs[i]["seed"])
    folders, configs = [folders[i] for i in order], [configs[i] for i in order]
    first = configs[0]
    # compared as a run reads them: a part saved before a setting existed has its default
    settings = [_settings(f) for f in folders]
    for folder, cfg in zip(folders[1:], settings[1:]):
        other = sorted(
            k
            for k in set(cfg) | set(settings[0])
            if k not in ("seed", "seeds") and cfg.get(k) != settings[0].get(k)
        )
        if other:
            raise PoolError(
                f"{folder} was trained with other settings than {folders[0]}: {', '.join(other)}"
            )
    for (a, ca), (b, cb) in zip(zip(folders, configs), zip(folders[1:], configs[1:])):
        if ca["seed"] + ca["seeds"] != cb["seed"]:
            raise PoolError(
                f"the seeds of {a} ({ca['seed']} to {ca['seed'] + ca['seeds'] - 1}) and of {b} "
                f"({cb['seed']} to {cb['seed'] + cb['seeds'] - 1}) do not follow on"
            )
    seeds = [c["seeds"] for c in configs]
    results = [_read(f / "eval.json", json.loads) for f in folders]
    for folder, result in zip(folders, results):
        if not isinstance(result.get("evaluations"), list) or not result["evaluations"]:
            raise PoolError(f"{folder / 'eval.json'} holds no evaluations")
    files = {
        CONFIG_YAML: yaml.safe_dump({**first, "seeds": sum(seeds)}, sort_keys=False),
        "eval.json": json.dumps(pooled_eval(results, folders, configs), indent=1) + "\n",
        SUMMARY_JSON: json.dumps(
            pooled_summary([f / SUMMARY_JSON for f in folders], seeds), indent=1
        )
        + "\n",
    }
    metrics = [f / "metrics.csv" for f in folders]
    if any(m.exists() for m in metrics):
        files["metrics.csv"] = pooled_metrics(metrics, seeds)
    return files


def _settings(folder: Path) -> dict:
    """A part's settings as a run reads them (layers.load_run_config): its config.yaml, with the
    defaults of settings added since it was saved; PoolError where they cannot be read."""
    try:
        return layers.to_dict(layers.load_run_config(folder))
    except UsageError as e:
        raise PoolError(f"{folder / CONFIG_YAML}: {e}") from None


def pooled_eval(results: list[dict], folders: list[Path], configs: list[dict]) -> dict:
    """One eval.json of the parts' results (in seed order)."""
    first = results[0]
    shared = {
        k: v for k, v in first.items() if k not in (*SUMMED, *PER_PART, *PER_SEED, "evaluations")
    }
    for folder, result in zip(folders[1:], results[1:]):
        other = [k for k in shared if result.get(k) != shared[k]]
        if other or len(result["evaluations"]) != len(first["evaluations"]):
            raise PoolError(
                f"{folder}'s eval.json differs from {folders[0]}'s: "
                f"{', '.join(other) or 'the evaluations'}"
            )
    parts = [
        {
            "folder": f"{f.parent.parent.name}/{f.parent.name}/{f.name}",
            "seed": c["seed"],
            "seeds": c["seeds"],
            **{k: r[k] for k in (*SUMMED, *PER_PART) if k in r},
        }
        for f, c, r in zip(folders, configs, results)
    ]
    devices = list(dict.fromkeys(r["device"] for r in results if "device" in r))
    return {
        **shared,
        **{k: sum(r[k] for r in results) for k in SUMMED if all(k in r for r in results)},
        **({"device": " + ".join(devices)} if devices else {}),
        **{k: joined([r.get(k) for r in results]) for k in PER_SEED if k in first},
        "evaluations": [
            pooled_evaluation([r["evaluations"][i] for r in results])
            for i in range(len(first["evaluations"]))
        ],
        "parts": parts,
    }


def joined(lists: list[list | None]) -> list | None:
    """The parts' per-seed lists as one, in seed order; None when a part has none (None)."""
    return None if any(x is None for x in lists) else [x for part in lists for x in part]


def pooled_evaluation(parts: list[dict]) -> dict:
    """One evaluation (evaluator.summarize's keys) over the seeds of `parts`: the returns'
    statistics from the episodes' returns, each env metric's mean and std over all episodes from the
    parts' (population) means and stds, its seed means in seed order."""
    first = parts[0]
    fixed = {
        k: v
        for k, v in first.items()
        if k not in POOLED_EVAL and not k.endswith(("_mean", "_std", "_seed_means"))
    }
    for part in parts[1:]:
        if any(part.get(k) != v for k, v in fixed.items()):
            raise PoolError(
                f"evaluations of other kinds cannot be pooled: {first.get('variant')} against "
                f"{part.get('variant')}"
            )
    returns = np.concatenate([np.asarray(p["returns"], np.float64) for p in parts])
    seeds = np.array([p["seeds"] for p in parts])
    out = {
        **fixed,
        **return_summary(returns),
        "mean_length": float(np.average([p["mean_length"] for p in parts], weights=seeds)),
    }
    for name in (k[: -len("_seed_means")] for k in first if k.endswith("_seed_means")):
        means, stds = (np.array([p[f"{name}_{s}"] for p in parts]) for s in ("mean", "std"))
        mean = float(np.average(means, weights=seeds))
        out.update(
            {
                f"{name}_mean": mean,
                f"{name}_std": float(
                    np.sqrt(max(np.average(stds**2 + means**2, weights=seeds) - mean**2, 0.0))
                ),
                f"{name}_seed_means": [m for p in parts for m in p[f"{name}_seed_means"]],
            }
        )
    return {**out, "returns": returns.tolist()}


def pooled_metrics(paths: list[Path], seeds: list[int]) -> str:
    """The parts' binned metrics.csv as one: the same bins (update, env_steps) in each, every part's
    seeds numbered after the seeds of the parts before it."""
    tables = []
    for path in paths:
        if not path.exists():
            raise PoolError(
                f"{path} is missing: {paths[0].parent} has a learning curve, {path.parent} none"
            )
        with path.open(newline="") as f:
            tables.append(list(csv.reader(f)))
    header = tables[0][0]
    bins = [[(row[0], row[2]) for row in table[1:]] for table in tables]
    for path, table, b, n in zip(paths, tables, bins, seeds):
        if (
            table[0] != header
            or header[:3] != ["update", "seed", "env_steps"]
            or b[::n] != bins[0][:: seeds[0]]
        ):
            raise PoolError(f"{path} does not have {paths[0]}'s columns and updates")
    rows, offset = {}, 0
    for table, n in zip(tables, seeds):
        for row in table[1:]:
            rows.setdefault((row[0], row[2]), []).append(
                [row[0], str(int(row[1]) + offset), *row[2:]]
            )
        offset += n
    out = io.StringIO(newline="")
    writer = csv.writer(out)
    writer.writerow(header)
    writer.writerows(row for b in dict.fromkeys(bins[0]) for row in rows[b])
    return out.getvalue()


def pooled_summary(paths: list[Path], seeds: list[int]) -> dict:
    """The parts' summary.json as one: per-seed lists joined in seed order, the KL share (of the
    seeds' updates) weighted by the parts' seeds; a value one part lacks (None) is None."""
    kept = [_read(p, json.loads) for p in paths]
    tails = [k["training_return_seed_means"] for k in kept]
    shares = [k["kl_share"] for k in kept]
    return {
        "training_return_seed_means": joined(tails),
        "kl_share": None if None in shares else float(np.average(shares, weights=seeds)),
        "kl_storms": joined([k.get("kl_storms") for k in kept]),
    }
