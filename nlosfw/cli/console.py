"""Terminal output of the app: the console log and progress bars.

The console shows nlosfw's own messages (loggers ``nlosfw*``, INFO and above) and any
library's errors; everything else a library logs (JAX's backend probing, Hydra,
matplotlib's font manager...) goes only to the run's ``run.log``, as do records logged
with ``extra=FILE_ONLY``, whatever their level. Log records and progress bars share rich's
console, so they do not garble each other.
"""

from __future__ import annotations

import logging
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from rich import get_console
from rich.console import Console, ConsoleRenderable
from rich.logging import RichHandler
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    SpinnerColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

from nlosfw.common.logs import OWN_LOGGERS
from nlosfw.common.text import controls_visible


class ConsoleFilter(logging.Filter):
    """Passes nlosfw's own records (``nlosfw*`` loggers, plugins' included) and any
    library's record of level ERROR or above, except records marked :data:`FILE_ONLY`
    (an unexpected failure's traceback: the console has its one line)."""

    def filter(self, record: logging.LogRecord) -> bool:
        if not getattr(record, "console", True):
            return False
        return record.levelno >= logging.ERROR or record.name.startswith(OWN_LOGGERS)


class _PlainHandler(RichHandler):
    """Rich's handler with control characters of messages (a file name holding escape
    sequences) shown as ``\\xNN`` instead of reaching the terminal."""

    def render_message(self, record: logging.LogRecord, message: str) -> ConsoleRenderable:
        return super().render_message(record, controls_visible(message))


def rich_log_handler() -> logging.Handler:
    """The console handler of the run log (used by conf/hydra/job_logging/nlosfw.yaml)."""
    handler = _PlainHandler(console=app_console(), show_path=False, rich_tracebacks=False,
                          markup=False, log_time_format="[%X]")
    handler.addFilter(ConsoleFilter())
    return handler


def app_console() -> Console:
    """The console progress bars and the log share (rich's own)."""
    return get_console()


def progress_bar(console: Console | None = None) -> Progress:
    """A progress display with an info field (``task.fields['info']``)."""
    return Progress(
        SpinnerColumn(finished_text="[green]✓[/]"),
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TextColumn("{task.fields[info]}"),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
        console=console or app_console(),
        transient=False,
    )


@contextmanager
def step(description: str, console: Console | None = None) -> Iterator[Callable[[str], None]]:
    """A progress line for a step without a count (a spinner and the time elapsed); it stays
    on screen, completed, when the step ends. Yields a function that sets its info text."""
    with progress_bar(console) as progress:
        task = progress.add_task(description, total=None, info="")
        yield lambda info: progress.update(task, info=info)
        progress.update(task, total=1, completed=1)
