"""Per-frequency signal fractions of a confocal field, measured from its evanescent region.

A hidden scene seen from a confocal wall makes, at path frequency f (cycles per metre of
path), a field whose lateral spatial frequencies stay within |k_xy| <= 2 f: each hidden
point contributes exp(2 pi i f 2 r(x)) / r^n and |grad 2 r| <= 2. Everything the field
holds beyond that circle (the evanescent region) is noise: the photon noise of the
histograms, which is white in time and so equally strong at every frequency. From the
wall's 2-D power spectrum at each frequency:

    P(f) = mean |FFT_xy P_f|^2 / (Y X)          (signal and noise)
    N(f) = the same mean over |k_xy| > 2 f      (noise only)

and the Wiener weight of the frequency is max(0, 1 - N(f) / P(f)): the fraction of its
power that is signal. Frequencies whose evanescent region is too small to measure (2 f
near or past the wall's lateral Nyquist frequency) take the median N of those measured
(white noise). A noise-free field gets weights of about 1; the measured Stanford LCT
captures lose their top frequencies where their signal ends (the diffuse S above about
12 cycles/m, the retroreflective charts above about 40).

A field zero-filled on a larger grid (the sparse ``raw`` source given to an imager of the
full grid) has copies of its spectrum in the evanescent region: the weights come from the
samples it has, the regular sub-grid of its rows and columns that are not all zero; with
an irregular pattern there is nothing to measure and every weight is 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: Smallest share of the lateral spectrum beyond 2 f for N(f) to be measured there.
MIN_EVANESCENT_SHARE = 0.25


@dataclass(frozen=True, eq=False)
class NoiseWeights:
    """Per-frequency Wiener weights and what they were estimated from."""

    weights: np.ndarray
    """(F,) max(0, 1 - N/P), in [0, 1]; all ones when no frequency could be measured."""
    measured: int
    """How many frequencies had an evanescent region to measure N in."""
    noise_power: float
    """The median N over the measured frequencies (0 when none was)."""


def evanescent_noise_weights(values: np.ndarray, frequencies: np.ndarray,
                             spacing: tuple[float, float]) -> NoiseWeights:
    """Wiener weights of a confocal field on a regular wall grid (module docstring).

    ``values`` (F, Y, X) complex, ``frequencies`` (F,) in cycles per metre of path,
    ``spacing`` (dy, dx) in metres."""
    f = np.asarray(frequencies, dtype=float)
    sampled = _sampled_subgrid(values, spacing)
    if sampled is None:
        return NoiseWeights(weights=np.ones(f.size), measured=0, noise_power=0.0)
    values, spacing = sampled
    n_f, ny, nx = values.shape
    ky = np.fft.fftfreq(ny, spacing[0]) if ny > 1 else np.zeros(1)
    kx = np.fft.fftfreq(nx, spacing[1]) if nx > 1 else np.zeros(1)
    radius = np.hypot(ky[:, None], kx[None, :])
    total = np.empty(n_f)
    noise = np.full(n_f, np.nan)
    for i in range(n_f):
        power = np.abs(np.fft.fft2(values[i])) ** 2 / (ny * nx)
        total[i] = power.mean()
        outside = radius > 2.0 * f[i]
        if outside.mean() >= MIN_EVANESCENT_SHARE:
            noise[i] = power[outside].mean()
    measured = int(np.count_nonzero(~np.isnan(noise)))
    if measured == 0:
        return NoiseWeights(weights=np.ones(n_f), measured=0, noise_power=0.0)
    white = float(np.median(noise[~np.isnan(noise)]))
    noise = np.where(np.isnan(noise), white, noise)
    with np.errstate(divide="ignore", invalid="ignore"):
        weights = np.where(total > 0, 1.0 - noise / total, 0.0)
    return NoiseWeights(weights=np.clip(weights, 0.0, 1.0), measured=measured,
                        noise_power=white)


def _sampled_subgrid(values: np.ndarray, spacing: tuple[float, float]
                     ) -> tuple[np.ndarray, tuple[float, float]] | None:
    """The rows and columns of ``values`` that hold samples (not all zero), with their
    spacing, when they form a regular grid; None for an irregular pattern."""
    nonzero = values != 0
    rows = np.flatnonzero(nonzero.any(axis=(0, 2)))
    cols = np.flatnonzero(nonzero.any(axis=(0, 1)))
    if rows.size == values.shape[1] and cols.size == values.shape[2]:
        return values, spacing
    steps = []
    for index in (rows, cols):
        gaps = np.unique(np.diff(index))
        if gaps.size > 1:
            return None
        steps.append(int(gaps[0]) if gaps.size else 1)
    sub = values[:, rows][:, :, cols]
    if np.count_nonzero(sub) < sub.size // 2:     # zeros inside the sub-grid: irregular
        return None
    return sub, (spacing[0] * steps[0], spacing[1] * steps[1])
