"""Ctrl-C and SIGTERM mean one thing: stop, and keep what is finished.

The first signal raises KeyboardInterrupt where the work is (the episode loops catch it and keep
the finished episodes). While results are being written, and after the first signal, signals are
only noted: a second Ctrl-C never cuts a results file or an episode record in half. Training has
its own handlers (a stop at the next checkpoint) and puts these back when it ends."""

from __future__ import annotations

import signal
import sys
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from types import FrameType

_received = 0
_deferring = 0
_pending = False
_held = False
_raised = False
STOPPING = "stopping: writing what is finished first"
SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""The stops a command handles (a terminal's Ctrl-C, a kill)."""


def hold_signals() -> None:
    """SIGINT and SIGTERM only noted until `catch_signals`: the `drivestack` entry point calls this
    first, so a stop while the command line is still being imported ends the command with exit 130
    before it does anything (not with SIGTERM's default exit 143, or a traceback from the import)."""

    def noted(signum: int, frame: FrameType | None) -> None:
        global _held
        _held = True

    for sig in SIGNALS:
        signal.signal(sig, noted)


def catch_signals() -> bool:
    """Install the handler for SIGINT and SIGTERM (the CLI does, once, before any command); whether
    a stop came while they were held (`hold_signals`): the command then does nothing."""
    global _received, _pending, _held, _raised
    _received, _pending, _raised = 0, False, False
    for sig in SIGNALS:
        signal.signal(sig, _handler)
    held, _held = _held, False
    return held


def ignore_signals() -> None:
    """SIGINT and SIGTERM ignored from now on: the command's work is done and its exit code set.
    (At exit Python puts the default action back for signals it handles, so a signal during the
    interpreter's teardown would otherwise end the process with -SIGTERM instead of its code.)"""
    for sig in SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


def received() -> bool:
    """Whether a stop was asked for (the command then ends with exit code 130)."""
    return _received > 0


def note_stop() -> None:
    """A stop asked for elsewhere (training's own handler): the command ends with exit code 130,
    and a later signal, once these handlers are back, only waits like a second one."""
    global _received
    _received = max(_received, 1)


def raise_if_stopped() -> None:
    """KeyboardInterrupt again if a stop was raised before. Python ignores an exception raised in a
    finalizer or a `__del__` (it prints "Exception ignored"), so the first signal's KeyboardInterrupt
    is lost when it lands in one; work that runs item by item calls this before each item, so that
    stop still ends the work there."""
    if _raised:
        raise KeyboardInterrupt


def _interrupt() -> None:
    global _raised
    _raised = True
    raise KeyboardInterrupt


def _handler(signum: int, frame: FrameType | None) -> None:
    global _received, _pending
    _received += 1
    if _received == 1 and not _deferring:
        _interrupt()
    if _received == 1:
        _pending = True
    print(STOPPING, file=sys.stderr)


@contextmanager
def deferred(interrupt_after: bool = True) -> Iterator[None]:
    """Signals wait until the block is done. A first signal that arrived meanwhile is raised as
    KeyboardInterrupt when it ends, if `interrupt_after` (a step inside the work), else only noted
    (the last write of a command, which then exits 130)."""
    global _deferring, _pending
    _deferring += 1
    try:
        yield
    finally:
        _deferring -= 1
    if _pending and not _deferring:
        _pending = False
        if interrupt_after:
            _interrupt()


@contextmanager
def stopped_by(stop: Callable[[], bool]) -> Iterator[None]:
    """For work that stops itself cleanly when asked (Ray Tune's loop): inside the block the first
    SIGINT or SIGTERM calls `stop`, which returns False when the work cannot be asked yet (the
    signal then raises KeyboardInterrupt, as outside); later signals only say that the command
    stops. A stop that waits (`deferred`) is raised at once: the work never starts."""
    if _pending:
        raise KeyboardInterrupt

    def asked(signum: int, frame: FrameType | None) -> None:
        global _received
        _received += 1
        if _received > 1:
            print(STOPPING, file=sys.stderr)
        elif not stop():
            raise KeyboardInterrupt

    with handled_by(asked):
        yield


@contextmanager
def handled_by(handler: Callable[[int, FrameType | None], None]) -> Iterator[None]:
    """SIGINT and SIGTERM call `handler` inside the block; the handlers before it are put back after."""
    previous = {sig: signal.signal(sig, handler) for sig in SIGNALS}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
