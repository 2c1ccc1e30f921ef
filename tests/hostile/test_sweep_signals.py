"""A parallel sweep (Hydra's joblib launcher) interrupted: each running job ends with status
interrupted and its stage in its own metrics.json, its lock released, no other job starts,
and the command exits with 128 + the signal after one line
(:mod:`nlosfw.cli.workers`). The jobs are held at a pause point, never made slow."""

from __future__ import annotations

import json
import os
import pickle
import signal
import time
from pathlib import Path

import pytest

from nlosfw.cli import workers
from nlosfw.common.errors import RunInterrupted
from nlosfw.pipeline import interrupts
from nlosfw.pipeline.lifecycle import LOCK_NAME
from nlosfw.pipeline.pause import ENV as PAUSE_ENV

#: The quick run, swept over three seeds on the joblib launcher (two worker processes).
SWEEP = ("-m", "hydra/launcher=parallel", "scene=tiny", "model=interp", "imager=fft",
         "figures.enabled=false", "transform.n_frequencies=21", "reconstruction.n_depths=4")


def start_sweep(workdir: Path, tools, *overrides: str):
    """The sweep started in the background (its own session), its jobs to be held when
    their capture stage starts; the process, the pause folder, the sweep folder and the
    temporary folder its processes use."""
    pause, sweep, tmp = workdir / "pause", workdir / "sweep", workdir / "tmp"
    tmp.mkdir()
    proc = tools.start_run(*SWEEP, *overrides, f"hydra.sweep.dir={sweep}", cwd=workdir,
                           env={PAUSE_ENV: f"capture:{pause}", "TMPDIR": str(tmp)})
    return proc, pause, sweep, tmp


def wait_jobs_held(pause: Path, proc, count: int, timeout: float = 600.0) -> list[int]:
    """Wait until ``count`` worker processes are held at the pause point (each has written
    ``reached-<pid>``); their process ids. Fails saying so when the sweep ends first or
    ``timeout`` seconds pass."""
    deadline = time.monotonic() + timeout
    while len(held := sorted(pause.glob("reached-*"))) < count:
        if proc.poll() is not None:
            out, err = proc.communicate()
            raise AssertionError(f"the sweep (exit status {proc.returncode}) ended before "
                                 f"{count} jobs reached the pause point:\n{out}\n{err}")
        if time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            out, err = proc.communicate()
            raise AssertionError(f"{len(held)} of {count} jobs reached the pause point "
                                 f"({pause}/reached-<pid>) within {timeout:.0f} s:\n{out}\n"
                                 f"{err}")
        time.sleep(0.05)
    return [int(p.name.removeprefix("reached-")) for p in held]


def wait_gone(pids: list[int], timeout: float = 600.0) -> None:
    """Wait until none of ``pids`` runs any more (gone, or a zombie awaiting its reaper)."""
    deadline = time.monotonic() + timeout
    for pid in pids:
        while True:
            try:
                state = Path(f"/proc/{pid}/stat").read_text().rpartition(")")[2].split()[0]
            except OSError:
                break
            if state in ("Z", "X"):
                break
            assert time.monotonic() < deadline, f"worker {pid} still runs {timeout:.0f} s on"
            time.sleep(0.05)


def assert_interrupted(sweep: Path, jobs: int, name: str) -> None:
    for n in range(jobs):
        metrics = json.loads((sweep / str(n) / "metrics.json").read_text())
        assert metrics["status"] == "interrupted", (n, metrics["status"])
        assert metrics["error"] == {"stage": "capture", "message": f"interrupted by {name}",
                                    "signal": name}
    assert list(sweep.rglob(LOCK_NAME)) == []


def test_sigterm_to_the_parent_ends_each_running_job_with_its_status(workdir, tools):
    """Three jobs, two workers: the two running jobs end as interrupted at the capture
    stage, the third (queued) never starts, the parent alone was signalled."""
    proc, pause, sweep, tmp = start_sweep(workdir, tools, "simulator.seed=0,1,2")
    try:
        pids = wait_jobs_held(pause, proc, 2)
    except BaseException:
        tools.release(pause)
        raise
    assert proc.pid not in pids and len(set(pids)) == 2     # two worker processes
    status, out, err = tools.stop(proc, signal.SIGTERM)
    assert status == 143, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines == ["interrupted by SIGTERM: stopped cleanly (exit status 143)"], err
    assert_interrupted(sweep, 2, "SIGTERM")
    assert not (sweep / "2").exists(), "the queued third job was started"
    assert not tools.temporaries(sweep) and not tools.temporaries(workdir / "cache")
    assert list(tmp.glob("nlosfw-sweep-*")) == []          # the registration folder
    if Path("/proc/self/stat").exists():
        wait_gone(pids)


def test_sigint_to_the_whole_group_reaches_each_worker_twice_harmlessly(workdir, tools):
    """Ctrl-C in a terminal: every process of the group gets SIGINT, the workers once
    more from the parent; each job still ends interrupted with its metrics whole."""
    proc, pause, sweep, _ = start_sweep(workdir, tools, "simulator.seed=0,1")
    try:
        wait_jobs_held(pause, proc, 2)
    except BaseException:
        tools.release(pause)
        raise
    os.killpg(proc.pid, signal.SIGINT)
    status, out, err = tools.finish(proc, 600.0, "stop after SIGINT to its process group")
    assert status == 130, err
    lines = [line for line in err.splitlines() if line.strip()]
    assert lines == ["interrupted by SIGINT: stopped cleanly (exit status 130)"], err
    assert_interrupted(sweep, 2, "SIGINT")


# ------------------------------------------------------------------ unit level
@pytest.fixture()
def handlers():
    """The signal handlers of this process restored after the test."""
    saved = {sig: signal.getsignal(sig) for sig in interrupts.SIGNALS}
    yield
    for sig, handler in saved.items():
        signal.signal(sig, handler)


def test_a_second_signal_while_stopping_is_recorded_not_raised(handlers):
    """The handler raises once per outermost block: a second SIGTERM while the first is
    handled (metrics being written) is recorded only; a later block raises again."""
    calls: list[int] = []
    with interrupts.signals_raise(), interrupts.before_raising(calls.append):
        with pytest.raises(RunInterrupted) as first, interrupts.signals_raise():
            signal.raise_signal(signal.SIGTERM)
        assert first.value.signum == signal.SIGTERM
        signal.raise_signal(signal.SIGHUP)      # while "writing metrics": no exception
        assert interrupts.received() == signal.SIGHUP
    assert calls == [signal.SIGTERM]            # the hook ran once, before the raise
    with pytest.raises(RunInterrupted) as again, interrupts.signals_raise():
        signal.raise_signal(signal.SIGINT)
    assert again.value.signum == signal.SIGINT


def test_an_interruption_crosses_processes_whole():
    """A worker's RunInterrupted reaches the parent through pickle (an error there would
    make loky kill every worker)."""
    copy = pickle.loads(pickle.dumps(RunInterrupted(signal.SIGHUP)))
    assert (copy.signum, copy.exit_status, str(copy)) == (1, 129, "interrupted by SIGHUP")


def test_a_job_is_not_started_once_the_sweep_is_interrupted(tmp_path, monkeypatch, handlers):
    """In a worker (this process, its parent named as the sweep's), a job that begins
    after the parent marked the sweep interrupted stops at once, unregistered, and the
    worker waits to be killed instead of taking another job."""
    (tmp_path / workers.MARKER).write_text(f"{int(signal.SIGTERM)}\n")
    monkeypatch.setenv(workers.ENV, f"{os.getppid()}:{tmp_path}")
    held: list[int] = []
    monkeypatch.setattr(workers, "hold", held.append)

    def no_kill(pid: int, sig: int) -> None:
        raise AssertionError(f"signal {sig} sent to {pid}")

    monkeypatch.setattr(os, "kill", no_kill)          # the parent marked it: nobody is told
    started: list[bool] = []
    with pytest.raises(RunInterrupted) as caught, workers.job():
        started.append(True)
    assert caught.value.signum == signal.SIGTERM and not started
    assert held == [os.getppid()]
    assert [p.name for p in tmp_path.iterdir()] == [workers.MARKER]


def test_outside_a_sweep_a_job_is_left_alone(tmp_path, monkeypatch):
    """The parent itself (a sequential sweep) and a process without the variable run the
    job unchanged, and the parent's handler has no worker to stop."""
    for value in (None, f"{os.getpid()}:{tmp_path}"):
        if value is None:
            monkeypatch.delenv(workers.ENV, raising=False)
        else:
            monkeypatch.setenv(workers.ENV, value)
        before = signal.getsignal(signal.SIGTERM)
        with workers.job():
            assert signal.getsignal(signal.SIGTERM) is before
    assert list(tmp_path.iterdir()) == []
    workers.stop_workers(tmp_path / "sweep", signal.SIGTERM)     # no worker: no wait
    assert [p.name for p in (tmp_path / "sweep").iterdir()] == [workers.MARKER]
