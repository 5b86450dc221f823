"""Shared fixtures. Torch runs one thread per process here (as the trainer does): on a 2-core machine
the suite's processes already share the cores, and two torch threads waiting on each other made
the tiny networks' steps several times slower (a pre-training test: 45 s -> 4 s). Set before any
test module imports torch; subprocesses inherit it. Results do not depend on it."""

import os
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OMP_NUM_THREADS", "1")

import pytest

from common.numba_cache import CACHE_FOLDER
from stack.runtime import interrupts
from stack.settings.run import build_config
from tests.kernel_warmup import PARTS

WARM_STAMP = CACHE_FOLDER / "suite-warm"
"""Written once `tests.kernel_warmup` compiled this version's kernels into the cache."""


def pytest_sessionstart(session: pytest.Session) -> None:
    """Before pytest-xdist's workers start (its own hook runs last), compile the kernels once,
    one warm-up part on each core (`tests.kernel_warmup`), unless this version's cache is warm: each
    worker would otherwise compile them itself on a cold cache, both at once. Serial runs and the
    workers themselves skip it."""
    config = session.config
    if hasattr(config, "workerinput") or config.getoption("dist", "no") == "no" or WARM_STAMP.exists():
        return
    started = time.perf_counter()
    root = Path(__file__).resolve().parent.parent
    errors = {part: tempfile.TemporaryFile() for part in PARTS}
    parts = {
        part: subprocess.Popen(
            [sys.executable, "-m", "tests.kernel_warmup", part],
            cwd=root,
            stdout=subprocess.DEVNULL,
            stderr=errors[part],
        )
        for part in PARTS
    }
    failed = [part for part, process in parts.items() if process.wait() != 0]
    for part in failed:
        errors[part].seek(0)
        last = (errors[part].read().decode(errors="replace").strip().splitlines() or ["no output"])[-1]
        sys.stderr.write(f"kernel warm-up {part!r} failed (exit {parts[part].returncode}): {last}\n")
    if not failed:
        WARM_STAMP.parent.mkdir(parents=True, exist_ok=True)
        WARM_STAMP.write_text(f"{time.perf_counter() - started:.1f} s\n")


@pytest.fixture(autouse=True, scope="session")
def sb3_logs_in_the_session_s_temp(tmp_path_factory: pytest.TempPathFactory) -> None:
    """Models a test builds without a log folder log into the session's temporary folder: left to
    SB3, each made an empty `SB3-<time>` folder in the system's temp directory."""
    os.environ.setdefault("SB3_LOGDIR", str(tmp_path_factory.mktemp("sb3")))


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


@pytest.fixture(scope="module")
def local_ray():
    """One local 2-CPU Ray instance for the module (shut down after it, so no later test meets a
    running instance); `--ray local` reuses it."""
    ray = pytest.importorskip("ray")
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield
    ray.shutdown()
