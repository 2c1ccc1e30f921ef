"""The one timing rule of the benchmarks: the best of several wall-clock runs; and the
machine a result was measured on, as every results file records it.

The machines' cores are shared, so the minimum over repeats is the least disturbed
measurement. Scripts in this folder import them as ``from timing import best_of, machine``.
"""

from __future__ import annotations

import os
import platform
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


def machine(**extra: object) -> dict[str, object]:
    """The machine of a results file: its CPUs, platform and Python, then ``extra`` (the
    versions of the libraries measured, a note)."""
    return {"cpus": os.cpu_count(), "platform": platform.platform(),
            "python": platform.python_version(), **extra}
