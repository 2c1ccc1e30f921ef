"""The test-only pause point (NLOSFW_TEST_PAUSE) the other hostile tests hold runs at: it
holds a run until released, and does nothing at all without the variable."""

from __future__ import annotations

import itertools
import json
import os
import threading

import pytest

from nlosfw.pipeline import pause
from nlosfw.pipeline.pause import ENV, PauseTimeout, pause_point


def no_sleep(seconds: float) -> None:
    raise AssertionError("pause_point waited")


def test_inert_without_the_variable_or_for_another_point(tmp_path, monkeypatch):
    monkeypatch.setattr(pause, "sleep", no_sleep)
    monkeypatch.delenv(ENV, raising=False)
    for point in ("capture", "fit", "capture.hdf5"):
        pause_point(point)
    monkeypatch.setenv(ENV, f"fit:{tmp_path / 'p'}")
    pause_point("capture")
    pause_point("fit.hdf5")
    monkeypatch.setenv(ENV, "")
    pause_point("capture")
    assert list(tmp_path.iterdir()) == []


def test_a_run_without_the_variable_never_waits(workdir, tools, monkeypatch):
    monkeypatch.setattr(pause, "sleep", no_sleep)
    monkeypatch.delenv(ENV, raising=False)
    result = tools.run(*tools.QUICK, "hydra.run.dir=run")
    assert result.returncode == 0, result.stderr
    assert json.loads((workdir / "run" / "metrics.json").read_text())["status"] == "completed"


def test_the_point_waits_until_released(tmp_path, monkeypatch):
    """It polls until ``release`` exists (here created by the fifth poll), having said
    that it was reached (its process id in ``reached``)."""
    folder = tmp_path / "p"
    monkeypatch.setenv(ENV, f"capture:{folder}")
    polls: list[bool] = []

    def poll(seconds: float) -> None:
        assert (folder / "reached").read_text() == f"{os.getpid()}\n"
        polls.append(True)
        if len(polls) == 5:
            (folder / "release").touch()

    monkeypatch.setattr(pause, "sleep", poll)
    pause_point("capture")
    assert len(polls) == 5
    monkeypatch.setattr(pause, "sleep", no_sleep)
    pause_point("capture")                       # once released, passed at once


def test_a_point_never_released_fails_with_what_it_waited_for(tmp_path, monkeypatch):
    folder = tmp_path / "p"
    monkeypatch.setenv(ENV, f"fit:{folder}")
    clock = itertools.count(0.0, 100.0)        # each look at the clock: 100 s later
    monkeypatch.setattr(pause, "monotonic", lambda: next(clock))
    monkeypatch.setattr(pause, "sleep", lambda seconds: None)
    with pytest.raises(PauseTimeout) as caught:
        pause_point("fit")
    assert str(caught.value) == (f"{ENV}: held at fit for 600 s and {folder / 'release'} was "
                                 "not created; giving up")


def test_a_thread_held_at_the_point_goes_on_when_released(tmp_path, monkeypatch):
    folder = tmp_path / "p"
    monkeypatch.setenv(ENV, f"report:{folder}")
    passed = threading.Event()

    def held() -> None:
        pause_point("report")
        passed.set()

    thread = threading.Thread(target=held, daemon=True)
    thread.start()
    while not (folder / "reached").exists():
        assert thread.is_alive(), "the thread ended without reaching the pause point"
        thread.join(0.05)
    assert not passed.is_set()
    (folder / "release").touch()
    thread.join(600)
    assert passed.is_set(), "the thread was not released within 600 s"


def test_a_run_held_in_its_capture_stage_goes_on_when_released(workdir, tools):
    run = workdir / "run"
    proc, folder = tools.start_held("capture", *tools.QUICK, "hydra.run.dir=run", cwd=workdir)
    try:
        tools.wait_held(folder, proc)
        assert "stage capture: started" in (run / "run.log").read_text()
        assert not (run / "capture.hdf5").exists() and not (run / "metrics.json").exists()
        assert proc.poll() is None
    finally:
        tools.release(folder)
        status, out, err = tools.finish(proc)
    assert status == 0, err
    assert json.loads((run / "metrics.json").read_text())["status"] == "completed"
