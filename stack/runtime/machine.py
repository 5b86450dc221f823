"""What this machine gives a run, asked in one place: its CPUs (by the process pool,
`stack.runtime.executors`, and a local Ray instance, `stack.runtime.ray_tasks`, which must not import
each other) and its available memory (by the checks before a run)."""

from __future__ import annotations

import os
from pathlib import Path


def usable_cpus() -> int:
    """The CPUs this process may run on: the most processes `jobs` starts, and a local Ray
    instance's task slots."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def available_memory_bytes() -> int | None:
    """MemAvailable of /proc/meminfo [bytes]; None where it cannot be read."""
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None
