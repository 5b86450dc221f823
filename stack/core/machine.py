"""What this machine gives a run, asked in one place by the process pool (`stack.core.executors`)
and a local Ray instance (`stack.core.ray_tasks`), which must not import each other."""

from __future__ import annotations

import os


def usable_cpus() -> int:
    """The CPUs this process may run on: the most processes `jobs` starts, and a local Ray
    instance's task slots."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1
