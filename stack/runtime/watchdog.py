"""A local Ray instance ends with its command, even when the command is killed (SIGKILL, the OOM
killer). Linux ends Ray's GCS and raylet with the command, but the agents the raylet started wait a
minute for the dead GCS before they exit.

The watchdog is a small separate process (its own session: deaf to a terminal's Ctrl-C) that notes
the command's process tree every `PERIOD_S` and, once the command is gone (the pipe from it ends,
however it ended), kills every process of that tree still alive. The tree, not a mark in the
processes' environment: Ray's processes set their titles over it. Linux only (/proc); standard
library only: this file is run as a script, without importing the package.
"""

from __future__ import annotations

import os
import select
import signal
import subprocess
import sys
from pathlib import Path

PERIOD_S = 1.0
"""How often the watchdog notes the command's process tree [s] (about 0.5 % of a core)."""

_watchdog: list[tuple[subprocess.Popen, int]] = []
"""The watchdog and the write end of the pipe to it, never closed: the kernel closes it when this
process ends, after every exit handler (Ray's own shutdown included), which tells the watchdog."""


def watch_descendants() -> None:
    """Start the watchdog of this process's descendants (once per process; Linux only, where /proc
    tells the process tree)."""
    if _watchdog or not Path(f"/proc/{os.getpid()}/task").is_dir():
        return
    read, write = os.pipe()
    watchdog = subprocess.Popen(
        [sys.executable, "-I", __file__, str(os.getpid())],
        stdin=read,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
        start_new_session=True,
    )
    os.close(read)
    _watchdog.append((watchdog, write))


def descendants(pid: int) -> list[int]:
    """The pids of every process below `pid` (children, theirs, ...), from /proc."""
    found: list[int] = []
    try:
        threads = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return found
    for thread in threads:
        try:
            children = Path(f"/proc/{pid}/task/{thread}/children").read_text().split()
        except OSError:
            continue
        for child in map(int, children):
            found += [child, *descendants(child)]
    return found


def started(pid: int) -> str | None:
    """When process `pid` started (clock ticks since boot), None when there is none: with the pid it
    names one process, even after the pid is reused."""
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[19]
    except (OSError, IndexError):
        return None


def watch(command: int) -> None:
    """Note `command`'s descendants until standard input ends, then kill those still alive."""
    seen: dict[int, str | None] = {}
    while True:
        ready, _, _ = select.select([0], [], [], PERIOD_S)
        if ready and not os.read(0, 4096):
            break
        for pid in descendants(command):
            if pid != os.getpid():
                seen.setdefault(pid, started(pid))
    for pid, start in seen.items():
        if start is not None and started(pid) == start:
            try:
                os.kill(pid, signal.SIGKILL)
            except OSError:
                pass


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    watch(int(sys.argv[1]))
