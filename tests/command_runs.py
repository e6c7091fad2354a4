"""Many `python -m <module> <args>` runs for the price of one interpreter start. Used by
tests/test_cli.py and tests/test_console.py through `outcomes`.

    python tests/command_runs.py <module> '<cases as JSON>' [<module the command runs in turn>...]

Each case is {"args": [...], "cwd": folder, "out": file, "err": file}. This process imports
<module> once (what costs a fresh `python -m` about 7 s on a CPU: jax, mujoco, orbax, hydra),
and the modules it runs in turn (the console script's subcommands) with their imports,
then for each case forks a child that goes into `cwd`, points its stdout and stderr (file
descriptors 1 and 2) at `out` and `err`, and runs the module as `python -m` does
(runpy, as `__main__`, with sys.argv[1:] = args): its exit status is what `python -m` gives
(SystemExit's code; 1 and the traceback on stderr for an uncaught exception), its atexit
functions run as they would at its end. Each case thus starts from the state of a freshly imported
module, never from another case's. This process prints one JSON list of the exit statuses on stdout
and nothing on stderr itself: anything that importing the module prints (which a real `python -m`
would print in every case) shows on its stderr, which the test checks is empty.
"""

from __future__ import annotations

import atexit
import importlib
import json
import os
import runpy
import subprocess
import sys
import traceback
from pathlib import Path


def outcomes(
    module: str,
    cases: list[list[str]],
    root: Path,
    runs: tuple[str, ...] = (),
    cwd: Path | None = None,
) -> list[tuple[int, str, str, Path]]:
    """`python -m module *args` for each args of `cases`, through one start of this script: each
    case's (exit status, stdout, stderr, the folder it ran in: `cwd`, or an empty folder of its own
    under `root`). Fails unless the start itself printed nothing on stderr."""
    jobs = []
    for k, args in enumerate(cases):
        folder = cwd or root / f"case{k}"
        folder.mkdir(exist_ok=True)
        jobs.append(
            {
                "args": args,
                "cwd": str(folder),
                "out": str(root / f"case{k}.out"),
                "err": str(root / f"case{k}.err"),
            }
        )
    out = subprocess.run(
        [sys.executable, __file__, module, json.dumps(jobs), *runs],
        cwd=root,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == 0 and out.stderr == "", out.stderr[-3000:]
    statuses = json.loads(out.stdout)
    return [
        (status, Path(job["out"]).read_text(), Path(job["err"]).read_text(), Path(job["cwd"]))
        for status, job in zip(statuses, jobs, strict=True)
    ]


def said(stderr: str) -> list[str]:
    """What a command printed on stderr beside its progress bar: the non-empty lines without
    tqdm's rate (either way up: "s/upd" below one update a second, under load)."""
    return [
        line
        for line in stderr.replace("\r", "\n").splitlines()
        if line.strip() and "upd/s" not in line and "s/upd" not in line
    ]


def run_case(module: str, case: dict) -> None:
    """In the forked child: one `python -m module *args`; never returns."""
    code = 1
    try:
        os.chdir(case["cwd"])
        for fd, path in ((1, case["out"]), (2, case["err"])):
            target = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o644)
            os.dup2(target, fd)
            os.close(target)
        sys.argv = [module, *case["args"]]
        try:
            runpy.run_module(module, run_name="__main__", alter_sys=True)
            code = 0
        except SystemExit as e:  # as the interpreter handles it at its end
            if e.code is None:
                code = 0
            elif isinstance(e.code, int):
                code = e.code
            else:
                print(e.code, file=sys.stderr)
                code = 1
        except BaseException:  # noqa: BLE001  what the interpreter does with an uncaught exception
            traceback.print_exc()
            code = 1
        atexit._run_exitfuncs()
        sys.stdout.flush()
        sys.stderr.flush()
    finally:
        os._exit(code)


def main() -> None:
    module, cases, runs = sys.argv[1], json.loads(sys.argv[2]), sys.argv[3:]
    for name in (module, *runs):
        importlib.import_module(name)  # with everything it imports
    for name in (module, *runs):
        # each runs as __main__ in a case, as under `python -m`, not from this copy
        del sys.modules[name]
    statuses = []
    for case in cases:
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            run_case(module, case)
        statuses.append(os.waitstatus_to_exitcode(os.waitpid(pid, 0)[1]))
    print(json.dumps(statuses))


if __name__ == "__main__":
    main()
