"""A run's written record: metrics as CSV and TensorBoard events, and the learning-curve PNG."""

from __future__ import annotations

import csv
import sys
import warnings
from collections import Counter
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from hintsjax.system import paths
from hintsjax.system.errors import UsageError

METRICS_CSV = "metrics.csv"
CURVE_PNG = "learning_curve.png"
CURVE_POINTS = 250  # points per seed of a plotted (and an archived) learning curve
KL_ABOVE = 0.5  # an update whose approx. KL from its rollout policy exceeds this blew up
STORM_UPDATES = 10  # a KL storm: this many updates in a row that blew up


def fresh_folder(base: Path) -> Path:
    """A new folder at `base`, or at `base-1`, `base-2`, ... if taken; never an existing one, also
    when processes started at once (a sweep's jobs) ask for the same name."""
    folder, i = Path(base), 1
    while True:
        try:
            # atomic: of two processes making it, one gets FileExistsError
            folder.mkdir(parents=True)
            return folder
        except FileExistsError:
            folder, i = Path(base).with_name(f"{Path(base).name}-{i}"), i + 1


def _complete(row: dict[str, str | None]) -> bool:
    """Whether a metrics row was written whole: every column there, each a number, the update a
    whole one (a row cut off mid-write lacks columns or ends in part of a number)."""
    try:
        values = [float(v) for v in row.values()]
        return None not in row and float(row["update"]).is_integer() and bool(values)
    except (TypeError, ValueError):
        return False


def _cut_short(row: dict[str, str | None]) -> bool:
    """Whether a metrics row is the start of one (a stop as it was appended): its columns run out
    early, and those there are numbers (the last perhaps a part of one)."""
    present = [v for k, v in row.items() if k is not None and v is not None]
    try:
        [float(v) for v in present if v != ""]
    except ValueError:
        return False
    return None not in row and len(present) < len(row)


def _spans(numbers: list[int]) -> str:
    """1, 2, 3, 7 -> '1-3, 7'."""
    spans, start = [], numbers[0]
    for prev, n in zip(numbers, [*numbers[1:], None]):
        if n != prev + 1 if n is not None else True:
            spans.append(f"{start}-{prev}" if prev > start else f"{start}")
            start = n
    return ", ".join(spans)


class RunLog:
    """Appends per-update, per-seed metric rows to metrics.csv and means to TensorBoard."""

    def __init__(self, run_dir: Path, resume_update: int = 0):
        # here: it loads protobuf (0.4 s), which only a run that logs needs
        from tensorboardX import SummaryWriter

        self.path = Path(run_dir) / METRICS_CSV
        self.columns: list[str] | None = None
        # a resumed run, or one started again in its folder (a requeued job's, at 0)
        if self.path.exists():
            self._truncate(resume_update)
        self.tb = SummaryWriter(str(Path(run_dir) / "tb"))

    def _rows(self) -> list[dict[str, str]]:
        with self.path.open() as f:
            return list(csv.DictReader(f))

    def _rewrite(self, rows: Iterable[dict[str, str]]) -> None:
        """The file anew with `self.columns` and `rows` (NaN in a column a row lacks), whole or not
        at all (paths.write_whole)."""
        rows = list(rows)

        def write(part: Path) -> None:
            with part.open("w", newline="") as f:
                writer = csv.DictWriter(f, self.columns, restval="nan")
                writer.writeheader()
                writer.writerows(rows)

        paths.write_whole(self.path, write)

    def _truncate(self, update: int) -> None:
        """Keep the rows of the `update` updates the resumed checkpoint holds: rows written after
        it go, and so does a last row cut off as it was written (a stop mid-append), with one line
        naming the updates the file lacks, if any (its curve goes on without them); an empty
        file starts anew. UsageError, the file left as it is, if it is not a metrics.csv this
        package wrote (no `update` column, or a row whose update is not a whole number)."""
        try:
            with self.path.open(newline="") as f:
                reader = csv.DictReader(f)
                rows, columns = list(reader), reader.fieldnames
            if columns is None:  # empty: nothing was logged, or nothing survived
                self.path.unlink()
                self._say_missing(range(1, update + 1))
                return
            if "update" not in columns:
                raise KeyError("update")
            if rows and _cut_short(rows[-1]):  # cut off as it was appended
                rows = rows[:-1]
            kept = [r for r in rows if int(r["update"]) <= update]
            if not all(_complete(r) for r in kept):
                raise ValueError("a row that is not numbers")
            seeds = {r["seed"] for r in kept}  # an update is logged when each seed has its row
        except (KeyError, TypeError, ValueError, UnicodeDecodeError, csv.Error) as e:
            raise UsageError(
                f"{self.path} is not a metrics file of this run ({type(e).__name__}); "
                "move it away to resume (the run's checkpoints are intact)"
            ) from None
        self.columns = list(columns)
        rows_of = Counter(int(r["update"]) for r in kept)
        self._say_missing([u for u in range(1, update + 1) if rows_of[u] < max(len(seeds), 1)])
        self._rewrite(kept)

    def _say_missing(self, updates: Iterable[int]) -> None:
        updates = list(updates)
        if updates:
            print(
                f"warning: {self.path} lacks the rows of updates {_spans(updates)} (lost from the "
                "file); the run goes on from its checkpoint, its curve without them",
                file=sys.stderr,
            )

    def _widen(self, names: list[str]) -> None:
        """Add columns for metrics that a resumed run's file predates (a metric added to the code
        since it began): its earlier rows get NaN there."""
        rows = self._rows()
        self.columns = [*self.columns, *names]
        self._rewrite(rows)

    def write(self, metrics: dict[str, np.ndarray], first_update: int) -> None:
        """metrics: name -> [S, n] for n updates starting after `first_update` updates."""
        names = sorted(metrics)
        seeds, n = np.asarray(metrics[names[0]]).shape
        new = not self.path.exists()
        if self.columns is None:
            self.columns = ["update", "seed", *names]
        elif missing := [k for k in names if k not in self.columns]:
            self._widen(missing)
        with self.path.open("a", newline="") as f:
            # NaN in a column of the file that this code no longer logs
            writer = csv.DictWriter(f, self.columns, restval="nan")
            if new:
                writer.writeheader()
            for i in range(n):
                for s in range(seeds):
                    writer.writerow(
                        {
                            "update": first_update + i + 1,
                            "seed": s,
                            **{k: float(metrics[k][s, i]) for k in names},
                        }
                    )
        for i in range(n):
            step = int(np.asarray(metrics["env_steps"])[0, i])
            for k in names:
                column = np.asarray(metrics[k])[:, i]
                if not np.all(np.isnan(column)):
                    self.tb.add_scalar(f"train/{k}", float(np.nanmean(column)), step)
        self.tb.flush()

    def close(self) -> None:
        self.tb.close()


@dataclass(frozen=True)
class Log:
    """A metrics.csv read once: its updates and env steps [U], and each logged column [S, U] as
    logged (NaN where a seed has no row)."""

    updates: np.ndarray
    steps: np.ndarray
    columns: dict[str, np.ndarray]


def read_log(path: Path, names: Iterable[str] | None = None) -> Log:
    """A metrics.csv's `names` columns (all but update, seed and env_steps when None), one pass; a
    name the file does not log is left out of `columns`."""
    with Path(path).open() as f:
        reader = csv.DictReader(f)
        fields = reader.fieldnames or ()
        rows = list(reader)
    names = (
        [c for c in fields if c not in ("update", "seed", "env_steps")]
        if names is None
        else [c for c in names if c in fields]
    )
    updates = sorted({int(r["update"]) for r in rows})
    seeds = sorted({int(r["seed"]) for r in rows})
    index = {u: i for i, u in enumerate(updates)}
    steps = np.zeros(len(updates))
    columns = {c: np.full((len(seeds), len(updates)), np.nan) for c in names}
    for r in rows:
        i, seed = index[int(r["update"])], int(r["seed"])
        steps[i] = float(r["env_steps"])
        for c in names:
            columns[c][seed, i] = float(r[c])
    return Log(np.asarray(updates), steps, columns)


def carried(values: np.ndarray) -> np.ndarray:
    """[S, U] -> a copy with each seed's NaNs carried forward from its last value."""
    values = np.array(values)
    for s in range(values.shape[0]):
        for i in range(1, values.shape[1]):
            if np.isnan(values[s, i]):
                values[s, i] = values[s, i - 1]
    return values


def read_curves(path: Path, metric: str = "episode_return") -> tuple[np.ndarray, np.ndarray]:
    """(env_steps [U], values [S, U]) from a metrics.csv, NaNs carried forward per seed."""
    log = read_log(path, (metric,))
    return log.steps, carried(log.columns[metric])


def kl_storms(path: Path) -> list[dict] | None:
    """Per seed of a metrics.csv, its KL storms (`storms_of`); None without the file or an
    approx_kl column (not PPO)."""
    try:
        return storms_of(read_log(path, ("approx_kl",)))
    except OSError:
        return None


def storms_of(log: Log) -> list[dict] | None:
    """Per seed, its KL storms (STORM_UPDATES or more updates in a row whose approx. KL exceeds
    KL_ABOVE): {"first": the update the first one starts at, or None, "longest": the longest run
    of such updates}; None for a log with no approx_kl column (not PPO)."""
    if "approx_kl" not in log.columns:
        return None
    storms = []
    # each seed's updates as logged; inf blew up too, NaN did not
    for above in log.columns["approx_kl"] > KL_ABOVE:
        run, longest, first = 0, 0, None
        for update, hot in enumerate(above, start=1):
            run = run + 1 if hot else 0
            longest = max(longest, run)
            if run == STORM_UPDATES and first is None:
                first = update - STORM_UPDATES + 1
        storms.append({"first": first, "longest": longest})
    return storms


def storms_text(seeds: list[int], storms: list[dict] | None) -> str:
    """'KL storm (seed 1 from update 4548 on: ...)' for the seeds of `seeds` (a run's collapsed
    ones) that had one (`storms`: `kl_storms` of the run); '' for none. What a collapsed seed's
    training did: its PPO updates blew up, which is PPO's doing, not the physics'
    (experiments/results/locomotion_ppo_stability.md)."""
    hit = [
        (s, storms[s]["first"])
        for s in seeds
        if storms and s < len(storms) and storms[s]["first"] is not None
    ]
    if not hit:
        return ""
    which = ", ".join(f"seed {s} from update {u}" for s, u in hit)
    return (
        f"KL storm ({which} on: approx. KL above {KL_ABOVE:g} for {STORM_UPDATES} or more updates "
        "in a row): "
        "PPO's steps blew up"
    )


def bin_means(
    steps: np.ndarray, values: np.ndarray, points: int = CURVE_POINTS
) -> tuple[np.ndarray, np.ndarray]:
    """A curve averaged over at most `points` runs of consecutive updates: (the env steps of each
    bin's last update [B], each seed's mean over the bin [S, B]). NaNs are left out of the means;
    a bin of NaNs stays NaN. With `points` or fewer updates the curve comes back as it was."""
    edges = np.linspace(0, len(steps), min(points, len(steps)) + 1).round().astype(int)
    seen = ~np.isnan(values)
    sums = np.add.reduceat(np.where(seen, values, 0.0), edges[:-1], axis=1)
    counts = np.add.reduceat(seen, edges[:-1], axis=1)
    return steps[edges[1:] - 1], np.where(counts > 0, sums / np.maximum(counts, 1), np.nan)


def mean_confidence_band(
    values: np.ndarray, level: float = 0.95, resamples: int = 1000, seed: int = 0
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean, low, high) over seeds (axis 0) per column, with a percentile-bootstrap confidence
    band for the mean (seeds resampled with replacement). NaN seeds are ignored per column."""
    rng = np.random.default_rng(seed)
    picks = rng.integers(0, values.shape[0], (resamples, values.shape[0]))
    with warnings.catch_warnings():  # columns before any episode ended are all-NaN
        warnings.simplefilter("ignore", RuntimeWarning)
        means = np.nanmean(values[picks], axis=1)  # [resamples, U]
        tail = 100 * (1 - level) / 2
        low, high = np.nanpercentile(means, [tail, 100 - tail], axis=0)
        return np.nanmean(values, axis=0), low, high


def plot_curves(
    curves: dict[str, tuple[np.ndarray, np.ndarray]], out: Path, title: str = ""
) -> None:
    """One line per label (mean over seeds) with a 95% bootstrap confidence band for the mean;
    x is environment steps. Long curves are first averaged into CURVE_POINTS bins (`bin_means`):
    per-update returns of runs with few, long episodes are too noisy to read."""
    # here: matplotlib takes about a second to import, and only a finished run draws
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(8.5, 4), dpi=120)
    for label, curve in curves.items():
        steps, values = bin_means(*curve)
        mean, low, high = mean_confidence_band(values)
        ax.plot(steps, mean, label=f"{label} (n={values.shape[0]})")
        ax.fill_between(steps, low, high, alpha=0.2)
    ax.set_xlabel("environment steps")
    ax.set_ylabel("training episode return (mean, 95% CI)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    # beside the axes, off the curves
    ax.legend(fontsize=7, loc="center left", bbox_to_anchor=(1.01, 0.5))
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
