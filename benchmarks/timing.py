"""The one timing rule of the benchmarks: the best of several wall-clock runs; and the
machine a result was measured on, as every results file records it; and the table of a
new code path's speed-up over its baseline, per backend.

The machines' cores are shared, so the minimum over repeats is the least disturbed
measurement. Scripts in this folder import them as ``from timing import best_of, machine``.
"""

from __future__ import annotations

import os
import platform
import time
from collections.abc import Callable, Mapping
from typing import Any, TypeVar

from rich.console import Console
from rich.table import Table

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


def print_speedups(title: str, rows: Mapping[str, Mapping[str, Any]], new: tuple[str, str]
                   ) -> None:
    """Print each backend's baseline and new seconds (``rows[backend]["baseline_s"]`` and
    the key ``new[1]``, in the column ``new[0]``), the speed-up and the gradients'
    mismatch."""
    table = Table(title=title)
    for column in ("backend", "baseline (s)", new[0], "speed-up", "gradient mismatch"):
        table.add_column(column, justify="right")
    for backend, row in rows.items():
        table.add_row(backend, f"{row['baseline_s']:.3f}", f"{row[new[1]]:.3f}",
                      f"{row['speedup']:.2f}x", f"{row['gradient_mismatch']:.1e}")
    Console().print(table)
