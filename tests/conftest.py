"""Shared fixtures. Torch runs one thread per process here (as the trainer does): on a 2-core machine
the suite's processes already share the cores, and two torch threads waiting on each other made
the tiny networks' steps several times slower (a pre-training test: 45 s -> 4 s). Set before any
test module imports torch; subprocesses inherit it. Results do not depend on it."""

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest

from stack.core.config import build_config


@pytest.fixture
def tiny_config():
    """A short, sparse run: 8 s episodes with 15 vehicles."""
    return build_config(
        {"episodes": 1, "highway": {"vehicles_count": 15, "duration": 8}},
        "tiny",
    )
