"""Where independent work items run: here, over local processes (`jobs`) or as Ray tasks (`ray`,
an address). Results come back as they finish, tagged with their item's index, so a caller can show
progress at once and still aggregate in item order: the outcome never depends on what ran where.
Ctrl-C (or the caller dropping the iterator) cancels the items not yet started."""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from multiprocessing import get_context
from typing import TypeVar

Item = TypeVar("Item")
Result = TypeVar("Result")


def completed(
    task: Callable[[Item], Result], items: Sequence[Item], jobs: int = 1, ray: str | None = None
) -> Iterator[tuple[int, Result]]:
    """(index, task(item)) for every item, in completion order: with `ray` (`local`, `auto` or
    HOST:PORT) as Ray tasks, else over `jobs` spawned processes (1: one after the other, here)."""
    if ray is not None:
        from stack.core.ray_tasks import ray_completed

        yield from ray_completed(task, items, ray)
    elif jobs <= 1 or len(items) <= 1:
        for index, item in enumerate(items):
            yield index, task(item)
    else:
        yield from _pool_completed(task, items, jobs)


def _pool_completed(
    task: Callable[[Item], Result], items: Sequence[Item], jobs: int
) -> Iterator[tuple[int, Result]]:
    """`completed` over a pool of `jobs` spawned processes (fresh interpreters: no state shared)."""
    with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as pool:
        futures: dict[Future[Result], int] = {pool.submit(task, item): i for i, item in enumerate(items)}
        try:
            for future in as_completed(futures):
                yield futures[future], future.result()
        finally:
            for future in futures:
                future.cancel()
