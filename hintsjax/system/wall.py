"""Where a run's wall-clock went: `Laps` marks the stages of `pipeline.train` (eval.json's
`wall_split_seconds`), and `process_age` is how long the process had run before the first mark
(the interpreter, the imports, the config; in a process that trains several runs, a sweep
worker's, the runs before too), read from Linux's /proc.
"""

from __future__ import annotations

import os
import time
from pathlib import Path


def process_age() -> float | None:
    """Seconds since this process started (Linux: /proc/self/stat's start time against the
    boot clock); None where that cannot be read."""
    try:
        fields = Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()
        started = int(fields[19]) / os.sysconf("SC_CLK_TCK")  # field 22, after pid and (comm)
        return max(0.0, time.clock_gettime(time.CLOCK_BOOTTIME) - started)
    except (OSError, ValueError, IndexError, AttributeError):
        return None


class Laps:
    """Seconds between marks, named by the stage each ends: `mark("training")` records the time
    since the previous mark (or since the Laps began) as "training"."""

    def __init__(self) -> None:
        self.seconds: dict[str, float | None] = {"startup": process_age()}
        self._last = time.perf_counter()

    def mark(self, stage: str) -> None:
        now = time.perf_counter()
        self.seconds[stage] = now - self._last
        self._last = now
