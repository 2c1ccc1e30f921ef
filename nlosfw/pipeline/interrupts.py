"""SIGINT, SIGTERM and SIGHUP as an exception, so that a run stops cleanly.

Inside :func:`signals_raise` the signals raise
:class:`~nlosfw.common.errors.RunInterrupted` in the main thread: ``finally`` blocks
remove temporary files, the pipeline writes ``metrics.json`` with status
``interrupted`` and the stage reached, and the command line exits with 130 (SIGINT),
143 (SIGTERM) or 129 (SIGHUP: the terminal closed) after one line. Python checks for
signals between bytecodes, so a signal arriving during a long numpy or HDF5 call takes
effect when the call returns.

A signal raises once. A second one (Ctrl-C pressed twice; or a whole process group
signalled, by a terminal or SLURM's ``scancel``, while the parent of a parallel sweep
forwards the same signal to its workers) arriving while the first is being handled
(metrics.json being written, the lock released) is recorded and otherwise ignored, so
it cannot break what the first one started. The count starts again when the outermost
:func:`signals_raise` block is entered (a later run in the same process, through
:func:`nlosfw.run`, can be interrupted again).

Two hooks serve parallel sweeps (:mod:`nlosfw.cli.workers`): :func:`before_raising` lets
the parent of a sweep forward the signal to its workers and wait for them before it
raises; :func:`record_signals` lets a worker process survive a signal that arrives
between two jobs (recorded, see :func:`received`), instead of dying of it.
"""

from __future__ import annotations

import contextlib
import logging
import signal
import threading
from collections.abc import Callable, Iterator
from types import FrameType

from nlosfw.common.errors import RunInterrupted

log = logging.getLogger(__name__)

SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


class _State:
    """The process's signal bookkeeping (changed in the main thread only)."""

    depth = 0                     # how many signals_raise blocks are open
    raised: int | None = None     # the signal raised in the outermost open block
    received: int | None = None   # the last signal this process received, ever
    hooks: list[Callable[[int], None]] = []


def _raise(signum: int, frame: FrameType | None) -> None:
    _State.received = signum
    if _State.raised is not None:
        return                    # already stopping: a second signal must not break that
    _State.raised = signum
    for hook in list(_State.hooks):
        try:
            hook(signum)
        except Exception as err:  # the run must still stop
            log.error("while handling %s: %s", signal.Signals(signum).name, err)
    raise RunInterrupted(signum)


def _record(signum: int, frame: FrameType | None) -> None:
    _State.received = signum


@contextlib.contextmanager
def signals_raise() -> Iterator[None]:
    """SIGINT, SIGTERM and SIGHUP raise :class:`RunInterrupted` while the block runs (in the
    main thread; elsewhere the block runs unchanged), once (see the module), the previous
    handlers restored after."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    if _State.depth == 0:
        _State.raised = None
    previous = {sig: signal.signal(sig, _raise) for sig in SIGNALS}
    _State.depth += 1
    try:
        yield
    finally:
        _State.depth -= 1
        for sig, handler in previous.items():
            signal.signal(sig, handler)


@contextlib.contextmanager
def before_raising(hook: Callable[[int], None]) -> Iterator[None]:
    """While the block runs, the first signal handled by :func:`signals_raise` calls
    ``hook(signum)`` (in the main thread, further signals ignored) before it raises; an
    exception from ``hook`` is logged and the signal still raises."""
    _State.hooks.append(hook)
    try:
        yield
    finally:
        _State.hooks.remove(hook)


def record_signals() -> None:
    """From now on, in this process, SIGINT, SIGTERM and SIGHUP outside :func:`signals_raise`
    are recorded (:func:`received`) instead of ending the process (main thread only; does
    nothing elsewhere)."""
    if threading.current_thread() is threading.main_thread():
        for sig in SIGNALS:
            signal.signal(sig, _record)


def received() -> int | None:
    """The last of SIGINT, SIGTERM, SIGHUP this process received (handled by this module),
    or None."""
    return _State.received


def as_interruption(err: BaseException) -> RunInterrupted | None:
    """``err`` as a :class:`RunInterrupted` (a bare KeyboardInterrupt is SIGINT), or None."""
    if isinstance(err, RunInterrupted):
        return err
    if isinstance(err, KeyboardInterrupt):
        return RunInterrupted(signal.SIGINT)
    return None
