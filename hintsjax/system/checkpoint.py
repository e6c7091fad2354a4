"""Orbax checkpoints of the full runner state (params, optimiser state, env state, RNG, step).

`save` blocks until the checkpoint is written, except inside `writing(run_dir)` (the run loop):
there it returns once the arrays are copied off the device and orbax writes the files in a
background thread (its async checkpointing), so training goes on meanwhile. Either way a
checkpoint appears in its folder only when complete (orbax finalises it by an atomic rename), so
a process killed mid-write keeps the previous one. Leaving `writing` waits for the writes and
reports a failed one.
"""

from __future__ import annotations

import contextlib
import logging
import os
import sys
import tempfile
import time
import types
import warnings
from pathlib import Path

import jax
import orbax.checkpoint as ocp

from hintsjax.system import devices
from hintsjax.system.errors import UsageError
from hintsjax.system.refusals import cause_text

CHECKPOINTS = "checkpoints"


def _quiet_closed_loops(previous):
    """An unraisable-exception hook that drops asyncio's "Event loop is closed": when a background
    write fails (a full disk), orbax closes its event loop while tensorstore's threads still call
    back into it, and each callback printed a traceback of that error (38 to 84 of them before the
    one line naming the checkpoint, under `ulimit -f`). Anything else goes to `previous`."""

    def hook(unraisable) -> None:
        if not (_closed_loop(unraisable.exc_value) or _orbax_read(unraisable.object)):
            previous(unraisable)

    return hook


def _orbax_read(obj) -> bool:
    """Whether `obj` is one of orbax's coroutines: when one array of a checkpoint cannot be read,
    the reads of the others are dropped unawaited and each printed "Exception ignored in:
    <coroutine _read_array_index_and_device_put>" with its traceback (up to 45 of them)."""
    return isinstance(obj, types.CoroutineType) and "orbax" in obj.cr_code.co_filename


# orbax's per-array write coroutine, as Python names it when one is dropped unawaited
_UNAWAITED_WRITE = r"coroutine '[\w.<>]*write_fragment' was never awaited"


def _drop_unawaited_writes() -> None:
    """For the rest of the process, drop the RuntimeWarning "coroutine '...write_fragment' was
    never awaited" (and its tracemalloc hint): when a background write fails (a full disk), orbax
    may shut its event loop before the writes of a checkpoint's other arrays start, and each is
    reported when it is collected, which can be after `writing` is left (at exit)."""
    warnings.filterwarnings("ignore", message=_UNAWAITED_WRITE, category=RuntimeWarning)


def _closed_loop(value: BaseException | None) -> bool:
    return isinstance(value, RuntimeError) and str(value) == "Event loop is closed"


def _drop_closed_loop_noise() -> None:
    """For the rest of the process, drop the "Event loop is closed" errors that tensorstore's
    threads print (through sys.excepthook, 0 to 32 of them) when a restore of unreadable files
    fails and orbax closes its event loop, and its dropped reads (`_orbax_read`,
    `_unretrieved_reads`): the one line naming the checkpoint says it all."""
    if getattr(sys.excepthook, "drops_closed_loops", False):
        return
    previous_except = sys.excepthook

    def excepthook(kind, value, tb) -> None:
        if not _closed_loop(value):
            previous_except(kind, value, tb)

    excepthook.drops_closed_loops = True
    sys.excepthook = excepthook
    sys.unraisablehook = _quiet_closed_loops(sys.unraisablehook)
    logging.getLogger("asyncio").addFilter(_unretrieved_reads)


def _unretrieved_reads(record: logging.LogRecord) -> bool:
    """A logging filter that drops asyncio's "Task (or _GatheringFuture) exception was never
    retrieved" for a read of tensorstore's (orbax's reads of a checkpoint's other arrays, left
    when one failed)."""
    text = record.getMessage()
    return not (
        text.startswith(("Task exception was never retrieved", "_GatheringFuture exception was"))
        and "tensorstore" in text.lower()
    )


class CheckpointWriteError(RuntimeError):
    """A checkpoint could not be written (disk full, folder removed): the run stops, and the
    newest complete checkpoint is the one to resume from."""


def _manager(run_dir: Path, create: bool, background: bool = False) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(
        max_to_keep=2, create=create, enable_async_checkpointing=background
    )
    return ocp.CheckpointManager(
        (Path(run_dir) / CHECKPOINTS).absolute(),
        options=options,
        item_handlers=ocp.StandardCheckpointHandler(),
    )


_WRITERS: dict[Path, ocp.CheckpointManager] = {}  # folders inside `writing`: their async managers
_HANDED: dict[Path, int] = {}  # the update each of those managers was given last


@contextlib.contextmanager
def writing(run_dir: Path):
    """Within this block `save(run_dir, ...)` writes in the background; leaving it waits for the
    writes to finish (CheckpointWriteError if one failed), also when the block is left by an
    exception, so an interrupted run keeps the checkpoint it was writing. Meanwhile a failed write's
    "Event loop is closed" noise is dropped (`_quiet_closed_loops`), and from then on its unawaited
    writes (`_drop_unawaited_writes`) and the same error that tensorstore's threads print through
    sys.excepthook, which can come after the block (`_drop_closed_loop_noise`, as a failed
    restore's)."""
    _WRITERS[Path(run_dir).absolute()] = _manager(run_dir, create=True, background=True)
    _drop_unawaited_writes()
    _drop_closed_loop_noise()
    previous = sys.unraisablehook
    sys.unraisablehook = _quiet_closed_loops(previous)
    try:
        yield
    finally:
        try:
            flush(run_dir)
        finally:
            sys.unraisablehook = previous


def _array_specs(tree) -> list[tuple[tuple[int, ...], str]]:
    """The (shape, dtype) of every array in `tree`, sorted: comparable across pytree types."""
    return sorted((tuple(x.shape), str(x.dtype)) for x in jax.tree.leaves(tree))


def require_same_arrays(stored, expected, source: str) -> None:
    """ValueError unless the stored arrays' metadata matches `expected` in shapes and types.
    Compared before reading any array: a mismatched restore fails part-way and leaves orbax's
    other reads pending (pages of tracebacks at exit)."""
    saved, wanted = _array_specs(stored), _array_specs(expected)
    if saved != wanted:
        raise ValueError(
            f"its {len(saved)} arrays differ in shape or type from the {len(wanted)} that {source}"
        )


def on_this_device(abstract):
    """`abstract`'s shapes and types placed on this process's first device: what to restore
    into, wherever the arrays were saved (a GPU's checkpoint records devices a CPU lacks; each
    process of a run over several reads the whole state, hintsjax/system/devices.py spreads it)."""
    here = jax.sharding.SingleDeviceSharding(jax.local_devices()[0])
    return jax.tree.map(lambda x: jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=here), abstract)


@contextlib.contextmanager
def _quiet():
    """Hold back orbax's own log lines about unreadable files: our error is the one line."""
    logger = logging.getLogger("absl")
    level = logger.level
    logger.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        logger.setLevel(level)


def _raw_keys(state):
    """Typed PRNG keys as their uint32 data: what orbax can store."""
    return jax.tree.map(
        lambda x: jax.random.key_data(x)
        if jax.dtypes.issubdtype(x.dtype, jax.dtypes.prng_key)
        else x,
        state,
    )


def _writable(folder: Path) -> str | None:
    """Why `folder` takes no new checkpoint folder (full, read-only, immutable, too many open
    files, its run folder gone), or None: process 0 makes and removes one there (the others answer
    None). A save orbax cannot even begin leaves its background threads waiting for each other
    until its ten-minute timeout, and the process with them."""
    if not devices.is_main():
        return None
    try:
        folder.mkdir(exist_ok=True)  # not its parents: a run folder removed stays removed
        os.rmdir(tempfile.mkdtemp(prefix=".probe-", dir=folder))
    except OSError as e:
        return cause_text(e)
    return None


def _failed(run_dir: Path, update: int | None, why: str) -> CheckpointWriteError:
    return CheckpointWriteError(
        f"could not write checkpoint {update} in {run_dir / CHECKPOINTS}: {why}"
    )


def save(run_dir: Path, state, update: int) -> None:
    """Save the seed-batched runner state after `update` updates: in the background inside
    `writing(run_dir)` (after this folder's previous write is done), else blocking.
    CheckpointWriteError if this or an earlier background write failed, naming the one that did,
    or if the folder takes no new checkpoint (`_writable`), found before orbax is asked."""
    key = Path(run_dir).absolute()
    manager = _WRITERS.get(key)
    at, why = update, None
    if manager is not None:
        try:  # the write handed over last (the run loop saves only once it is done)
            manager.wait_until_finished()
            manager.check_for_errors()
        except Exception as e:
            at, why = _HANDED.get(key, update), cause_text(e)
    why = why or _writable(key / CHECKPOINTS)
    # one answer for all: a failure may show on one process only, and each joins orbax's save
    if not devices.every_process(why is None):
        raise _failed(key, at, why or "another process of the run could not write it")
    try:
        if manager is None:
            with _manager(run_dir, create=True) as blocking:
                blocking.save(update, args=ocp.args.StandardSave(_raw_keys(state)))
                blocking.wait_until_finished()
            return
        manager.save(update, args=ocp.args.StandardSave(_raw_keys(state)))
        _HANDED[key] = update
    except Exception as e:
        raise _failed(key, update, cause_text(e)) from None


def saving(run_dir: Path) -> bool:
    """Whether a checkpoint of `run_dir` is still being written."""
    manager = _WRITERS.get(Path(run_dir).absolute())
    return manager is not None and manager.is_saving_in_progress()


def flush(run_dir: Path) -> None:
    """Wait until the background writes into `run_dir` are complete and stop writing in the
    background; CheckpointWriteError naming the first that failed (the complete ones stay)."""
    key = Path(run_dir).absolute()
    manager, handed = _WRITERS.pop(key, None), _HANDED.pop(key, None)
    if manager is None:
        return
    try:
        manager.wait_until_finished()
        manager.check_for_errors()
    except Exception as e:
        raise _failed(key, handed, cause_text(e)) from None
    finally:
        with contextlib.suppress(Exception):
            manager.close()


def _first_line(e: Exception) -> str:
    return str(e).strip().splitlines()[0][:200] if str(e).strip() else type(e).__name__


def drop_empty_step_folders(run_dir: Path) -> None:
    """Remove empty numbered folders from checkpoints/ (made by hand, or by a copy cut short):
    orbax would take one for the newest checkpoint, fail to resume from it and never save below
    it. Being empty, nothing is lost."""
    for folder in (Path(run_dir) / CHECKPOINTS).iterdir():
        if folder.is_dir() and folder.name.isdigit() and not any(folder.iterdir()):
            folder.rmdir()


def newest_listed(run_dir: Path) -> int | None:
    """The newest numbered checkpoint folder with something in it, read off the folder alone (no
    orbax manager, whose opening is a collective every process must join): orbax renames a
    checkpoint into its number only once it is complete."""
    path = Path(run_dir) / CHECKPOINTS
    if not path.is_dir():
        return None
    return max(
        (
            int(step.name)
            for step in path.iterdir()
            if step.is_dir() and step.name.isdigit() and any(step.iterdir())
        ),
        default=None,
    )


def any_saved(run_dir: Path) -> bool:
    """Whether `run_dir` holds a checkpoint, read off the folder alone (`newest_listed`)."""
    return newest_listed(run_dir) is not None


def latest_update(run_dir: Path) -> int | None:
    """The update of the newest complete checkpoint in `run_dir` (None without any; an empty
    numbered folder is none: `drop_empty_step_folders`)."""
    path = Path(run_dir) / CHECKPOINTS
    if not path.is_dir():
        return None
    drop_empty_step_folders(run_dir)
    with _quiet(), _manager(run_dir, create=False) as manager:
        return manager.latest_step()


# where a resumed run sets aside the checkpoints it could not restore
CORRUPT = "checkpoints-corrupt"


def restore_latest(run_dir: Path, abstract, set_aside: bool = False):
    """(runner state, update) of the newest checkpoint that restores; UsageError if there is none,
    or if the newest does not match (its arrays' shapes and types differ from `abstract`'s).

    A newer checkpoint that cannot be read (a truncated array file, a missing manifest, a step
    half-written when the power went) is passed over for the one before it, with one line on
    stderr naming both; with `set_aside` (a run that trains on, and would write that step again)
    it is moved into the run folder's checkpoints-corrupt/, kept for a look, never deleted.

    `abstract` is the seed-batched state's shapes and types, which the caller knows (a run's
    `Trainer.abstract_state()`), so that checkpointing needs nothing of the code that trains.
    """
    if latest_update(run_dir) is None:
        raise UsageError(f"no checkpoint in {Path(run_dir) / CHECKPOINTS}")
    expected = on_this_device(jax.eval_shape(_raw_keys, abstract))
    with _quiet(), _manager(run_dir, create=False) as manager:
        steps = sorted(manager.all_steps(), reverse=True)
    failed: list[tuple[int, str]] = []
    # before the first read: an unreadable one's noise starts while it fails
    _drop_closed_loop_noise()
    for update in steps:
        try:
            raw = _restore(run_dir, update, expected)
            break
        except _Mismatch as e:
            # the newest is readable and of another shape: its config.yaml is the wrong one
            if not failed:
                raise UsageError(
                    f"checkpoint {update} in {run_dir} does not match its config.yaml: {e}"
                ) from None
            failed.append((update, str(e)))
        except Exception as e:  # orbax raises many types for unreadable files
            failed.append((update, _first_line(e)))
    else:
        newest, reason = failed[0]
        raise UsageError(
            f"checkpoint {newest} in {run_dir} is corrupt or does not match its "
            f"config.yaml: {reason}"
            + (f" (and the {len(failed) - 1} before it)" if len(failed) > 1 else "")
        )
    if failed:
        kept = ""
        if set_aside:
            aside = Path(run_dir) / CORRUPT
            aside.mkdir(exist_ok=True)
            for step, _ in failed:
                (Path(run_dir) / CHECKPOINTS / str(step)).replace(
                    aside / f"{step}-{time.strftime('%Y%m%d-%H%M%S')}"
                )
            kept = f"; set aside in {aside}"
        newest, reason = failed[0]
        print(
            f"warning: checkpoint {newest} in {Path(run_dir) / CHECKPOINTS} cannot be restored "
            f"({reason[:120]}); "
            f"using checkpoint {update}, the newest that restores{kept}",
            file=sys.stderr,
        )
    state = jax.tree.map(
        lambda a, r: jax.random.wrap_key_data(r)
        if jax.dtypes.issubdtype(a.dtype, jax.dtypes.prng_key)
        else r,
        abstract,
        raw,
    )
    return state, update


class _Mismatch(ValueError):
    """A checkpoint whose arrays are readable and of other shapes or types than expected."""


def _restore(run_dir: Path, update: int, expected):
    """The raw arrays of checkpoint `update`; _Mismatch where its metadata reads but differs."""
    with _quiet(), _manager(run_dir, create=False) as manager:
        stored = manager.item_metadata(update)
        if not jax.tree.leaves(stored):  # no metadata: a step cut short, not another config's
            raise ValueError("its metadata lists no arrays")
        try:
            require_same_arrays(stored, expected, "the config gives")
        except ValueError as e:
            raise _Mismatch(str(e)) from None
        return manager.restore(update, args=ocp.args.StandardRestore(expected))
