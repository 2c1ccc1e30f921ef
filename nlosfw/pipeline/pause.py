"""A test-only pause point: a run held at a named point until a test releases it.

Tests that need a run alive, at a given stage, or interrupted in the middle of one hold it
there instead of making it slow and hoping. With the environment variable
``NLOSFW_TEST_PAUSE=<point>:<dir>`` set, a run that reaches ``<point>`` writes
``<dir>/reached`` and ``<dir>/reached-<pid>`` (its process id), then waits until
``<dir>/release`` exists; a signal (SIGINT, SIGTERM, SIGHUP) interrupts the wait as it
would the stage. ``reached-<pid>`` tells the jobs of a parallel sweep apart: each worker
process held at the point has its own. Without the variable, or for
any other point, :func:`pause_point` returns at once: one lookup in ``os.environ``.

The points:

* ``<stage>`` (``capture``, ``transform``, ``fit``, ``predict``, ``reconstruct``,
  ``report``): the stage has started (``on_stage_start`` was called, ``run.log`` says so)
  and has done nothing yet;
* ``<file>`` (a run file's name, ``capture.hdf5``, ``fields/true.hdf5``, ...): the file
  is written at its temporary path and not yet published under its name.

Once released, the point is passed at once by every later arrival (the jobs of a sweep run
in one process). A run left waiting for :data:`TIMEOUT_SECONDS` fails with a message that
says what it waited for.
"""

from __future__ import annotations

import logging
import os
from pathlib import Path
from time import monotonic, sleep

from nlosfw.common.errors import NlosfwError

log = logging.getLogger(__name__)

#: ``<point>:<dir>``: hold the run at ``<point>`` until ``<dir>/release`` exists.
ENV = "NLOSFW_TEST_PAUSE"
#: How long a held run waits for its release before it fails.
TIMEOUT_SECONDS = 600.0
#: How often a held run looks for its release.
POLL_SECONDS = 0.02


class PauseTimeout(NlosfwError):
    """A run held at a test pause point was not released in time."""


def pause_point(point: str) -> None:
    """Hold the run at ``point`` when ``NLOSFW_TEST_PAUSE`` names it (see the module);
    otherwise return at once."""
    setting = os.environ.get(ENV)
    if not setting:
        return
    name, _, folder = setting.partition(":")
    if name != point or not folder:
        return
    _hold(point, Path(folder))


def _hold(point: str, folder: Path) -> None:
    release = folder / "release"
    if release.exists():
        return
    folder.mkdir(parents=True, exist_ok=True)
    for name in (f"reached-{os.getpid()}", "reached"):
        partial = folder / f".{name}.{os.getpid()}"
        partial.write_text(f"{os.getpid()}\n")
        partial.replace(folder / name)       # whole, so a test never reads it half-written
    log.info("%s: held at %s until %s exists", ENV, point, release)
    deadline = monotonic() + TIMEOUT_SECONDS
    while not release.exists():
        if monotonic() > deadline:
            raise PauseTimeout(f"{ENV}: held at {point} for {TIMEOUT_SECONDS:.0f} s and "
                               f"{release} was not created; giving up")
        sleep(POLL_SECONDS)
    log.info("%s: released at %s", ENV, point)
