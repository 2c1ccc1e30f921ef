"""Progress reports from long computations, without any display library.

A plugin method that can run for long (an imager's ``reconstruct``) takes an optional
keyword ``on_progress``: a :data:`ProgressCallback` it calls as ``on_progress(done,
total)`` each time a block of its work finishes (a depth plane, a block of voxels). The
caller decides how to show it (the command line draws a rich progress bar); the plugin
imports nothing for it. Plugins written before the keyword existed keep working: the
caller checks with :func:`accepts_progress` whether a method takes it.
"""

from __future__ import annotations

import inspect
import threading
from collections.abc import Callable
from typing import Any

#: ``on_progress(done, total)``: ``done`` of ``total`` units of work have finished
#: (0 <= done <= total, non-decreasing, the last call has done == total).
ProgressCallback = Callable[[int, int], None]


def accepts_progress(method: Callable[..., Any]) -> bool:
    """Whether ``method`` takes the keyword argument ``on_progress``."""
    try:
        parameters = inspect.signature(method).parameters
    except (TypeError, ValueError):
        return False
    return "on_progress" in parameters or any(
        p.kind is inspect.Parameter.VAR_KEYWORD for p in parameters.values())


class ProgressCounter:
    """Counts finished units of work (from any thread) and reports each step to a callback.

    ``ProgressCounter(total, on_progress)``; ``advance(n)`` after n more units finish.
    With ``on_progress=None`` it only counts.
    """

    def __init__(self, total: int, on_progress: ProgressCallback | None) -> None:
        self.total = int(total)
        self.done = 0
        self._on_progress = on_progress
        self._lock = threading.Lock()

    def advance(self, units: int = 1) -> None:
        """Record ``units`` more finished units and report the new count."""
        with self._lock:
            self.done = min(self.total, self.done + int(units))
            if self._on_progress is not None:
                self._on_progress(self.done, self.total)
