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
from types import FrameType, ModuleType

STOPPING = "stopping: writing what is finished first"
SIGNALS = (signal.SIGINT, signal.SIGTERM)
"""The stops a command handles (a terminal's Ctrl-C, a kill)."""


class StopSignals:
    """The stop signals' state in one place, and the handler that the CLI installs for them (the
    object itself: `signal.signal(sig, STOPS)`): one per process, `STOPS`."""

    def __init__(self) -> None:
        self.received = 0
        """Stop signals since `catch_signals` (or a stop noted elsewhere, `note_stop`)."""
        self.deferring = 0
        """How many `deferred` blocks are open: a first signal inside one waits for the last."""
        self.pending = False
        """A first signal arrived inside a `deferred` block and waits for its end."""
        self.held = False
        """A signal arrived while they were held (`hold_signals`), before the command started."""
        self.raised = False
        """The first signal raised KeyboardInterrupt (`raise_if_stopped` raises it again)."""

    def hold_signals(self) -> None:
        """SIGINT and SIGTERM only noted until `catch_signals`: the `drivestack` entry point calls
        this first, so a stop while the command line is still being imported ends the command with
        exit 130 before it does anything (not with SIGTERM's default exit 143, or a traceback from
        the import)."""

        def noted(signum: int, frame: FrameType | None) -> None:
            self.held = True

        for sig in SIGNALS:
            signal.signal(sig, noted)

    def catch_signals(self) -> bool:
        """Install this handler for SIGINT and SIGTERM (the CLI does, once, before any command);
        whether a stop came while they were held (`hold_signals`): the command then does nothing."""
        self.received, self.pending, self.raised = 0, False, False
        for sig in SIGNALS:
            signal.signal(sig, self)
        sys.unraisablehook = self.unraisable
        held, self.held = self.held, False
        return held

    def received_stop(self) -> bool:
        """Whether a stop was asked for (the command then ends with exit code 130)."""
        return self.received > 0

    def note_stop(self) -> None:
        """A stop asked for elsewhere (training's own handler): the command ends with exit code
        130, and a later signal, once these handlers are back, only waits like a second one."""
        self.received = max(self.received, 1)

    def raise_if_stopped(self) -> None:
        """KeyboardInterrupt again if a stop was raised before. Python ignores an exception raised
        in a finalizer or a `__del__` (`unraisable` keeps it from printing it), so the first
        signal's KeyboardInterrupt is lost when it lands in one; work that runs item by item calls this
        before each item, so that stop still ends the work there."""
        if self.raised:
            raise KeyboardInterrupt

    def unraisable(self, unraisable: sys.UnraisableHookArgs) -> None:
        """`sys.unraisablehook`: a first signal's KeyboardInterrupt lost in a finalizer is not
        printed as "Exception ignored ... Traceback" (`raise_if_stopped` raises it again at the next
        item); anything else goes to Python's own hook."""
        if not (self.raised and isinstance(unraisable.exc_value, KeyboardInterrupt)):
            sys.__unraisablehook__(unraisable)

    def interrupt(self) -> None:
        self.raised = True
        raise KeyboardInterrupt

    def __call__(self, signum: int, frame: FrameType | None) -> None:
        """The handler: the first signal interrupts at once, unless a `deferred` block holds it."""
        self.received += 1
        if self.received == 1 and not self.deferring:
            self.interrupt()
        if self.received == 1:
            self.pending = True
        print(STOPPING, file=sys.stderr)

    @contextmanager
    def deferred(self, interrupt_after: bool = True) -> Iterator[None]:
        """Signals wait until the block is done. A first signal that arrived meanwhile is raised as
        KeyboardInterrupt when it ends, if `interrupt_after` (a step inside the work), else only
        noted (the last write of a command, which then exits 130)."""
        self.deferring += 1
        try:
            yield
        finally:
            self.deferring -= 1
        if self.pending and not self.deferring:
            self.pending = False
            if interrupt_after:
                self.interrupt()

    @contextmanager
    def stopped_by(self, stop: Callable[[], bool]) -> Iterator[None]:
        """For work that stops itself cleanly when asked (Ray Tune's loop): inside the block the
        first SIGINT or SIGTERM calls `stop`, which returns False when the work cannot be asked yet
        (the signal then raises KeyboardInterrupt, as outside); later signals only say that the
        command stops. A stop that waits (`deferred`) is raised at once: the work never starts."""
        if self.pending:
            raise KeyboardInterrupt

        def asked(signum: int, frame: FrameType | None) -> None:
            self.received += 1
            if self.received > 1:
                print(STOPPING, file=sys.stderr)
            elif not stop():
                raise KeyboardInterrupt

        with handled_by(asked):
            yield


STOPS = StopSignals()
"""This process's stop signals."""


def _field(name: str) -> property:
    """A module attribute that reads and sets `STOPS`' field `name`."""
    return property(lambda module: getattr(STOPS, name), lambda module, value: setattr(STOPS, name, value))


class _StopSignalsModule(ModuleType):
    """This module, whose names of the state before it was one object read and set `STOPS`' fields,
    so code (and a test) that sets one still sets the one state."""

    _received = _field("received")
    _deferring = _field("deferring")
    _pending = _field("pending")
    _held = _field("held")
    _raised = _field("raised")


sys.modules[__name__].__class__ = _StopSignalsModule
_handler = STOPS
hold_signals = STOPS.hold_signals
catch_signals = STOPS.catch_signals
received = STOPS.received_stop
note_stop = STOPS.note_stop
raise_if_stopped = STOPS.raise_if_stopped
deferred = STOPS.deferred
stopped_by = STOPS.stopped_by


def ignore_signals() -> None:
    """SIGINT and SIGTERM ignored from now on: the command's work is done and its exit code set.
    (At exit Python puts the default action back for signals it handles, so a signal during the
    interpreter's teardown would otherwise end the process with -SIGTERM instead of its code.)"""
    for sig in SIGNALS:
        signal.signal(sig, signal.SIG_IGN)


@contextmanager
def handled_by(handler: Callable[[int, FrameType | None], None]) -> Iterator[None]:
    """SIGINT and SIGTERM call `handler` inside the block; the handlers before it are put back after."""
    previous = {sig: signal.signal(sig, handler) for sig in SIGNALS}
    try:
        yield
    finally:
        for sig, old in previous.items():
            signal.signal(sig, old)
