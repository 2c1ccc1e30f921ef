"""A parallel sweep interrupted: every running job ends with its status, no other starts.

With Hydra's joblib launcher (``hydra/launcher=parallel``) the jobs run in loky worker
processes, children of the command's process (the *parent*). Left alone, a signal to the
parent raises in the middle of ``joblib.Parallel``, which then kills its workers with
SIGKILL (``abort_everything``); loky also kills every worker as soon as one of them dies
(a "broken executor"), and a worker dies of SIGTERM or SIGHUP between two jobs (their
default action), and of SIGINT there (loky's loop exits on KeyboardInterrupt). So the
running jobs ended without ``metrics.json`` and with their lock.

What happens instead, from :func:`forwarding` (the parent, around Hydra) and :func:`job`
(around each job, in whatever process runs it):

* **How the parent knows its workers.** The parent puts ``NLOSFW_SWEEP=<pid>:<folder>``
  in its environment, which the workers inherit when loky starts them. A process whose
  parent is ``<pid>`` (so not the parent itself, which runs the jobs of a sequential sweep;
  not a job on another machine) is a worker: while it runs a job it keeps a file named
  by its process id in ``<folder>`` (a new temporary folder, made when first needed,
  removed when the command ends). On a signal the parent
  signals exactly those processes, and only once it has checked that each is still its own
  direct child and alive (``/proc/<pid>/stat`` on Linux, ``ps -o ppid=`` elsewhere): it
  never signals its process group (which it may share with the user's shell or script),
  loky's resource tracker (which runs no job), an idle worker or a recycled process id.
  Neither joblib nor loky has a public way to list the workers.
* **The parent's handler** (:func:`~nlosfw.pipeline.interrupts.before_raising`, before it
  raises): writes ``<folder>/interrupted``, sends the same signal once to each worker
  running a job, then waits, up to :data:`WAIT_SECONDS`, until each has removed its file
  (its metrics.json written, its lock released) or is gone; then it raises, joblib kills
  the workers, and the command exits with 130, 143 or 129 after its one line.
* **A worker** handles the signals (:func:`~nlosfw.pipeline.interrupts.signals_raise`)
  while it runs a job, and records them between jobs
  (:func:`~nlosfw.pipeline.interrupts.record_signals`) instead of dying (which would make
  loky kill the others mid-write). Its job ends as any interrupted run does: status
  ``interrupted`` with the stage in metrics.json, the lock released. A job that starts
  after the sweep was interrupted (the worker received a signal, or
  ``<folder>/interrupted`` exists) stops before it writes anything of its own. An
  interrupted worker then waits to be killed instead of taking the next job (at most
  :data:`HOLD_SECONDS`, less when the parent is gone), so no further job is started, and
  its interruption never reaches joblib in the parent (which would kill the other
  workers at once). When the parent has not marked the sweep interrupted, the worker
  sends it the signal it got: a job interrupted is the sweep interrupted (as in a
  sequential sweep), whether the signal came to the parent, to the whole group, or to
  one worker alone.
* **Twice the same signal** (a terminal's Ctrl-C or SLURM's ``scancel`` signal the whole
  group: each worker gets it from there and again from the parent) is harmless: a signal
  raises once, later ones are recorded (:mod:`nlosfw.pipeline.interrupts`).

Limits: a worker that has never run a job still has the default handlers, so when a whole
process group is signalled at the very start of a sweep (or with fewer jobs than workers)
it dies, and loky kills the others; a job a worker had already taken from loky's queue
when the signal came has Hydra's directory (``.hydra/``) and nothing else; SIGKILL (the
out-of-memory killer's) cannot be handled: loky then kills the other workers as before.
"""

from __future__ import annotations

import contextlib
import logging
import os
import secrets
import shutil
import subprocess
import tempfile
from collections.abc import Iterator
from functools import partial
from pathlib import Path
from time import monotonic, sleep

from nlosfw.common.errors import RunInterrupted
from nlosfw.pipeline import interrupts

log = logging.getLogger(__name__)

#: ``<parent pid>:<folder>``: set by the parent of a sweep for its workers.
ENV = "NLOSFW_SWEEP"
#: How long the interrupted parent waits for its workers to finish their jobs.
WAIT_SECONDS = 60.0
#: How long an interrupted worker waits to be killed before it gives up and goes on.
HOLD_SECONDS = 2 * WAIT_SECONDS
#: How often waits look again.
POLL_SECONDS = 0.05
#: The file that says that the sweep was interrupted (it holds the signal's number).
MARKER = "interrupted"


@contextlib.contextmanager
def forwarding() -> Iterator[Path]:
    """In the parent, around Hydra: the workers of a parallel sweep started in the block
    are told where to register, and a signal is forwarded to them (see the module).
    Yields the sweep's folder (made when first needed), where the jobs also record how
    they ended (:mod:`nlosfw.cli.outcomes`)."""
    folder = Path(tempfile.gettempdir()) / f"nlosfw-sweep-{os.getpid()}-{secrets.token_hex(6)}"
    saved = os.environ.get(ENV)
    os.environ[ENV] = f"{os.getpid()}:{folder}"
    try:
        with interrupts.before_raising(partial(stop_workers, folder)):
            yield folder
    finally:
        if saved is None:
            os.environ.pop(ENV, None)
        else:
            os.environ[ENV] = saved
        shutil.rmtree(folder, ignore_errors=True)


def stop_workers(folder: Path, signum: int, wait_seconds: float = WAIT_SECONDS) -> None:
    """Mark the sweep interrupted, send ``signum`` once to each worker running a job and
    wait (up to ``wait_seconds``) until each has finished it or is gone."""
    try:   # made even when no worker has registered yet: one about to sees it and stops
        folder.mkdir(mode=0o700, exist_ok=True)
        partial_marker = folder / f".{MARKER}.{os.getpid()}"
        partial_marker.write_text(f"{signum}\n")
        partial_marker.replace(folder / MARKER)
    except OSError as err:             # then no worker could register either
        log.debug("cannot mark the sweep interrupted in %s: %s", folder, err)
        return
    running = [pid for pid in _registered(folder) if _is_child(pid)]
    for pid in running:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signum)
    deadline = monotonic() + wait_seconds
    while True:
        running = [pid for pid in running if (folder / str(pid)).exists() and _is_child(pid)]
        if not running:
            return
        if monotonic() > deadline:
            log.warning("%d job(s) of the sweep did not finish within %.0f s of the signal; "
                        "they are stopped now", len(running), wait_seconds)
            return
        sleep(POLL_SECONDS)


@contextlib.contextmanager
def job() -> Iterator[None]:
    """Around one job: in a worker of a parallel sweep, the signals handled, the job
    registered while it runs, refused once the sweep is interrupted, and the worker held
    afterwards (see the module); elsewhere nothing."""
    sweep = _sweep()
    if sweep is None:
        yield
        return
    parent, folder = sweep
    interrupts.record_signals()
    try:
        with interrupts.signals_raise():
            entry = _register(folder)
            try:
                stop = _marker(folder) or interrupts.received()
                if stop:
                    raise RunInterrupted(stop)   # the sweep was interrupted: do not start
                yield
            finally:
                if entry is not None:
                    entry.unlink(missing_ok=True)
    except RunInterrupted as err:
        if not _marker(folder):        # the parent has not handled it (yet): it must
            with contextlib.suppress(OSError):
                os.kill(parent, err.signum)
        hold(parent)
        raise


def hold(parent: int, seconds: float = HOLD_SECONDS) -> None:
    """Wait to be killed by the sweep's parent (joblib kills its workers once the parent
    has stopped waiting), so as to take no further job; give up when ``parent`` is no
    longer this process's parent, or after ``seconds``."""
    deadline = monotonic() + seconds
    while os.getppid() == parent and monotonic() < deadline:
        sleep(POLL_SECONDS)


def _sweep() -> tuple[int, Path] | None:
    """The parent's process id and the registration folder when this process is a worker
    of a sweep (its parent set :data:`ENV`), else None."""
    pid, _, folder = os.environ.get(ENV, "").partition(":")
    if not pid.isdigit() or not folder or os.getppid() != int(pid):
        return None
    return int(pid), Path(folder)


def _register(folder: Path) -> Path | None:
    """This worker's file in ``folder`` (None, logged, when it cannot be written: the job
    then runs unregistered, and is not waited for)."""
    entry = folder / str(os.getpid())
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        entry.write_text(f"{os.getpid()}\n")
    except OSError as err:
        log.debug("cannot register this sweep worker in %s: %s", folder, err)
        return None
    return entry


def _registered(folder: Path) -> list[int]:
    """The process ids of the workers registered in ``folder``."""
    try:
        return sorted(int(p.name) for p in folder.iterdir() if p.name.isdigit())
    except OSError:
        return []


def _marker(folder: Path) -> int | None:
    """The signal that interrupted the sweep, when the parent has marked it so."""
    try:
        text = (folder / MARKER).read_text().strip()
    except OSError:
        return None
    return int(text) if text.isdigit() else None


def _is_child(pid: int) -> bool:
    """Whether ``pid`` is a live (not zombie) direct child of this process."""
    stat = Path(f"/proc/{pid}/stat")
    if Path("/proc/self/stat").exists():
        try:
            fields = stat.read_text().rpartition(")")[2].split()
        except OSError:
            return False
        return len(fields) > 1 and fields[0] not in ("Z", "X") and fields[1] == str(os.getpid())
    try:
        found = subprocess.run(["ps", "-o", "ppid=", "-p", str(pid)], capture_output=True,
                               text=True, timeout=30, check=False)
    except (OSError, subprocess.TimeoutExpired):
        return False
    return found.stdout.strip() == str(os.getpid())
