"""One writer a run folder (hintsjax/system/folder_lock.py): a second run on a folder that a run
holds is refused in one line naming the holder, exit 2, with nothing in the folder changed; a
holder killed with SIGKILL leaves no lock behind; readers say when a run still trains there."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from hintsjax.system import folder_lock
from hintsjax.system.errors import UsageError

HOLD = (
    "import sys, time\n"
    "from hintsjax.system import folder_lock\n"
    "folder_lock.acquire(sys.argv[1])\n"
    "print('held', flush=True)\n"
    "time.sleep(120)\n"
)


def holding(folder: Path) -> subprocess.Popen:
    """Another process that holds `folder`'s lock (until it is killed)."""
    proc = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(folder)], stdout=subprocess.PIPE, text=True
    )
    assert proc.stdout.readline().strip() == "held"
    return proc


def killed(proc: subprocess.Popen) -> None:
    proc.send_signal(signal.SIGKILL)
    proc.wait(timeout=30)


def snapshot(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def test_a_held_folder_is_refused_naming_its_holder_until_the_holder_is_killed(tmp_path):
    other = holding(tmp_path)
    try:
        assert f"pid {other.pid}" in folder_lock.holder(tmp_path)
        with pytest.raises(UsageError, match=f"being written by another run \\(pid {other.pid} "):
            folder_lock.acquire(tmp_path)
    finally:
        killed(other)
    # SIGKILL: no clean-up ran, its lock file is still there, and it holds nothing
    assert (tmp_path / folder_lock.LOCK).exists()
    assert folder_lock.holder(tmp_path) is None
    mine = folder_lock.acquire(tmp_path)
    assert f"pid {os.getpid()}" in folder_lock.holder(tmp_path)
    mine.release()
    assert not (tmp_path / folder_lock.LOCK).exists() and folder_lock.holder(tmp_path) is None
    folder_lock.acquire(tmp_path).release()  # free again once released


def test_a_resume_of_a_folder_another_run_holds_is_one_line_and_changes_nothing(tmp_path, capsys):
    from hintsjax import run
    from hintsjax.settings.layers import run_config, save_run_config

    from test_cli import tiny_values

    folder = tmp_path / "run"
    folder.mkdir()
    save_run_config(folder, run_config({k: v for k, v in tiny_values().items() if k != "out_dir"}))
    other = holding(folder)
    try:
        before = snapshot(folder)
        capsys.readouterr()
        assert run.main_from_values({"resume": str(folder)}) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert snapshot(folder) == before
    finally:
        killed(other)
    assert len(err) == 1 and err[0].startswith("error: "), err
    assert f"{folder} is being written by another run (pid {other.pid} " in err[0]


def test_a_reader_of_a_folder_in_training_says_so(tmp_path, capsys):
    folder_lock.say_if_training(tmp_path)
    assert capsys.readouterr().err == ""
    other = holding(tmp_path)
    try:
        folder_lock.say_if_training(tmp_path)
        said = capsys.readouterr().err
    finally:
        killed(other)
    assert said.startswith(f"note: {tmp_path} is still training (pid {other.pid} "), said
    folder_lock.say_if_training(tmp_path)  # its holder gone: nothing to say
    assert capsys.readouterr().err == ""


@pytest.mark.slow
def test_a_second_run_on_a_folder_in_training_is_refused_and_leaves_its_log_whole(tmp_path):
    """Two writers at once, through the command line: a run trains; a resume of its folder,
    started while it trains, exits 2 naming it; the first, then stopped by SIGTERM, has logged
    each of its updates once and in order, and leaves no lock."""
    from test_cli import TINY

    # 20000 updates in chunks of 100: training still, whenever the second run gets going
    steps = ["ppo.total_env_steps=1280000", "checkpoint_every=100"]
    first = subprocess.Popen(
        [sys.executable, "-m", "hintsjax.run", *TINY, *steps, "out_dir=runs", "name=one"],
        cwd=tmp_path,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    folder = tmp_path / "runs" / "one"
    try:
        deadline = time.monotonic() + 240
        while (
            not (folder / "metrics.csv").exists()
            or len((folder / "metrics.csv").read_text().splitlines()) < 2
        ):
            assert first.poll() is None and time.monotonic() < deadline
            time.sleep(0.2)
        second = subprocess.run(
            [sys.executable, "-m", "hintsjax.run", f"resume={folder}"],
            cwd=tmp_path,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert first.poll() is None, "the first run ended before the second could meet it"
    finally:
        first.send_signal(signal.SIGTERM)
        out, err = first.communicate(timeout=300)
    assert second.returncode == 2, second.stderr[-3000:]
    lines = second.stderr.strip().splitlines()
    assert len(lines) == 1 and f"(pid {first.pid} " in lines[0], lines
    assert first.returncode == 143, err[-3000:]
    rows = (folder / "metrics.csv").read_text().strip().splitlines()[1:]
    logged = [tuple(int(x) for x in row.split(",")[:2]) for row in rows]  # (update, seed)
    n = len(logged) // 2  # TINY's 2 seeds
    assert n > 0 and logged == [(u, s) for u in range(1, n + 1) for s in (0, 1)], logged[:6]
    assert not (folder / folder_lock.LOCK).exists()


def test_a_file_system_that_takes_no_locks_is_one_line_and_the_run_goes_on(
    tmp_path, monkeypatch, capsys
):
    import errno
    import fcntl

    def unsupported(fd, how):
        raise OSError(errno.ENOLCK, os.strerror(errno.ENOLCK))

    monkeypatch.setattr(fcntl, "flock", unsupported)
    lock = folder_lock.acquire(tmp_path)
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and err[0].startswith(f"warning: {tmp_path} takes no lock"), err
    lock.release()  # nothing to release
