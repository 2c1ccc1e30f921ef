"""Conventions of nlosfw's log records that the console and the run log share."""

from __future__ import annotations

import logging
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
