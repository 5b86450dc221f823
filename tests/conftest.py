"""Shared fixtures. Torch runs one thread per process here (as the trainer does): on a 2-core machine
the suite's processes already share the cores, and two torch threads waiting on each other made
the tiny networks' steps several times slower (a pre-training test: 45 s -> 4 s). Set before any
test module imports torch; subprocesses inherit it. Results do not depend on it."""

import os
import signal

os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest

from stack.runtime import interrupts
from stack.settings.run import build_config


@pytest.fixture
def tiny_config():
    """A short, sparse run: 8 s episodes with 15 vehicles."""
    return build_config(
        {"episodes": 1, "highway": {"vehicles_count": 15, "duration": 8}},
        "tiny",
    )


@pytest.fixture
def own_handlers():
    """The test process's SIGINT and SIGTERM handlers and the interrupt state
    (`stack.runtime.interrupts`), put back after a test that sends itself signals."""
    saved = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    interrupts.catch_signals()
    for sig, handler in saved.items():
        signal.signal(sig, handler)
