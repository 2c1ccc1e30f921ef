"""Conventions of nlosfw's log records that the console and the run log share."""

from __future__ import annotations

from typing import Final

#: ``log.info(..., extra=FILE_ONLY)``: the record goes to run.log but not to the console.
FILE_ONLY: Final = {"console": False}

#: Logger name prefix of nlosfw's own records (plugins' included: ``nlosfw_torch``, ...).
OWN_LOGGERS: Final = "nlosfw"
