"""Regularisation across frequency: the field is smooth in omega, so penalise its curvature.

A phasor field P(x, y, f) is a sum of e^{-2 pi i f r} over path lengths r of the hidden
scene; with the common delay removed (``demodulate``) it turns slowly across the band.
Between training frequencies a network is free to wiggle; the penalty

    weight * mean |P(p, f - h) - 2 P(p, f) + P(p, f + h)|^2

(the second difference at the mean training-frequency spacing h, on the normalised
field, at random wall points p of the training hull) pulls it towards a field with
small curvature in f. It is the same for every network: the trainer draws the points
and frequencies here and the backend adds the penalty to the data loss
(:class:`~nlosfw.model.neural.backend.SmoothnessBatch`).

Multi mode: each of ``points`` random points gets a random centre frequency f in the
training band (held-out frequencies included) and the network is evaluated at
f - h, f, f + h. Single mode: every network (one per training frequency) is evaluated
at the same random points and the penalty is the second divided difference across
neighbouring training frequencies, scaled to h (for uneven spacing the exact
three-point formula; for even spacing 1, -2, 1).
"""

from __future__ import annotations

import logging

import numpy as np

from nlosfw.model.neural.backend import SmoothnessBatch

log = logging.getLogger(__name__)


def second_difference_matrix(frequencies: np.ndarray) -> np.ndarray:
    """(F - 2, F) rows h^2 f''(f_i) at each inner training frequency (in sorted order), for
    values indexed as ``frequencies``; h is the mean spacing. Even spacing: 1, -2, 1."""
    f = np.asarray(frequencies, dtype=np.float64)
    order = np.argsort(f)
    fs = f[order]
    h = (fs[-1] - fs[0]) / (fs.size - 1)
    d = np.zeros((f.size - 2, f.size))
    for i in range(1, f.size - 1):
        h0, h1 = fs[i] - fs[i - 1], fs[i + 1] - fs[i]
        d[i - 1, order[i - 1]] = 2 * h * h / (h0 * (h0 + h1))
        d[i - 1, order[i]] = -2 * h * h / (h0 * h1)
        d[i - 1, order[i + 1]] = 2 * h * h / (h1 * (h0 + h1))
    return d


class FrequencySmoothness:
    """Draws each step's :class:`SmoothnessBatch` (see the module docstring)."""

    def __init__(self, weight: float, points: int, box: np.ndarray, frequencies: np.ndarray,
                 single: bool, rng: np.random.Generator) -> None:
        """``box`` (2, 2): min and max of the normalised training x, y; ``frequencies``:
        the normalised training frequencies (one per network in single mode)."""
        self.weight, self.points, self.single, self.rng = float(weight), points, single, rng
        self.box = np.asarray(box, dtype=np.float64)
        f = np.unique(np.asarray(frequencies, dtype=np.float64))
        self.lo, self.hi = float(f[0]), float(f[-1])
        self.h = (self.hi - self.lo) / (f.size - 1)
        self.matrix = (second_difference_matrix(frequencies) if single
                       else np.array([[1.0, -2.0, 1.0]])).astype(np.float32)

    @classmethod
    def of(cls, weight: float, points: int, xy: np.ndarray, frequencies: np.ndarray,
           single: bool, rng: np.random.Generator) -> FrequencySmoothness | None:
        """The penalty for training points ``xy`` (N, 2) and ``frequencies`` (normalised),
        or None when it is off (``weight`` 0) or there are fewer than 3 frequencies."""
        if weight <= 0:
            return None
        if np.unique(frequencies).size < 3:
            log.warning("frequency_smoothness needs 3 or more training frequencies; off")
            return None
        box = np.stack([xy.min(axis=0), xy.max(axis=0)])
        return cls(weight, points, box, frequencies, single, rng)

    def batch(self) -> SmoothnessBatch:
        """Inputs and second-difference matrix of one step."""
        p = self.rng.uniform(self.box[0], self.box[1], (self.points, 2))
        if self.single:
            return SmoothnessBatch(p.astype(np.float32), self.matrix, self.weight)
        centre = self.rng.uniform(self.lo + self.h, self.hi - self.h, self.points)
        x = np.concatenate([np.column_stack([p, centre + k * self.h]) for k in (-1, 0, 1)])
        return SmoothnessBatch(x.astype(np.float32), self.matrix, self.weight)
