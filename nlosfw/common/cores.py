"""How many cores this process may use, and running independent tasks on them."""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable
from concurrent.futures import ThreadPoolExecutor
from typing import TypeVar

T = TypeVar("T")


def available_cores() -> int:
    """Cores this process may run on (its CPU affinity where the OS reports one)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not Linux
        return max(1, os.cpu_count() or 1)


def worker_count(workers: int) -> int:
    """Threads for a ``workers`` option: -1 means every available core."""
    return available_cores() if workers == -1 else workers


def run_tasks(task: Callable[[T], None], items: Iterable[T], threads: int) -> None:
    """``task(item)`` for every item, on up to ``threads`` threads (inline for one), one item
    per task: on an error or an interrupt, ``Executor.map`` cancels the items not yet
    started and the error is raised here."""
    if threads <= 1:
        for item in items:
            task(item)
        return
    with ThreadPoolExecutor(max_workers=threads) as pool:
        for _ in pool.map(task, items):
            pass
