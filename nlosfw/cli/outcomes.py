"""A sweep's jobs each end with their own status: a failed job never stops the others.

An exception out of a job would stop Hydra's basic launcher at that job (``SystemExit``
passes through its loop), or make joblib kill the parallel launcher's other workers in
the middle of their stages. So a job of a sweep (``-m``) that fails does not raise: its
record says how it ended (``metrics.json``, by the engine), it prints one line
``job N failed: <message>`` and writes its outcome into the sweep's folder (the one
:mod:`nlosfw.cli.workers` shares between the command's process and its workers), and
returns. Every job that ends writes its outcome there. When Hydra has run them all,
:func:`check` (in the command's process) ends the command with one line naming the
failed jobs and the values they were swept over: exit status 2 when each was refused as
bad input (exit status 2), else 1.

A job whose folder cannot be reached (a launcher running jobs on other machines) raises
its error as an ordinary exception instead: Hydra's launchers record it as the job's
failure, run the other jobs, and the sweep ends with the first such error.
Interruptions (SIGINT, SIGTERM, SIGHUP) are not failures: they stop the whole sweep as
before (:mod:`nlosfw.cli.workers`).
"""

from __future__ import annotations

import json
import logging
import os
import secrets
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

from nlosfw.common.errors import NlosfwError
from nlosfw.common.files import write_text

log = logging.getLogger(__name__)

#: The name of each outcome file: ``outcome-<job number>-<random>.json``.
PREFIX = "outcome-"


@dataclass(frozen=True)
class Outcome:
    """How one job of a sweep ended: its number, its overrides, and for a failed job its
    one-line error and exit status (0: it did not fail)."""

    num: int
    overrides: tuple[str, ...]
    message: str = ""
    exit_status: int = 0

    @property
    def failed(self) -> bool:
        return self.exit_status != 0


def sweep_folder() -> Path | None:
    """The sweep's folder when this process runs a job of a sweep started by this
    command (the command's process itself or one of its workers), else None."""
    from nlosfw.cli.workers import ENV

    pid, _, folder = os.environ.get(ENV, "").partition(":")
    if not pid.isdigit() or not folder or int(pid) not in (os.getpid(), os.getppid()):
        return None
    return Path(folder)


def record(folder: Path, outcome: Outcome) -> bool:
    """Write ``outcome`` into ``folder``; False (logged) when it cannot be written."""
    name = f"{PREFIX}{outcome.num}-{secrets.token_hex(6)}.json"
    try:
        folder.mkdir(mode=0o700, exist_ok=True)
        write_text(folder / name, json.dumps({
            "num": outcome.num, "overrides": list(outcome.overrides),
            "message": outcome.message, "exit_status": outcome.exit_status}))
    except OSError as err:
        log.warning("cannot record how sweep job %d ended in %s: %s", outcome.num, folder, err)
        return False
    return True


def outcomes(folder: Path) -> list[Outcome]:
    """The outcomes recorded in ``folder``, by job number."""
    found = []
    try:
        paths = sorted(folder.glob(f"{PREFIX}*.json"))
    except OSError:
        return []
    for path in paths:
        try:
            data = json.loads(path.read_text(encoding="utf-8"))
            found.append(Outcome(num=int(data["num"]),
                                 overrides=tuple(str(o) for o in data["overrides"]),
                                 message=str(data["message"]),
                                 exit_status=int(data["exit_status"])))
        except (OSError, ValueError, KeyError, TypeError) as err:
            log.warning("unreadable sweep job outcome %s: %s", path, err)
    return sorted(found, key=lambda o: o.num)


def check(folder: Path) -> None:
    """Raise the one-line error of the sweep whose jobs recorded their outcomes in
    ``folder`` when any of them failed (nothing when none did)."""
    ended = outcomes(folder)
    failed = [o for o in ended if o.failed]
    if not failed:
        return
    swept = _swept_keys(ended)
    total = len(ended)
    if len(failed) == 1:
        (job,) = failed
        error = NlosfwError(f"job {job.num} of {total} of the sweep failed"
                            f"{_values(job, swept, ' ({})')}: {job.message}")
    else:
        names = ", ".join(f"job {o.num}{_values(o, swept, ' ({})')}" for o in failed)
        error = NlosfwError(f"{len(failed)} of {total} jobs of the sweep failed: {names}; "
                            "each job's metrics.json and run.log say why")
    error.exit_status = 2 if all(o.exit_status == 2 for o in failed) else 1
    raise error


def _swept_keys(ended: Sequence[Outcome]) -> list[str]:
    """The keys whose values differ between the jobs (the ones the sweep varies)."""
    values: dict[str, set[str]] = {}
    for outcome in ended:
        for override in outcome.overrides:
            key, _, value = override.partition("=")
            values.setdefault(key, set()).add(value)
    for outcome in ended:   # a key some job lacks varies too
        keys = {o.partition("=")[0] for o in outcome.overrides}
        for key in values:
            if key not in keys:
                values[key].add("\0")
    return [key for key, seen in values.items() if len(seen) > 1]


def _values(outcome: Outcome, keys: Sequence[str], template: str) -> str:
    """``template`` holding the job's swept overrides, or nothing when none is known."""
    chosen = [o for o in outcome.overrides if o.partition("=")[0] in keys]
    return template.format(" ".join(chosen)) if chosen else ""
