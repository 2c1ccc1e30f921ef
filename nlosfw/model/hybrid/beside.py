"""One long fit in a second thread beside others in this one.

:func:`fit_beside` runs the long fit (the ensemble's neural volume, which trains on one
core) in a thread of its own while the short ones (its ``rsd_prior`` members) run one after
another in the calling thread. Every step the long fit reports reaches ``on_step`` from the
calling thread (queued, passed on between and after the short fits), and if the calling
thread stops (an error, an interrupt), the long fit stops at its next step: nothing is left
running. A fit's FitError is its outcome; any other error is raised.
"""

from __future__ import annotations

import contextvars
import queue
import threading
from collections.abc import Callable, Mapping
from typing import TypeVar

from nlosfw.common.errors import FitError
from nlosfw.model.interface import TrainingStep

T = TypeVar("T")
StepCallback = Callable[[TrainingStep], None] | None
#: A fit: called with the ``on_step`` it reports its steps to.
Fit = Callable[[StepCallback], T]


class _Abandoned(Exception):
    """Raised in the long fit's thread at its next step once the calling thread stopped."""


def attempt(fit: Fit[T], on_step: StepCallback) -> T | FitError:
    """``fit(on_step)``, or the FitError it raised."""
    try:
        return fit(on_step)
    except FitError as err:
        return err


def fit_beside(long: tuple[str, Fit[T]], short: Mapping[str, Fit[T]],
               on_step: StepCallback, name: str = "nlosfw-fit",
               on_alone: Callable[[], None] | None = None) -> dict[str, T | FitError]:
    """Each fit's outcome by label: ``long`` = (label, fit) in a thread named ``name``,
    the ``short`` ones in order in this thread (their own steps are not reported);
    ``on_alone``, if given, is called in the long fit's thread at its first step after the
    short ones end."""
    steps: queue.SimpleQueue[TrainingStep] = queue.SimpleQueue()
    stop, short_ended = threading.Event(), threading.Event()
    alone = on_alone                  # until it is called, in the long fit's thread

    def long_step(step: TrainingStep) -> None:
        nonlocal alone
        if stop.is_set():
            raise _Abandoned
        if alone is not None and short_ended.is_set():
            call, alone = alone, None
            call()
        steps.put(step)

    def pass_on(_: TrainingStep | None = None) -> None:
        while True:
            try:
                step = steps.get_nowait()
            except queue.Empty:
                return
            if on_step is not None:
                on_step(step)

    ended: list[T | FitError | BaseException] = []      # the long fit's outcome

    def run_long() -> None:
        try:
            ended.append(attempt(long[1], long_step))
        except BaseException as err:    # handed to the calling thread, which raises it
            ended.append(err)

    thread = threading.Thread(target=contextvars.copy_context().run, args=(run_long,),
                              daemon=True, name=name)
    thread.start()
    try:
        outcomes = {label: attempt(fit, pass_on) for label, fit in short.items()}
        short_ended.set()
        while thread.is_alive():
            thread.join(timeout=0.2)
            pass_on()
        pass_on()
    finally:
        stop.set()
        thread.join()
    result = ended.pop()
    if isinstance(result, BaseException) and not isinstance(result, FitError):
        raise result
    outcomes[long[0]] = result
    return outcomes
