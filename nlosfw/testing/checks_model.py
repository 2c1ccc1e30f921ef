"""Conformance checks for every model plugin (see :mod:`nlosfw.testing.checks_common`)."""

from __future__ import annotations

MODEL_CHECKS: tuple = ()
