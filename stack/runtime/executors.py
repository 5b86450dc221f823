"""Where independent work items run: here, over local processes (`jobs`) or as Ray tasks (`ray`,
an address). Results come back as they finish, tagged with their item's index, so a caller can show
progress at once and still aggregate in item order: the outcome never depends on what ran where.
Ctrl-C (or the caller dropping the iterator) cancels the items not yet started."""

from __future__ import annotations

import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Generator, Iterator, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from itertools import islice
from multiprocessing import get_context
from typing import TypeVar

from stack.runtime.interrupts import deferred, raise_if_stopped
from stack.runtime.machine import usable_cpus

Item = TypeVar("Item")
Result = TypeVar("Result")

QUEUED_PER_WORKER = 2
"""Items submitted per worker ahead of the results: keeps every worker busy, bounds what waits."""
WATCH_PERIOD_S = 1.0
"""How often a pool worker checks that its parent is alive [s] (where the system cannot tell it)."""


PR_SET_PDEATHSIG = 1
"""prctl option: the signal a process gets when its parent dies (linux/prctl.h)."""

_kept_pools: dict[int, ProcessPoolExecutor] | None = None
"""Within `shared_workers`: the pools made so far, by worker count, for the next `completed`."""


@contextmanager
def shared_workers() -> Iterator[None]:
    """Within it, `completed` keeps its pool of workers for the next call with as many workers, so
    work in several parts (a comparison's agents) starts its processes once; they end on leaving.
    Results do not change: a worker keeps nothing that an item's result depends on."""
    global _kept_pools
    if _kept_pools is not None:
        yield
        return
    _kept_pools = {}
    try:
        yield
    finally:
        pools, _kept_pools = _kept_pools, None
        for pool in pools.values():
            pool.shutdown(wait=True, cancel_futures=True)


def completed(
    task: Callable[[Item], Result], items: Sequence[Item], jobs: int = 1, ray: str | None = None
) -> Generator[tuple[int, Result], None, None]:
    """(index, task(item)) for every item, in completion order: with `ray` (`local`, `auto` or
    HOST:PORT) as Ray tasks, else over `jobs` spawned processes (1: one after the other, here)."""
    if ray is not None:
        from stack.runtime.ray_tasks import ray_completed

        yield from ray_completed(task, items, ray)
    elif jobs <= 1 or len(items) <= 1:
        for index, item in enumerate(items):
            raise_if_stopped()
            yield index, task(item)
    else:
        yield from _pool_completed(task, items, jobs)


def _pool_completed(
    task: Callable[[Item], Result], items: Sequence[Item], jobs: int
) -> Iterator[tuple[int, Result]]:
    """`completed` over a pool of `jobs` spawned processes (fresh interpreters: no state shared),
    at most one per usable CPU. Items are submitted as workers free up (a few queued ahead), so a
    long run costs no memory for items not yet started. If the caller stops early (Ctrl-C), the
    workers are ended at once instead of finishing their items."""
    workers = min(jobs, usable_cpus(), len(items))
    queue = iter(enumerate(items))
    pool = _pool(workers)
    running: dict[Future[Result], int] = {}
    finished = False
    try:
        for index, item in islice(queue, QUEUED_PER_WORKER * workers):
            running[_submitted(pool, task, item)] = index
        while running:
            raise_if_stopped()
            done, _ = wait(running, return_when=FIRST_COMPLETED)
            for future in done:
                index = running.pop(future)
                for following, item in islice(queue, 1):
                    running[_submitted(pool, task, item)] = following
                yield index, future.result()
        finished = True
    finally:
        if not finished:
            _end_workers(pool)
            if _kept_pools is not None:
                _kept_pools.pop(workers, None)
        if not finished or _kept_pools is None:
            pool.shutdown(wait=True, cancel_futures=True)


def _submitted(pool: ProcessPoolExecutor, task: Callable[[Item], Result], item: Item) -> Future[Result]:
    """`pool.submit(task, item)` with stops held back meanwhile: a worker the submit spawns is
    handed its start-up whole (a stop in the middle left it reading half of it: a traceback), and
    starts with SIGINT blocked, so a Ctrl-C to the process group while its interpreter starts
    (before `_worker_start` ignores it) is no traceback either; a stop held back is raised after."""
    with deferred():
        if not hasattr(signal, "pthread_sigmask"):
            return pool.submit(task, item)
        held = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
        try:
            return pool.submit(task, item)
        finally:
            signal.pthread_sigmask(signal.SIG_SETMASK, held)


def _pool(workers: int) -> ProcessPoolExecutor:
    """A pool of `workers` spawned processes: the one `shared_workers` kept, or a new one."""
    pool = None if _kept_pools is None else _kept_pools.get(workers)
    if pool is None:
        pool = ProcessPoolExecutor(
            max_workers=workers,
            mp_context=get_context("spawn"),
            initializer=_worker_start,
            initargs=(os.getpid(),),
        )
        if _kept_pools is not None:
            _kept_pools[workers] = pool
    return pool


def _end_workers(pool: ProcessPoolExecutor) -> None:
    """Kill `pool`'s worker processes (the executor has no public way before Python 3.14)."""
    for process in list(getattr(pool, "_processes", {}).values()):
        process.kill()


def _worker_start(parent: int) -> None:
    """A pool worker's first act: deaf to Ctrl-C (a terminal sends it to the whole process group;
    the parent stops the run and ends the workers, no worker traceback), and ends when its parent
    dies, even by SIGKILL: the kernel tells it on Linux (PR_SET_PDEATHSIG), a watchdog thread
    elsewhere. One thread for torch's operators (and any OpenMP library): a worker is one of `jobs`
    processes sharing the cores, and idle operator threads spinning beside the others' cost ~57 %
    more CPU time on 2 cores (`drivestack compare`, 4 agents x 200 episodes: 71.7 s user, not 45.7)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    if sys.platform.startswith("linux"):
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    if os.getppid() != parent:
        os._exit(1)
    threading.Thread(target=_watch_parent, args=(parent,), daemon=True).start()


def _watch_parent(parent: int) -> None:
    """End this process once `parent` is no longer its parent (it died: the process was re-parented)."""
    while os.getppid() == parent:
        time.sleep(WATCH_PERIOD_S)
    os._exit(1)
