"""The machine's refusals told by their cause (hintsjax/system/refusals.py): a full disk is the
disk, not memory, though tensorstore calls it RESOURCE_EXHAUSTED; too many open files names the
limit; a checkpoints folder that takes no new checkpoint is found before orbax is asked, so no
background thread of orbax's is left waiting; and limits too low for JAX to start are refused
before a command runs (under them XLA aborts in C++). Each is one line and exit 1.

The real faults (a full tmpfs, an immutable folder, `ulimit`) need root or a mount; where the
machine gives neither, those cases skip and say why."""

from __future__ import annotations

import errno
import os
import resource
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

import jax
import pytest

import command_runs  # tests/command_runs.py
from hintsjax.system import checkpoint, errors, refusals

# tensorstore's words for a full disk under orbax (a real one, from a 256 KiB tmpfs), as
# CheckpointManager raises them from its background write
TENSORSTORE_FULL = (
    'RESOURCE_EXHAUSTED: Error writing "w/0" in OCDBT database at local file "/t/1.orbax-'
    'checkpoint-tmp/ocdbt.process_0/": Failed to write 498033 bytes to file 4: No space left on '
    "device [os_error_code='28']"
)


def test_the_os_refusal_behind_an_error_is_found_by_its_code_or_its_words():
    assert refusals.os_errno(ValueError(TENSORSTORE_FULL)) == errno.ENOSPC
    assert refusals.os_errno(RuntimeError("[Errno 24] Too many open files")) == errno.EMFILE
    assert refusals.os_errno(RuntimeError("mkdir: Read-only file system")) == errno.EROFS
    assert refusals.os_errno(OSError(errno.EMFILE, "Too many open files")) == errno.EMFILE
    assert refusals.os_errno(RuntimeError("RESOURCE_EXHAUSTED: Out of memory allocating")) is None
    # raised from one, or while handling one, not where `from None` hides it: an out-of-memory
    # error raised in a handler of a missing file is memory, not the file
    try:
        try:
            raise ValueError(TENSORSTORE_FULL)
        except ValueError as e:
            raise checkpoint.CheckpointWriteError("could not write checkpoint 2") from e
    except checkpoint.CheckpointWriteError as e:
        assert refusals.os_errno(e) == errno.ENOSPC
        assert refusals.cause_text(e) == "No space left on device"
    try:
        try:
            raise FileNotFoundError(errno.ENOENT, "No such file or directory", "cache")
        except FileNotFoundError:
            raise RuntimeError("RESOURCE_EXHAUSTED: Out of memory allocating 8 bytes")
    except RuntimeError as e:
        assert refusals.os_errno(e) == errno.ENOENT and refusals.out_of_memory(e)
    try:
        try:
            raise ValueError(TENSORSTORE_FULL)
        except ValueError:
            raise RuntimeError("could not write checkpoint 2") from None
    except RuntimeError as e:
        assert refusals.os_errno(e) is None


def test_a_full_disk_is_not_memory_though_tensorstore_says_resource_exhausted():
    full = ValueError(TENSORSTORE_FULL)
    assert not refusals.out_of_memory(full)
    assert refusals.out_of_memory(RuntimeError("RESOURCE_EXHAUSTED: Out of memory allocating 8"))
    # work sized by settings lets a full disk through as itself, not as "lower ppo.batch_size"
    with pytest.raises(ValueError, match="No space left"):
        with refusals.sized_by("ppo.batch_size"):
            raise full


@pytest.mark.parametrize(
    ("error", "line"),
    [
        (
            ValueError(TENSORSTORE_FULL),
            "error: could not write /runs/r: No space left on device; free space there (or write "
            "to another disk) and run again",
        ),
        (
            OSError(errno.EMFILE, "Too many open files"),
            "error: too many open files (this process may open {files} at once: ulimit -n); raise "
            "the limit (ulimit -n 4096) and run again",
        ),
        (
            RuntimeError("failed to open: Too many open files"),
            "error: too many open files (this process may open {files} at once: ulimit -n); raise "
            "the limit (ulimit -n 4096) and run again",
        ),
    ],
)
def test_each_refusal_is_one_line_naming_its_cause_exit_1(error, line, capsys):
    files, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    assert refusals.machine_refused(error)
    assert refusals.report_machine(error, "/runs/r") == refusals.MACHINE
    assert capsys.readouterr().err.strip().splitlines() == [line.format(files=files)]


def test_limits_too_low_for_jax_are_refused_before_the_command_runs(monkeypatch, capsys):
    real = resource.getrlimit
    ran = []

    @errors.command
    def a_command() -> int:
        ran.append(True)
        return 0

    def limited(which: int, soft: int):
        monkeypatch.setattr(
            resource, "getrlimit", lambda r: (soft, soft) if r == which else real(r)
        )

    for which, flag, soft in (
        (resource.RLIMIT_AS, "-v", 1_500_000 * 1024),
        (resource.RLIMIT_DATA, "-d", 2 * 2**30),
    ):
        limited(which, soft)
        assert a_command() == refusals.MACHINE
        assert capsys.readouterr().err.strip().splitlines() == [
            f"error: this process may map at most {soft / 2**30:.1f} GiB of memory (ulimit {flag} "
            f"{soft // 1024}); JAX needs 4 GiB or more to start and compile: raise it (ulimit "
            f"{flag} unlimited) and run again"
        ]
    limited(resource.RLIMIT_NOFILE, 16)
    assert a_command() == refusals.MACHINE
    assert capsys.readouterr().err.strip().splitlines() == [
        "error: this process may open only 16 files at once (ulimit -n); a run needs 64 or more: "
        "raise it (ulimit -n 4096) and run again"
    ]
    assert not ran
    # at the floors, and unlimited, the command runs
    limited(resource.RLIMIT_AS, refusals.MIN_ADDRESS_SPACE)
    assert a_command() == 0 and ran == [True]
    limited(resource.RLIMIT_NOFILE, resource.RLIM_INFINITY)
    assert a_command() == 0 and ran == [True, True]


def _waiting_threads(before: set[threading.Thread]) -> list[str]:
    """Threads started since `before` still alive after a few seconds: what would keep the process
    from exiting (orbax's signalling threads are not daemons)."""
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        left = [t for t in threading.enumerate() if t not in before and not t.daemon]
        if not left:
            return []
        time.sleep(0.1)
    return [t.name for t in left]


def test_a_checkpoints_folder_that_takes_no_new_file_is_named_and_leaves_no_thread_waiting(
    tmp_path, unwritable
):
    """The write a folder made immutable refuses is found before orbax is asked: a background save
    orbax cannot even begin left its signalling threads waiting for each other (for its ten-minute
    timeout, the process hung at exit with them). The checkpoint already written stays; the one
    refused is named with its cause."""
    state = {"w": jax.random.normal(jax.random.key(0), (1000,))}
    before = set(threading.enumerate())
    checkpoint.save(tmp_path, state, 1)
    checkpoint.save(tmp_path, state, 2)
    unwritable(tmp_path / checkpoint.CHECKPOINTS)
    with pytest.raises(checkpoint.CheckpointWriteError) as refused:
        with checkpoint.writing(tmp_path):  # leaving it waits for the background writes
            checkpoint.save(tmp_path, state, 3)
    waiting = _waiting_threads(before)
    cause = "Operation not permitted" if os.geteuid() == 0 else "Permission denied"
    assert str(refused.value) == (
        f"could not write checkpoint 3 in {tmp_path.absolute() / 'checkpoints'}: {cause}"
    )
    assert waiting == []
    assert checkpoint.latest_update(tmp_path) == 2


def _tmpfs(size_kib: int, folder: Path) -> list[str]:
    """A command prefix that runs in a mount namespace with a `size_kib` tmpfs on `folder`: as
    root, or through an unprivileged user namespace (unshare -r); skips where neither mounts."""
    folder.mkdir(parents=True, exist_ok=True)
    script = f'mount -t tmpfs -o size={size_kib}k none "{folder}" && exec "$@"'
    prefix = ["unshare", "-m"] if os.geteuid() == 0 else ["unshare", "-rm"]
    prefix += ["sh", "-c", script, "sh"]
    if shutil.which("unshare") is None:
        pytest.skip("no unshare here to mount a small tmpfs")
    tried = subprocess.run([*prefix, "true"], capture_output=True, text=True)
    if tried.returncode != 0:
        pytest.skip(f"this machine mounts no tmpfs for a test: {tried.stderr.strip()}")
    return prefix


@pytest.mark.slow
def test_a_full_disk_while_checkpointing_is_the_disk_in_one_line_and_resumes_where_it_fits(
    tmp_path,
):
    """A run whose out_dir is a 256 KiB tmpfs: its first checkpoint fills it. One line names the
    checkpoint, the cause (no space, not memory: it said 'the device ran out of memory') and the
    command that goes on; exit 1, at once."""
    disk = tmp_path / "disk"
    prefix = _tmpfs(256, disk)
    started = time.monotonic()
    out = subprocess.run(
        [
            *prefix,
            sys.executable,
            "-m",
            "hintsjax.run",
            "env=pendulum",
            "agent=ppo_rgb",
            "seeds=2",
            "eval_episodes=3",
            "ppo.total_env_steps=512",
            "ppo.num_envs=4",
            "ppo.batch_size=64",
            "ppo.minibatch_size=32",
            "ppo.epochs=1",
            "checkpoint_every=2",
            "checkpoint_seconds=0",
            f"out_dir={disk}",
            "name=full",
            "compilation_cache=false",
        ],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert out.returncode == refusals.MACHINE, out.stderr[-2000:]
    said = command_runs.said(out.stderr)
    folder = disk / "full"
    assert said[-1] == (
        f"error: could not write checkpoint 2 in {folder / 'checkpoints'}: No space left on "
        "device; none is complete; once it can be written, go on with: python -m hintsjax.run "
        f"resume={folder}"
    ), said
    assert not any("memory" in line for line in said), said
    assert time.monotonic() - started < 300


@pytest.mark.slow
def test_limits_too_low_are_refused_by_every_command_before_jax_starts(tmp_path):
    """Under real limits (`ulimit`, as a shell sets them) the run, evaluate and video refuse in
    one line, exit 1: under ulimit -v 1500000 XLA aborted in C++ ("cannot allocate memory for
    thread-local data"), under ulimit -n 16 the run died in orbax's event loop."""
    for limit, words in (("-v 1500000", "may map at most 1.4 GiB"), ("-n 16", "only 16 files")):
        for module, args in (
            ("hintsjax.run", "env=pendulum agent=ppo_state"),
            ("hintsjax.evaluate", str(tmp_path)),
            ("hintsjax.video", str(tmp_path)),
        ):
            out = subprocess.run(
                ["bash", "-c", f"ulimit {limit} && exec {sys.executable} -m {module} {args}"],
                cwd=tmp_path,
                capture_output=True,
                text=True,
                timeout=300,
            )
            lines = out.stderr.strip().splitlines()
            assert out.returncode == refusals.MACHINE and len(lines) == 1, (module, out.stderr)
            assert lines[0].startswith("error: this process ") and words in lines[0], lines
    assert list(tmp_path.iterdir()) == []


def test_orbax_reads_left_unretrieved_are_dropped_from_the_log_and_nothing_else():
    """asyncio's "exception was never retrieved" for tensorstore's reads (a Task's or a
    _GatheringFuture's: orbax's other reads of a checkpoint it passed over; the re-try of issue 81
    saw 296 such lines before the one naming the checkpoint) is dropped; others are kept."""
    import logging

    def record(text: str) -> logging.LogRecord:
        return logging.LogRecord("asyncio", logging.ERROR, __file__, 1, text, None, None)

    reads = 'future: <_GatheringFuture finished exception=Exception("... TensorStore details")>'
    dropped = [
        f"_GatheringFuture exception was never retrieved\n{reads}",
        "Task exception was never retrieved\nfuture: <Task ... TensorStore({...})>",
    ]
    kept = [
        "_GatheringFuture exception was never retrieved\nfuture: <... ValueError('mine')>",
        "Task exception was never retrieved\nfuture: <Task ... ZeroDivisionError>",
        "Unclosed client session",
    ]
    assert [checkpoint._unretrieved_reads(record(t)) for t in dropped] == [False, False]
    assert [checkpoint._unretrieved_reads(record(t)) for t in kept] == [True, True, True]
