"""Conventions of nlosfw's log records that the console and the run log share."""

from __future__ import annotations

import copy
import logging
import threading
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from typing import Final

from nlosfw.common.text import controls_visible

#: ``log.info(..., extra=FILE_ONLY)``: the record goes to run.log but not to the console.
FILE_ONLY: Final = {"console": False}

#: Logger name prefix of nlosfw's own records (plugins' included: ``nlosfw_torch``, ...).
OWN_LOGGERS: Final = "nlosfw"

#: The format of a run.log line.
FILE_FORMAT: Final = "[%(asctime)s][%(name)s][%(levelname)s] %(message)s"


class VisibleFormatter(logging.Formatter):
    """run.log's formatter: control characters other than newline and tab shown as
    ``\\xNN`` (an escape sequence in a file name never acts on the terminal that shows the
    log)."""

    def __init__(self, fmt: str = FILE_FORMAT, datefmt: str | None = None) -> None:
        super().__init__(fmt, datefmt)

    def format(self, record: logging.LogRecord) -> str:
        return controls_visible(super().format(record))


class _Recorder(logging.Handler):
    """Keeps the records of one thread at INFO and above (handled as usual elsewhere)."""

    def __init__(self, records: list[logging.LogRecord], thread: int) -> None:
        super().__init__(logging.INFO)
        self.records, self.thread = records, thread

    def emit(self, record: logging.LogRecord) -> None:
        if record.thread == self.thread:
            self.records.append(record)


@contextmanager
def recorded(name: str = OWN_LOGGERS) -> Iterator[list[logging.LogRecord]]:
    """The records this thread logs at INFO and above under logger ``name`` in the block,
    as a list that fills while it runs (the records reach their handlers as usual)."""
    records: list[logging.LogRecord] = []
    handler = _Recorder(records, threading.get_ident())
    logger = logging.getLogger(name)
    logger.addHandler(handler)
    try:
        yield records
    finally:
        logger.removeHandler(handler)


def to_file(records: Iterable[logging.LogRecord]) -> None:
    """Log ``records`` again, to the run's log file only (:data:`FILE_ONLY`): what was said
    before the run's log existed (its plan's reading of the capture)."""
    for record in records:
        again = copy.copy(record)
        again.console = False
        logging.getLogger(record.name).handle(again)
