"""Conformance checks for every simulator plugin (see :mod:`nlosfw.testing.checks_common`)."""

from __future__ import annotations

SIMULATOR_CHECKS: tuple = ()
