"""Conformance checks for every transform plugin (see :mod:`nlosfw.testing.checks_common`)."""

from __future__ import annotations

TRANSFORM_CHECKS: tuple = ()
