"""Signals as interrupts: within `signal_as_interrupt` a signal (SIGTERM: `sigterm_as_interrupt`;
submitit's preemption: hintsjax/system/requeue.py) raises in the main thread as Ctrl-C does, so
whatever handles Ctrl-C handles it too; within `stops_deferred` (training's loop) the stop is kept
and raised at the loop's safe points (`raise_stop_asked`), as is one asked while a command's
modules still import (`keep_while_starting`)."""

from __future__ import annotations

import contextlib
import os
import signal
import threading
from typing import Any, Callable


class Terminated(KeyboardInterrupt):
    """SIGTERM (a cluster's time limit or preemption, `kill`), raised in the main thread as Ctrl-C
    raises KeyboardInterrupt, so whatever handles Ctrl-C (a run saves its newest logged state)
    handles it too; reported as its own line, exit 143."""


_stops: list[KeyboardInterrupt] = []  # the stop a signal asked for (within `signal_as_interrupt`)
_blocks: list[int] = []  # the signals of the `signal_as_interrupt` blocks open now, outermost first
_deferring: list[bool] = []  # `stops_deferred` blocks open now


@contextlib.contextmanager
def signal_as_interrupt(
    number: int, make: Callable[[int, Any], KeyboardInterrupt], again: bool = False
):
    """Within this block the signal `number` raises `make(number, frame)` in the main thread, as
    Ctrl-C raises KeyboardInterrupt (once: another signal while a stop is under way is ignored,
    and SIGKILL still kills); the signal's handler is put back after. Outside the main thread
    (where Python cannot handle signals) nothing changes.

    Within `stops_deferred` (training's loop) the stop is only kept, and the loop raises it at its
    safe points (`raise_stop_asked`), so that it never lands in the middle of a metrics row or a
    checkpoint's hand-over. Python also drops an exception raised while a garbage collector's
    callback runs (JAX has one: it prints "Exception ignored in ..." and goes on); the kept stop is
    raised at the next safe point then too."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, frame):
        if not _stops:
            _stops.append(make(signum, frame))
            if not _deferring:
                raise _stops[0]
        elif again:  # a second Ctrl-C: at once, wherever it lands (a save under way too)
            raise make(signum, frame)

    previous = signal.signal(number, handler)
    _blocks.append(number)
    try:
        yield
    finally:
        signal.signal(number, signal.SIG_DFL if previous is None else previous)
        _blocks.pop()
        # the outermost block: a stop taken in an inner one still holds off the outer's signal till
        # here
        if not _blocks:
            _stops.clear()


@contextlib.contextmanager
def stops_deferred():
    """Within this block a signal's stop (`signal_as_interrupt`) is kept, not raised: the code in
    it raises the stop at its own safe points (`raise_stop_asked`)."""
    _deferring.append(True)
    try:
        yield
    finally:
        _deferring.pop()


def raise_stop_asked() -> None:
    """Raise the stop a signal asked for, if any (`signal_as_interrupt`): kept within
    `stops_deferred`, or dropped by Python where it was raised."""
    if _stops:
        raise _stops[0]


def sigterm_as_interrupt():
    """Within this block SIGTERM raises Terminated in the main thread (`signal_as_interrupt`)."""
    return signal_as_interrupt(signal.SIGTERM, lambda number, frame: Terminated())


def sigint_as_interrupt():
    """Within this block Ctrl-C (SIGINT) raises KeyboardInterrupt as Python's own handler does, and
    keeps its stop (`signal_as_interrupt`): one that Python drops inside a garbage collector's
    callback (JAX's, while a program compiles) is raised at the next safe point, not lost; a
    second Ctrl-C is raised at once, wherever it lands. A SIGINT the shell ignores stays ignored."""
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:  # the shell's choice (`cmd &`): kept
        return contextlib.nullcontext()
    return signal_as_interrupt(signal.SIGINT, lambda number, frame: KeyboardInterrupt(), again=True)


def keep_while_starting() -> None:
    """For a command's process, before its modules import (hintsjax/__init__.py): Ctrl-C and
    SIGTERM keep their stop until the command's boundary begins (`command_begins`); a second
    Ctrl-C is raised at once. Python's own handler raised it wherever it landed, and inside JAX's
    garbage-collector callback it was dropped: the run then trained to its end."""
    if threading.current_thread() is not threading.main_thread():
        return
    for number in (signal.SIGINT, signal.SIGTERM):
        if signal.getsignal(number) in (signal.default_int_handler, signal.SIG_DFL):
            signal.signal(number, _kept_while_starting)


def _kept_while_starting(signum, frame) -> None:
    if not _stops:
        _stops.append(Terminated() if signum == signal.SIGTERM else KeyboardInterrupt())
    elif signum == signal.SIGINT:
        raise KeyboardInterrupt()
    else:  # a second SIGTERM: as if never handled (the process ends at once)
        signal.signal(signal.SIGTERM, signal.SIG_DFL)
        os.kill(os.getpid(), signal.SIGTERM)


def command_begins() -> None:
    """A command's boundary begins (hintsjax.system.errors.command): Python's own handlers back in
    place of `keep_while_starting`'s, then the stop it kept, if any, raised."""
    if threading.current_thread() is not threading.main_thread():
        return
    kept = False
    for number, default in ((signal.SIGINT, signal.default_int_handler), (signal.SIGTERM, None)):
        if signal.getsignal(number) is _kept_while_starting:
            signal.signal(number, signal.SIG_DFL if default is None else default)
            kept = True
    if kept and _stops and not _blocks:
        raise _stops.pop()
