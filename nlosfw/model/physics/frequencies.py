"""Which frequencies the physics-constrained fit uses: evenly spread over the field's band,
and enough of them that the voxel planes' depth span does not alias in time."""

from __future__ import annotations

import math

import numpy as np

from nlosfw.transform.field import PhasorField


def fit_frequency_indices(frequencies: np.ndarray, count: int) -> np.ndarray:
    """Indices of ``count`` frequencies evenly spread over the sorted ``frequencies`` (the
    first and the last included; all of them for count 0 or count >= F)."""
    order = np.argsort(frequencies, kind="stable")
    n = order.size
    if count == 0 or count >= n:
        return order
    picks = np.unique(np.round(np.linspace(0, n - 1, count)).astype(int))
    return order[picks]


def enough_frequencies(frequencies: np.ndarray, count: int, depth_span: float) -> int:
    """At least ``count`` (0: all), and enough evenly spread frequencies that paths over
    twice ``depth_span`` (m) do not alias in time (spacing <= 1 / (2.2 depth_span))."""
    if count == 0:
        return 0
    f = np.asarray(frequencies, dtype=float)
    band = float(f.max() - f.min())
    needed = int(math.ceil(band * 2.2 * depth_span)) + 1
    return max(count, needed)


def fitted_frequencies(count: int, field: PhasorField, depths: np.ndarray) -> np.ndarray:
    """The indices of the frequencies a fit on voxel planes at ``depths`` uses: at least
    ``count`` (0: all) evenly spread, and enough that the planes' span does not alias."""
    span = float(depths.max() - depths.min())
    return fit_frequency_indices(field.frequencies, enough_frequencies(
        field.frequencies, count, span))
