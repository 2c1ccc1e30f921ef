"""Reporting errors the user can fix: one line on stderr, traceback only on request."""

from __future__ import annotations

import logging
import os
import traceback

from rich.console import Console

from nlosfw.common.errors import NlosfwError, RunInterrupted, one_line
from nlosfw.common.text import console_text as escape

log = logging.getLogger("nlosfw")


def report_user_error(err: BaseException) -> None:
    """Print ``error: <message>`` as one line on stderr (the traceback too in debug mode)."""
    console = Console(stderr=True, soft_wrap=True, highlight=False)
    if os.environ.get("NLOSFW_DEBUG") == "1":
        console.print(escape("".join(traceback.format_exception(err))), end="")
    console.print(f"[bold red]error:[/] {escape(one_line(err, whole=True))}")


def report_job_failure(err: BaseException, num: int) -> None:
    """Print ``job <num> failed: <message>`` as one line on stderr (the traceback too in
    debug mode): a sweep's job that failed, the sweep going on."""
    console = Console(stderr=True, soft_wrap=True, highlight=False)
    if os.environ.get("NLOSFW_DEBUG") == "1":
        console.print(escape("".join(traceback.format_exception(err))), end="")
    console.print(f"[bold red]job {num} failed:[/] {escape(one_line(err, whole=True))}")


def unexpected_error(err: BaseException, stage: str | None = None) -> NlosfwError:
    """An unexpected exception (a bug, a library's failure) as a one-line error with exit
    status 1, naming its type, the stage it ended (if known) and where the traceback is."""
    where = f" in stage {stage}" if stage else ""
    failure = NlosfwError(f"{type(err).__name__}: {one_line(err, whole=True)} (an unexpected "
                          f"failure{where}; the traceback is in run.log, or on the console "
                          "with --debug)")
    failure.exit_status = 1
    failure.__traceback__ = err.__traceback__
    return failure


def report_interruption(err: RunInterrupted) -> None:
    """Print ``interrupted by SIGINT`` (or SIGTERM) as one line on stderr."""
    console = Console(stderr=True, soft_wrap=True, highlight=False)
    console.print(f"[bold yellow]interrupted[/] by {err.signal_name}: stopped cleanly "
                  f"(exit status {err.exit_status})")
