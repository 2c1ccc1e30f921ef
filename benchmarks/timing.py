"""The one timing rule of the benchmarks: the best of several wall-clock runs.

The machines' cores are shared, so the minimum over repeats is the least disturbed
measurement. Scripts in this folder import it as ``from timing import best_of``.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from typing import TypeVar

T = TypeVar("T")


def best_of(call: Callable[[], T], repeat: int = 1) -> tuple[float, T]:
    """(minimum wall-clock seconds over ``repeat`` calls of ``call``, the last result)."""
    seconds = float("inf")
    for _ in range(max(1, repeat)):
        start = time.perf_counter()
        result = call()
        seconds = min(seconds, time.perf_counter() - start)
    return seconds, result
