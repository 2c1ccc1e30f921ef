"""The held-out measurement error of a field model, its noise floor and its excess.

With count splitting (:mod:`nlosfw.capture.thinning`) a model trains on the kept wall points
of half A and is scored at the wall points it never saw against half B's measured field,
over the whole band:

- error  E = sum |P^ - P_B|^2 / sum |P_B|^2 (held-out points, every frequency);
- floor  F = sum Var(P_B) / sum |P_B|^2: the error of a perfect predictor (the noise-free
  field), since B's noise is independent of everything the model saw;
- excess E - F: an unbiased estimate of the error against B's noise-free field, over B's
  power. Each is reported in dB (10 log10); the excess is null (in dB) when E <= F.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.common.errors import DataError


@dataclass(frozen=True)
class HeldoutMeasurement:
    """Error, floor and excess of one prediction, as ratios to B's held-out power."""

    error: float
    floor: float
    n_samples: int

    @property
    def excess(self) -> float:
        """error - floor (may be negative: the error is within the noise)."""
        return self.error - self.floor

    @staticmethod
    def db(ratio: float) -> float | None:
        """10 log10 of a positive ratio, None otherwise."""
        return 10.0 * math.log10(ratio) if ratio > 0 and math.isfinite(ratio) else None


def heldout_measurement(predicted: np.ndarray, measured: np.ndarray, variance: np.ndarray,
                        spatial_mask: np.ndarray) -> HeldoutMeasurement:
    """The error, floor and excess of ``predicted`` (F, Y, X) against the ``measured`` field
    of B (F, Y, X) whose per-sample noise variance is ``variance`` (F, Y, X), at the wall
    points where ``spatial_mask`` (Y, X; True: trained on) is False, every frequency."""
    p, m, v = np.asarray(predicted), np.asarray(measured), np.asarray(variance)
    if not (p.shape == m.shape == v.shape) or p.ndim != 3:
        raise DataError(f"heldout_measurement: predicted {p.shape}, measured {m.shape} and "
                        f"variance {v.shape} must be the same (frequency, y, x) field")
    held = ~np.asarray(spatial_mask, dtype=bool)
    if held.shape != p.shape[1:]:
        raise DataError(f"heldout_measurement: mask {held.shape} is not the fields' grid "
                        f"{p.shape[1:]}")
    if not held.any():
        raise DataError("heldout_measurement: no wall point is held out")
    pm, mm, vm = p[:, held], m[:, held], v[:, held]
    power = float(np.sum(np.abs(mm) ** 2))
    if power <= 0:
        raise DataError("heldout_measurement: B's field is zero at the held-out points")
    error = float(np.sum(np.abs(pm - mm) ** 2)) / power
    floor = float(np.sum(vm)) / power
    return HeldoutMeasurement(error=error, floor=floor, n_samples=int(mm.size))
