"""The held-out measurement error of a field model, its noise floor and its excess.

With count splitting (:mod:`nlosfw.evaluation.count_splitting`) a model trains on the kept
wall points of half A and is scored at the wall points it never saw against half B's
measured field, over the whole band:

- error  E = sum |P^ - P_B|^2 / sum |P_B|^2 (held-out points, every frequency);
- floor  F = sum Var(P_B) / sum |P_B|^2: the error of a perfect predictor (the noise-free
  field), since B's noise is independent of everything the model saw;
- excess E - F: an unbiased estimate of the error against B's noise-free field, over B's
  power. Each is reported in dB (10 log10); the excess is null (in dB) when E <= F.

:func:`heldout_scores` gives them as a run records them: each a finite number or None,
with why each None is.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.common.errors import DataError
from nlosfw.evaluation.undefined import Scored, is_number, not_finite


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


@dataclass(frozen=True)
class HeldoutScores:
    """:class:`HeldoutMeasurement` as a run records it: ``nmse_db``, ``floor_db``,
    ``excess_db`` and ``excess`` (``scores.values``), each a finite number or None with why
    (``scores.reasons``), and the held-out samples (points x frequencies)."""

    scores: Scored
    n_samples: int


def heldout_scores(predicted: np.ndarray, measured: np.ndarray, variance: np.ndarray,
                   spatial_mask: np.ndarray) -> HeldoutScores:
    """The held-out measurement of ``predicted`` against half B's ``measured`` field
    (:func:`heldout_measurement`) in dB, every value that is undefined None with why (B's
    field zero at the held-out points, a zero error, no noise, an error within the
    floor)."""
    held = ~np.asarray(spatial_mask, dtype=bool)
    at_held = np.asarray(measured)[:, held] if np.ndim(measured) == 3 and \
        held.shape == np.shape(measured)[1:] else None
    names = ("nmse_db", "floor_db", "excess_db", "excess")
    if at_held is not None and held.any() and not float(np.sum(np.abs(at_held) ** 2)) > 0:
        why = "half B's field is zero at the held-out wall points: no error relative to it"
        return HeldoutScores(Scored(dict.fromkeys(names), dict.fromkeys(names, why)),
                             n_samples=int(at_held.size))
    score = heldout_measurement(predicted, measured, variance, spatial_mask)
    db = HeldoutMeasurement.db
    reasons = {}
    if db(score.error) is None:
        reasons["nmse_db"] = ("the prediction equals half B's field at the held-out points: "
                              "zero error" if score.error == 0 else not_finite(score.error))
    if db(score.floor) is None:
        reasons["floor_db"] = ("half B's field carries no noise variance at the held-out "
                               "points" if score.floor == 0 else not_finite(score.floor))
    if db(score.excess) is None:
        reasons["excess_db"] = ("the error is within the noise floor (excess <= 0)"
                                if is_number(score.excess) else not_finite(score.excess))
    excess = score.excess if is_number(score.excess) else None
    if excess is None:
        reasons["excess"] = not_finite(score.excess)
    values = {"nmse_db": db(score.error), "floor_db": db(score.floor),
              "excess_db": db(score.excess), "excess": excess}
    return HeldoutScores(Scored(values, reasons), n_samples=score.n_samples)
