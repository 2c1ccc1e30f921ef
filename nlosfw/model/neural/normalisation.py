"""Normalisation of phasor fields into the networks' range, and back.

Coordinates, frequencies and values are mapped affinely into [-margin, margin],
inside the open interval (-1, 1) every network sees; values are first
demodulated by the field's common path delay (:func:`estimate_delay`), which
the interpolation baseline uses as well.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import TypedDict

import numpy as np

from nlosfw.common.errors import FitError
from nlosfw.transform.field import PhasorField


def estimate_delay(values: np.ndarray, frequencies: np.ndarray) -> float:
    """Energy centroid (metres of path) of the band-limited transient behind a field.

    ``values`` (F, ...) at ``frequencies`` (F,). E(tau) = sum over pixels of
    |sum_f P_f e^{+2 pi i f tau}|^2 is evaluated over one period of the frequency
    sampling, [-1/(2 df), 1/(2 df)) with df the smallest frequency step (so fields whose
    phase grows with f, i.e. negative delays, are handled too), and the centroid of the
    part above 1% of its peak (a circular mean: the axis is periodic) is returned.
    Multiplying the field by e^{+2 pi i f tau} removes that common delay: the field then
    turns fewer times
    across the band, which is what makes it easier to fit in f.
    """
    f = np.asarray(frequencies, dtype=np.float64)
    if f.size < 2:
        return 0.0
    v = np.asarray(values).reshape(f.size, -1)
    gaps = np.diff(np.sort(f))
    gaps = gaps[gaps > 1e-12 * f.max()]
    if gaps.size == 0:
        return 0.0
    period = 1.0 / float(gaps.min())
    n_tau = int(min(8192, math.ceil(8.0 * float(np.ptp(f)) * period)))
    taus = np.linspace(-period / 2, period / 2, n_tau, endpoint=False)
    kernel = np.exp(2j * np.pi * f[:, None] * taus[None, :])     # (F, T)
    energy = np.zeros(taus.size)
    for k in range(0, v.shape[1], 4096):
        energy += np.sum(np.abs(v[:, k:k + 4096].T @ kernel) ** 2, axis=0)
    keep = energy >= 0.01 * energy.max()
    # tau is periodic: take the circular mean. A delay modulo the period only changes a
    # global phase of the demodulated field (f * period is an integer plus a constant).
    turn = np.sum(energy[keep] * np.exp(2j * np.pi * taus[keep] / period))
    return float(period / (2 * np.pi) * np.angle(turn))


class NormalisationDict(TypedDict):
    """A :class:`FieldNormalisation` as plain values."""

    xy_center: list[float]
    xy_half: float
    f_center: float
    f_half: float
    value_scale: float
    margin: float
    delay: float


@dataclass(frozen=True)
class FieldNormalisation:
    """Affine maps of coordinates, frequency and values into [-margin, margin] ⊂ (−1, 1).

    x and y of the training points map their extent to [-margin, margin] (the same
    factor for both axes keeps the aspect ratio), f maps the training band likewise.
    Values are first demodulated by a common path delay (P e^{+2 pi i f delay},
    ``delay`` 0 when disabled), then Re and Im are divided by one common scale so that
    max(|Re|, |Im|) maps to ``margin`` (one scale preserves phases). Points outside the
    training hull map outside [-margin, margin] (extrapolation).
    """

    xy_center: tuple[float, float]
    xy_half: float
    f_center: float
    f_half: float
    value_scale: float
    margin: float
    delay: float = 0.0

    @classmethod
    def fit(cls, field: PhasorField, margin: float, demodulate: bool = False
            ) -> FieldNormalisation:
        xy = field.wall_xyz[..., :2].reshape(-1, 2)
        lo, hi = xy.min(axis=0), xy.max(axis=0)
        half = float(np.max(hi - lo)) / 2
        f = field.frequencies
        f_half = float(f.max() - f.min()) / 2
        delay = estimate_delay(field.values, f) if demodulate else 0.0
        v = field.values * np.exp(2j * np.pi * f * delay)[:, None, None]
        peak = float(max(np.abs(v.real).max(), np.abs(v.imag).max()))
        if not peak > 0:
            raise FitError("field: all values are zero; nothing to fit")
        return cls(xy_center=(float(lo[0] + hi[0]) / 2, float(lo[1] + hi[1]) / 2),
                   xy_half=half if half > 0 else 1.0,
                   f_center=float(f.max() + f.min()) / 2,
                   f_half=f_half if f_half > 0 else float(f.max()),
                   value_scale=peak / margin, margin=float(margin), delay=delay)

    def coords(self, xy: np.ndarray) -> np.ndarray:
        """Normalised coordinates of wall points (..., 2) (float64)."""
        c = np.asarray(self.xy_center)
        return (np.asarray(xy, dtype=np.float64) - c) / self.xy_half * self.margin

    def freqs(self, f: np.ndarray) -> np.ndarray:
        """Normalised frequencies (float64)."""
        return (np.asarray(f, dtype=np.float64) - self.f_center) / self.f_half * self.margin

    def _carrier(self, f: np.ndarray, ndim: int) -> np.ndarray:
        f = np.asarray(f, dtype=np.float64)
        return np.exp(2j * np.pi * f * self.delay).reshape(f.shape + (1,) * (ndim - 1))

    def targets(self, values: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """Complex values (F, ...) at ``frequencies`` (F,) -> normalised (F, ..., 2) float32."""
        values = np.asarray(values)
        v = values * self._carrier(frequencies, values.ndim) / self.value_scale
        return np.stack([v.real, v.imag], axis=-1).astype(np.float32)

    def values(self, outputs: np.ndarray, frequencies: np.ndarray) -> np.ndarray:
        """Network outputs (F, ..., 2) at ``frequencies`` (F,) -> complex values (complex64)."""
        out = np.asarray(outputs, dtype=np.float64)
        v = (out[..., 0] + 1j * out[..., 1]) * self.value_scale
        return (v / self._carrier(frequencies, v.ndim)).astype(np.complex64)

    def to_dict(self) -> NormalisationDict:
        """Plain values for a model file's header."""
        return {"xy_center": list(self.xy_center), "xy_half": self.xy_half,
                "f_center": self.f_center, "f_half": self.f_half,
                "value_scale": self.value_scale, "margin": self.margin, "delay": self.delay}

    @classmethod
    def from_dict(cls, data: NormalisationDict) -> FieldNormalisation:
        """Inverse of :meth:`to_dict`."""
        return cls(xy_center=tuple(float(v) for v in data["xy_center"]),  # type: ignore[arg-type]
                   xy_half=float(data["xy_half"]), f_center=float(data["f_center"]),
                   f_half=float(data["f_half"]), value_scale=float(data["value_scale"]),
                   margin=float(data["margin"]), delay=float(data.get("delay", 0.0)))
