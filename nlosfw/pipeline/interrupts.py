"""SIGINT, SIGTERM and SIGHUP as an exception, so that a run stops cleanly.

Inside :func:`signals_raise` the signals raise
:class:`~nlosfw.common.errors.RunInterrupted` in the main thread: ``finally`` blocks
remove temporary files, the pipeline writes ``metrics.json`` with status
``interrupted`` and the stage reached, and the command line exits with 130 (SIGINT),
143 (SIGTERM) or 129 (SIGHUP: the terminal closed) after one line. Python checks for
signals between bytecodes, so a signal arriving during a long numpy or HDF5 call takes
effect when the call returns.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from collections.abc import Iterator
from types import FrameType

from nlosfw.common.errors import RunInterrupted

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def _raise(signum: int, frame: FrameType | None) -> None:
    raise RunInterrupted(signum)


@contextlib.contextmanager
def signals_raise() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise :class:`RunInterrupted` while the block runs (in the main
    thread; elsewhere the block runs unchanged), the previous handlers restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.signal(sig, _raise) for sig in SIGNALS}
    try:
        yield
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)


def as_interruption(err: BaseException) -> RunInterrupted | None:
    """``err`` as a :class:`RunInterrupted` (a bare KeyboardInterrupt is SIGINT), or None."""
    if isinstance(err, RunInterrupted):
        return err
    if isinstance(err, KeyboardInterrupt):
        return RunInterrupted(signal.SIGINT)
    return None
