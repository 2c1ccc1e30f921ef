"""fit_beside: one long fit in a second thread beside short ones in this one."""

from __future__ import annotations

import threading
import time

from nlosfw.model import TrainingStep
from nlosfw.model.hybrid.beside import fit_beside


def _step(k: int) -> TrainingStep:
    return TrainingStep(step=k, total_steps=50, loss=1.0 / k)


def test_on_alone_is_called_once_in_the_long_fits_thread_after_the_short_fits():
    """The short fit waits for the long fit's first step, so that step comes before the
    short fits end: ``on_alone`` is not called there, but once, at a later step, in the long
    fit's thread; every step still reaches ``on_step`` here, in order."""
    first_step = threading.Event()
    short_ended: list[float] = []
    calls: list[tuple[str, int, bool]] = []
    steps_taken: list[int] = []
    seen: list[tuple[int, str]] = []

    def long(on_step):
        for k in range(1, 51):
            steps_taken.append(k)
            on_step(_step(k))
            first_step.set()
            time.sleep(0.005)
        return "long"

    def short(on_step):
        first_step.wait(10)
        short_ended.append(time.perf_counter())
        return "short"

    def on_alone():
        calls.append((threading.current_thread().name, steps_taken[-1], bool(short_ended)))

    outcomes = fit_beside(("volume", long), {"a": short, "b": lambda on_step: "b"},
                          lambda s: seen.append((s.step, threading.current_thread().name)),
                          name="test-long", on_alone=on_alone)
    assert outcomes == {"a": "short", "b": "b", "volume": "long"}
    assert len(calls) == 1, calls
    thread, step, after_short = calls[0]
    assert thread == "test-long" and after_short and 1 < step <= 50, calls
    assert [k for k, _ in seen] == list(range(1, 51))
    assert {name for _, name in seen} == {threading.current_thread().name}


def test_on_alone_is_not_called_when_the_long_fit_ends_first():
    """A long fit that takes no step after the short fits end never hears of it."""
    calls: list[int] = []
    short_may_end = threading.Event()

    def long(on_step):
        on_step(_step(1))
        short_may_end.set()
        return "long"

    def short(on_step):
        short_may_end.wait(10)
        time.sleep(0.05)
        return "short"

    outcomes = fit_beside(("volume", long), {"a": short}, None,
                          on_alone=lambda: calls.append(1))
    assert outcomes == {"a": "short", "volume": "long"} and calls == []
