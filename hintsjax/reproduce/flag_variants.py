"""One measurement per XLA flag variant, each in a fresh process (XLA reads XLA_FLAGS once, at
start-up): what profile_update.py and compile_time.py share. The script runs itself as the child
with `--variant NAME` and prints its result through `report`; the parent reads it back."""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import subprocess
import sys
from typing import Any

PREFIX = "RESULT "


def chosen(parser: argparse.ArgumentParser, names: str, valid: dict[str, Any]) -> list[str]:
    """The comma-separated variant names, or exit 2 naming the valid ones."""
    chosen = [v for v in names.split(",") if v]
    unknown = [v for v in chosen if v not in valid]
    if unknown:
        parser.exit(2, f"error: unknown variant(s) {unknown}; valid: {', '.join(valid)}\n")
    return chosen


def params_digest(params: Any) -> str:
    """A digest of every array in `params`: equal digests from two processes (two variants, or one
    variant twice) mean the same numbers."""
    import numpy as np
    from jax import tree

    return hashlib.sha256(
        b"".join(np.asarray(x).tobytes() for x in tree.leaves(params))
    ).hexdigest()[:16]


def report(result: dict) -> None:
    """The child's result, on the line the parent reads."""
    print(PREFIX + json.dumps(result), flush=True)


def run(script: str, flags: str, argv: list[str]) -> dict | None:
    """Run `python script *argv` with `flags` appended to XLA_FLAGS; its reported result, or None
    (its error's tail printed) if it reported none."""
    env = {**os.environ, "XLA_FLAGS": (os.environ.get("XLA_FLAGS", "") + " " + flags).strip()}
    out = subprocess.run([sys.executable, script, *argv], env=env, capture_output=True, text=True)
    lines = [line for line in out.stdout.splitlines() if line.startswith(PREFIX)]
    if not lines:
        print(f"{' '.join(argv)}: failed\n{out.stderr[-3000:]}", flush=True)
        return None
    return json.loads(lines[-1][len(PREFIX) :])
