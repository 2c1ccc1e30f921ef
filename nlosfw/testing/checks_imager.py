"""Conformance checks for every imager plugin (see :mod:`nlosfw.testing.checks_common`)."""

from __future__ import annotations

IMAGER_CHECKS: tuple = ()
