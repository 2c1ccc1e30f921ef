"""Frequency sets of the phasor transforms: default bands, limits and validation.

Frequencies are temporal frequencies in cycles per metre of optical path
(wavelength = 1/f). Two limits matter:

* the capture's temporal Nyquist limit ``1 / (2 delta_t)``: a histogram with
  bins of ``delta_t`` metres carries nothing above it (an error);
* the wall's spatial sampling. A scatterer at distance r from wall point x_s
  puts the phase exp(-2 pi i f m r) on the field, m = 1 for a single laser spot
  (only the sensor leg moves with x_s) and m = 2 for a confocal scan (laser and
  sensor legs both move: the path doubles). The field is a wave of spatial
  wavelength 1/(m f) on the wall, which a grid of spacing Δ carries without
  aliasing when 1/(m f) >= 2Δ, i.e. ``f <= 1 / (2 m Δ)``: 1/(2Δ) single-spot,
  1/(4Δ) confocal (:func:`spatial_limit`; exceeding it is a warning).

The automatic band (:func:`default_band`) ends at that limit and starts a
factor :data:`DEFAULT_BAND_RATIO` lower.
"""

from __future__ import annotations

import logging

import numpy as np

from nlosfw.capture.data import Capture
from nlosfw.capture.enums import CaptureKind
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.transform.field import Band, PhasorField

log = logging.getLogger(__name__)

#: Default ratio f_max / f_min of the band: wall wavelengths from 2Δ to 8Δ, centred
#: (geometrically) on Liu's usual 4Δ virtual wavelength.
DEFAULT_BAND_RATIO = 4.0


def path_multiplier(kind: CaptureKind) -> int:
    """m: how many legs of the path move with the wall point, 2 confocal, else 1."""
    return 2 if kind is CaptureKind.CONFOCAL else 1


def wall_spacing(configured: float | None, capture: Capture, required: bool) -> float | None:
    """Δ for a transform: ``configured`` if set, else the capture's sensor grid spacing.

    When the capture has no spacing (a single wall point), returns None if the
    transform does not need one (explicit frequencies or wavelength), and
    re-raises the DataError otherwise.
    """
    if configured is not None:
        return configured
    try:
        return grid_spacing(capture.sensor_grid_xyz)
    except DataError:
        if required:
            raise
        return None


def grid_spacing(points: np.ndarray) -> float:
    """Sampling distance Δ (m) of a set of wall points.

    A grid (A, B, 3) gives the larger of its two axis steps (the one that
    limits aliasing); a list (N, 3) the median nearest-neighbour distance.
    Raises :class:`DataError` when no spacing exists (a single point).
    """
    pts = np.asarray(points, dtype=float)
    if pts.ndim == 3 and pts.shape[0] * pts.shape[1] > 1:
        steps = []
        if pts.shape[0] > 1:
            steps.append(float(np.median(np.linalg.norm(np.diff(pts, axis=0), axis=-1))))
        if pts.shape[1] > 1:
            steps.append(float(np.median(np.linalg.norm(np.diff(pts, axis=1), axis=-1))))
        spacing = max(steps)
    else:
        flat = pts.reshape(-1, 3)
        if flat.shape[0] < 2:
            raise DataError("sensor_grid_xyz: a single wall point has no grid spacing; give the "
                            "frequencies explicitly")
        from scipy.spatial import cKDTree

        dist, _ = cKDTree(flat).query(flat, k=2)
        spacing = float(np.median(dist[:, 1]))
    if not spacing > 0:
        raise DataError("sensor_grid_xyz: wall points coincide (spacing 0); give the frequencies "
                        "explicitly")
    return spacing


def temporal_nyquist(delta_t: float) -> float:
    """Highest frequency (cycles per metre) a histogram of bin width ``delta_t`` carries."""
    return 0.5 / float(delta_t)


def spatial_limit(spacing: float, kind: CaptureKind = CaptureKind.SINGLE_SPOT) -> float:
    """Highest frequency (cycles per metre of path) a wall grid of spacing Δ carries without
    aliasing: 1/(2 m Δ), i.e. 1/(2Δ) single-spot and 1/(4Δ) confocal (module docstring)."""
    return 0.5 / (path_multiplier(kind) * float(spacing))


def aliasing_warning(f_max: float, spacing: float | None, kind: CaptureKind,
                     option: str) -> str | None:
    """The one-line warning for a band reaching ``f_max`` on a wall of spacing Δ, or None
    when it does not alias (or no spacing is known)."""
    if spacing is None:
        return None
    limit = spatial_limit(spacing, kind)
    if f_max <= limit * (1 + 1e-9):
        return None
    m = path_multiplier(kind)
    why = "confocal: the path doubles, " if m == 2 else ""
    return (f"{option}: frequencies up to {f_max:.4g} cycles/m alias on the wall grid of "
            f"spacing {spacing:.4g} m ({why}limit 1/({2 * m}Δ) = {limit:.4g} cycles/m); keep "
            f"f <= {limit:.4g} cycles/m")


def warn_aliasing(f_max: float, spacing: float | None, kind: CaptureKind, option: str) -> None:
    """Log :func:`aliasing_warning` (a WARNING) if the band aliases."""
    message = aliasing_warning(f_max, spacing, kind, option)
    if message is not None:
        log.warning("%s", message)


def band_info(frequencies: np.ndarray, spacing: float | None, kind: CaptureKind,
              option: str) -> Band:
    """What a transform records about its band (the field's ``band``): the wall spacing it
    was checked against, the aliasing limit, whether it aliases, the option."""
    f_max = float(np.max(frequencies))
    limit = None if spacing is None else spatial_limit(spacing, kind)
    return Band(grid_spacing=None if spacing is None else float(spacing),
                spatial_limit=limit, option=option,
                aliases=aliasing_warning(f_max, spacing, kind, option) is not None)


def band_warning(field: PhasorField) -> str | None:
    """The aliasing warning of ``field``'s band (None: it does not alias, or no band was
    recorded): whoever images the field on the wall says it, once."""
    band = field.band
    if band is None or not band.aliases or band.grid_spacing is None:
        return None
    return aliasing_warning(float(field.frequencies.max()), band.grid_spacing,
                            field.geometry.kind, band.option)


def check_frequency_values(values: tuple[float, ...] | np.ndarray, option: str) -> None:
    """ConfigError unless every value is finite and > 0."""
    arr = np.asarray(values, dtype=float)
    bad = arr[~np.isfinite(arr) | (arr <= 0)]
    if bad.size:
        raise ConfigError(option, f"frequencies must be finite and > 0 cycles per metre, got "
                                  f"{float(bad[0])}")


def validate_frequencies(frequencies: np.ndarray, delta_t: float, spacing: float | None,
                         option: str = "frequencies",
                         kind: CaptureKind = CaptureKind.SINGLE_SPOT,
                         warn: bool = True) -> np.ndarray:
    """Check ``frequencies`` against a capture; return them as a float64 array.

    Errors (one line, naming ``option``) on an empty set, non-finite or
    non-positive values, or values above the temporal Nyquist limit; with ``warn``, a
    logged WARNING (:func:`warn_aliasing`) when they pass the wall grid's
    :func:`spatial_limit` for the capture's ``kind`` (the built-in transforms record it in
    the field's band instead: :func:`band_info`, :func:`band_warning`).
    """
    f = np.atleast_1d(np.asarray(frequencies, dtype=float))
    if f.size == 0:
        raise ConfigError(option, "the frequency set is empty; give at least one frequency > 0")
    check_frequency_values(f, option)
    nyquist = temporal_nyquist(delta_t)
    if f.max() > nyquist * (1 + 1e-12):
        raise ConfigError(option, f"{f.max():.6g} cycles/m is above the capture's temporal "
                                  f"Nyquist limit 1/(2*delta_t) = {nyquist:.6g}; valid: 0 < f <= "
                                  f"{nyquist:.6g}")
    if warn:
        warn_aliasing(float(f.max()), spacing, kind, option)
    return f


def default_band(spacing: float, delta_t: float, f_min: float | None,
                 f_max: float | None,
                 kind: CaptureKind = CaptureKind.SINGLE_SPOT) -> tuple[float, float]:
    """(f_min, f_max) of the default band, filling whichever end is not given.

    f_max defaults to the grid limit :func:`spatial_limit` (1/(2Δ) single-spot,
    1/(4Δ) confocal: finest wall wavelength 2Δ), capped at the temporal Nyquist
    limit; f_min defaults to f_max / 4. Raises ConfigError when the band is empty.
    """
    hi = f_max
    if hi is None:
        hi = spatial_limit(spacing, kind)
        nyquist = temporal_nyquist(delta_t)
        if hi > nyquist:
            log.info("default f_max %.4g cycles/m capped at the temporal Nyquist limit %.4g",
                     hi, nyquist)
            hi = nyquist
    lo = f_min if f_min is not None else hi / DEFAULT_BAND_RATIO
    if not lo < hi:
        raise ConfigError("f_min", f"empty band: f_min = {lo:.6g} must be below f_max = "
                                   f"{hi:.6g} cycles/m")
    return float(lo), float(hi)


def uniform_step(values: np.ndarray) -> float | None:
    """The common step of ``values`` in their given order (any sign), or None.

    None for fewer than two values, a zero step, or steps that differ by more than
    1e-9 relative: the sets a frequency recurrence or a DFT grid can use.
    """
    steps = np.diff(np.asarray(values, dtype=float))
    if steps.size == 0:
        return None
    step = float(steps.mean())
    if step != 0 and np.allclose(steps, step, rtol=1e-9, atol=0):
        return step
    return None


def dft_length(frequencies: np.ndarray, delta_t: float, n_bins: int,
               max_factor: int = 64) -> int | None:
    """A DFT length N >= ``n_bins`` of which every frequency is an exact bin, or None.

    Frequency f is bin k of a length-N DFT when f * N * delta_t = k is an
    integer. Candidates are ``n_bins`` itself and, for uniformly spaced sets,
    1 / (step * delta_t); lengths above ``max_factor * n_bins`` are not used.
    """
    f = np.asarray(frequencies, dtype=float)
    candidates = [int(n_bins)]
    step = uniform_step(np.sort(f))
    if step is not None and step > 0:
        n = 1.0 / (step * delta_t)
        if abs(n - round(n)) < 1e-6 * max(1.0, n):
            candidates.append(int(round(n)))
    for n in candidates:
        if n < n_bins or n > max_factor * n_bins:
            continue
        k = f * n * delta_t
        if np.all(np.abs(k - np.round(k)) < 1e-9 * np.maximum(1.0, k)) and np.all(
            np.round(k) < n / 2 + 1e-9
        ):
            return n
    return None
