"""Scores that cannot be computed on some data: a value of None, with why, never NaN or inf
(a run's record is JSON, which has neither)."""

from __future__ import annotations

import math
from typing import NamedTuple


class Scored(NamedTuple):
    """Named scores as a run records them: each a finite number or None (``values``), and
    why each None is, in one line (``reasons``, by name)."""

    values: dict[str, float | None]
    reasons: dict[str, str]


def is_number(value: object) -> bool:
    """Whether ``value`` is a finite int or float (not None, NaN or inf)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(
        value)


def not_finite(value: float) -> str:
    """The generic reason for a value computed as NaN or inf."""
    return f"computed as {value!r} on this data: undefined"
