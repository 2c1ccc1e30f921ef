"""The evaluation protocol: train/held-out splits of a phasor field and metrics.

Thesis ch. 4-5: train on every other wall sample in x and y (32 x 32 of
64 x 64) and on 90% of 151 frequencies, then predict the full field. Sparser
scans keep every 4th or 8th sample (16 x 16, 8 x 8), or a random subset of the
wall samples (:class:`SpatialSampling`). :func:`split_field` makes the split,
:func:`field_metrics` scores a prediction on three sets (held-out pixels at
training frequencies, every pixel at held-out frequencies, everything), and
:func:`parameter_data_ratio` gives Table 4.1's parameters/data percentage.

Scattered wall samples (a random scan) are a :class:`PhasorField` with ONE row:
``wall_xyz`` of shape (1, N, 3) and ``values`` (F, 1, N), the samples in
row-major order of the full grid. Such a field has no grid spacing
(``grid_spacing()`` is None): imagers that need a grid refuse it, the ``rsd``
imager sums over its points directly, and field models fit it like any other.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from nlosfw.common.config import MAX_SEED, Choice, is_seed
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.transform.field import PhasorField


class SpectralSplit(Choice):
    """Which frequencies are held out: spread over the band (interpolation), the highest
    ones (extrapolation), or none."""

    interleaved = "interleaved"
    tail = "tail"
    none = "none"


class SpatialPattern(Choice):
    """Which wall samples a scan keeps: a regular sub-grid, or a random subset."""

    grid = "grid"
    random = "random"


@dataclass(frozen=True)
class SpatialSampling:
    """Which wall samples of the full grid the field models train on.

    ``grid``: every ``step``-th sample in x and y, starting at index 0 (2, 4, 8 keep
    32 x 32, 16 x 16, 8 x 8 of 64 x 64). ``random``: ``fraction`` of the samples (at
    least one), drawn uniformly without replacement with ``seed``; ``fraction`` None
    keeps 1 / step^2 of them, as many as the grid pattern with the same step.
    """

    pattern: SpatialPattern = SpatialPattern.grid
    step: int = 2
    fraction: float | None = None
    seed: int = 0

    def __post_init__(self) -> None:
        if self.pattern not in tuple(SpatialPattern):
            raise DataError(f"spatial sampling: pattern must be grid or random, got "
                            f"{self.pattern!r}")
        object.__setattr__(self, "pattern", SpatialPattern(self.pattern))
        if isinstance(self.step, bool) or int(self.step) != self.step or self.step < 1:
            raise DataError(f"split_field: spatial_step must be an integer >= 1, got "
                            f"{self.step}")
        if self.fraction is not None and not 0 < self.fraction <= 1:
            raise DataError(f"spatial sampling: fraction must be in (0, 1], got "
                            f"{self.fraction}")
        if not is_seed(self.seed):
            raise DataError(f"spatial sampling: seed must be an integer from 0 to {MAX_SEED}, "
                            f"got {self.seed!r}")

    @property
    def kept_fraction(self) -> float:
        """The fraction of wall samples a random pattern keeps."""
        return self.fraction if self.fraction is not None else 1.0 / self.step**2

    def mask(self, grid_shape: tuple[int, int]) -> np.ndarray:
        """The kept samples of a (ny, nx) wall grid, boolean (ny, nx)."""
        ny, nx = grid_shape
        mask = np.zeros((ny, nx), dtype=bool)
        if self.pattern == SpatialPattern.grid:
            mask[::self.step, ::self.step] = True
            return mask
        n_keep = min(ny * nx, max(1, int(round(self.kept_fraction * ny * nx))))
        rng = np.random.default_rng(self.seed)
        mask.flat[rng.choice(ny * nx, size=n_keep, replace=False)] = True
        return mask


@dataclass(frozen=True, eq=False)
class FieldSplit:
    """A field split into training samples and held-out samples.

    ``train_field`` holds the training pixels at the training frequencies: a sub-grid
    (grid pattern) or the scattered samples as one row, (1, N) (random pattern);
    ``spatial_mask[y, x]`` is True at training pixels of the full grid;
    ``train_frequencies`` and ``heldout_frequencies`` index the full field's
    frequencies (both sorted).
    """

    train_field: PhasorField
    spatial_mask: np.ndarray
    train_frequencies: np.ndarray
    heldout_frequencies: np.ndarray
    sampling: SpatialSampling = SpatialSampling()
    spectral: str = "interleaved"

    @property
    def spatial_step(self) -> int:
        """The grid pattern's step (for a random pattern, the step its default fraction
        derives from)."""
        return self.sampling.step

    @property
    def n_train_values(self) -> int:
        """Real training values (2 per complex sample), the "data size" of thesis Table 4.1."""
        return int(2 * self.train_field.values.size)

    @property
    def undersampling(self) -> float:
        """Wall samples of the full grid per training sample (4, 16, 64 for steps 2, 4, 8
        of a 64 x 64 wall)."""
        return float(self.spatial_mask.size / max(1, int(self.spatial_mask.sum())))

    def raw_field(self, field: PhasorField) -> PhasorField:
        """The training samples of the full ``field`` at every frequency: what the ``raw``
        source images.

        Grid pattern: the sub-grid. Random pattern: the full grid with zeros at every
        sample not kept; a zero adds nothing to the Rayleigh-Sommerfeld sum, so any
        imager images exactly the kept points (the same image as the ``rsd`` imager's
        direct sum over the scattered (1, N) field).
        """
        if self.sampling.pattern == SpatialPattern.grid:
            k = self.sampling.step
            return field.select(y=slice(None, None, k), x=slice(None, None, k))
        values = np.where(self.spatial_mask[None], field.values, 0)
        return field.replace(values=values.astype(field.values.dtype))


def heldout_frequency_indices(n_frequencies: int, spectral: str, fraction: float) -> np.ndarray:
    """Indices of the held-out frequencies (sorted).

    ``interleaved``: ceil(fraction * F) indices spread evenly over the band, never the
    first or last (so held-out frequencies are interpolated); ``tail``: the highest
    ceil(fraction * F) (extrapolated); ``none``: no frequency held out.
    """
    if spectral == "none" or n_frequencies < 3:
        return np.zeros(0, dtype=np.int64)
    n_hold = int(math.ceil(fraction * n_frequencies - 1e-9))
    n_hold = min(max(n_hold, 1), n_frequencies - 2)
    if spectral == "tail":
        return np.arange(n_frequencies - n_hold, n_frequencies, dtype=np.int64)
    step = n_frequencies / n_hold
    idx = np.clip(np.round((np.arange(n_hold) + 0.5) * step).astype(np.int64), 1,
                  n_frequencies - 2)
    return np.unique(idx)


def scattered_field(field: PhasorField, mask: np.ndarray) -> PhasorField:
    """The samples of a grid ``field`` where ``mask`` (Y, X) is True, as scattered samples:
    one row, wall (1, N, 3) and values (F, 1, N), in row-major order."""
    mask = np.asarray(mask, dtype=bool)
    if mask.shape != field.grid_shape:
        raise DataError(f"scattered_field: mask of shape {mask.shape} for a field on a "
                        f"{field.grid_shape} grid")
    var, counts = field.variance, field.counts
    return field.replace(values=field.values[:, mask][:, None, :],
                         wall_xyz=field.wall_xyz[mask][None],
                         variance=None if var is None else var[:, mask][:, None, :],
                         counts=None if counts is None else dataclasses.replace(
                             counts, counts=counts.counts[:, mask][:, None, :]))


def split_field(field: PhasorField, spatial_step: int | SpatialSampling = 2,
                spectral: str = "interleaved", spectral_fraction: float = 0.1
                ) -> FieldSplit:
    """Split ``field`` for training as in the thesis, or sparser.

    Spatial: ``spatial_step`` k keeps every k-th sample in x and y starting at index 0
    (64 x 64 -> 32 x 32 with the default 2; 1 keeps everything); a
    :class:`SpatialSampling` chooses the grid or a random pattern. Spectral: hold out
    ``spectral_fraction`` of the frequencies, ``interleaved`` (every tenth or so:
    interpolation), ``tail`` (the highest ones: extrapolation) or ``none``. The thesis
    setting, 151 frequencies, holds out 16 and trains on 135. The training field keeps the
    photon counts (:attr:`PhasorField.counts`) of its wall points only when no frequency
    is held out: they hold every frequency.
    """
    if not isinstance(field, PhasorField):
        raise ConfigError("field", f"split_field needs a PhasorField, got "
                                   f"{type(field).__name__}")
    if isinstance(spatial_step, SpatialSampling):
        sampling = spatial_step
    elif _is_number(spatial_step) and float(spatial_step) >= 1 and \
            float(spatial_step).is_integer():
        sampling = SpatialSampling(step=int(spatial_step))
    else:
        raise ConfigError("spatial_step", f"must be an integer >= 1 (or a SpatialSampling), "
                                          f"got {spatial_step!r}")
    if not isinstance(spectral, str) or spectral not in tuple(SpectralSplit):
        raise ConfigError("spectral", f"must be interleaved, tail or none, got {spectral!r}")
    if not _is_number(spectral_fraction) or not 0 < spectral_fraction < 1:
        raise ConfigError("spectral_fraction", f"must be in (0, 1), got {spectral_fraction!r}")
    mask = sampling.mask(field.grid_shape)
    held = heldout_frequency_indices(field.n_frequencies, spectral, spectral_fraction)
    train = np.setdiff1d(np.arange(field.n_frequencies), held)
    if held.size and field.counts is not None:
        field = field.replace(counts=None)
    if sampling.pattern == SpatialPattern.grid:
        k = sampling.step
        train_field = field.select(train, slice(None, None, k), slice(None, None, k))
    else:
        train_field = scattered_field(field.select(train), mask)
    return FieldSplit(train_field=train_field, spatial_mask=mask, train_frequencies=train,
                      heldout_frequencies=held, sampling=sampling, spectral=str(spectral))


def _is_number(value: object) -> bool:
    """Whether ``value`` is a real number (not a bool), finite or not."""
    return isinstance(value, (int, float, np.integer, np.floating)) and \
        not isinstance(value, (bool, np.bool_))


def error_metrics(true: np.ndarray, predicted: np.ndarray) -> dict[str, Any]:
    """Errors of complex ``predicted`` against ``true`` (same shape), over all their elements.

    * ``relative_l2``: ||P^ - P|| / ||P|| (complex L2 norms);
    * ``nmse_db``: 10 log10(||P^ - P||^2 / ||P||^2) = 20 log10(relative_l2);
    * ``amplitude_rmse``: sqrt(mean((|P^| - |P|)^2)) in the field's units, and
      ``relative_amplitude_rmse``, the same divided by sqrt(mean(|P|^2));
    * ``phase_error``: sum(|P| |wrap(arg P^ - arg P)|) / sum(|P|), radians in [0, pi].

    Values are None when the set is empty; ``n_samples`` counts complex samples.
    """
    t = np.asarray(true, dtype=np.complex128).ravel()
    p = np.asarray(predicted, dtype=np.complex128).ravel()
    if t.shape != p.shape:
        raise DataError(f"error_metrics: shapes differ: true {t.shape}, predicted {p.shape}")
    empty = {"relative_l2": None, "nmse_db": None, "amplitude_rmse": None,
             "relative_amplitude_rmse": None, "phase_error": None, "n_samples": 0}
    if t.size == 0:
        return empty
    err2 = float(np.sum(np.abs(p - t) ** 2))
    ref2 = float(np.sum(np.abs(t) ** 2))
    rel = math.sqrt(err2 / ref2) if ref2 > 0 else math.inf
    mag_t, mag_p = np.abs(t), np.abs(p)
    amp_rmse = float(np.sqrt(np.mean((mag_p - mag_t) ** 2)))
    rms = math.sqrt(ref2 / t.size)
    dphi = np.abs(np.angle(p * np.conj(t)))
    phase = float(np.sum(mag_t * dphi) / np.sum(mag_t)) if ref2 > 0 else math.nan
    return {
        "relative_l2": rel,
        "nmse_db": 10 * math.log10(err2 / ref2) if ref2 > 0 and err2 > 0 else (
            -math.inf if ref2 > 0 else math.inf),
        "amplitude_rmse": amp_rmse,
        "relative_amplitude_rmse": amp_rmse / rms if rms > 0 else math.inf,
        "phase_error": phase,
        "n_samples": int(t.size),
    }


def field_metrics(true_field: PhasorField | np.ndarray, predicted_field: PhasorField | np.ndarray,
                  split: FieldSplit) -> dict[str, dict[str, Any]]:
    """Errors of a prediction of the full field on the three sets of the protocol.

    ``true_field`` and ``predicted_field`` are the full fields (or their complex
    ``values`` arrays, shape (F, Y, X)) that ``split`` was made from. Returns
    ``{"heldout_pixels": ..., "heldout_frequencies": ..., "all": ...}``, each the dict
    of :func:`error_metrics`: held-out pixels at training frequencies, every pixel at
    held-out frequencies, and every sample; plus ``heldout_pixels_inside``, the held-out
    pixels inside the training pixels' bounding box (with the default split the last
    row and column lie outside it, half a training step beyond: an extrapolation that
    often dominates ``heldout_pixels``). Sets that are empty (no spatial or no spectral
    hold-out) have None values.
    """
    if not isinstance(split, FieldSplit):
        raise ConfigError("split", f"field_metrics needs the FieldSplit the fields were split "
                                   f"by (split_field's), got {type(split).__name__}")
    t = _field_values(true_field, "true_field")
    p = _field_values(predicted_field, "predicted_field")
    if t.shape != p.shape or t.ndim != 3:
        raise DataError(f"field_metrics: true {t.shape} and predicted {p.shape} must both be the "
                        "full (frequency, y, x) field")
    if t.shape[1:] != split.spatial_mask.shape:
        raise DataError(f"field_metrics: the fields' grid {t.shape[1:]} is not the split's "
                        f"{split.spatial_mask.shape}")
    n_f = split.train_frequencies.size + split.heldout_frequencies.size
    if t.shape[0] != n_f:
        raise DataError(f"field_metrics: the fields have {t.shape[0]} frequencies, the split "
                        f"{n_f}")
    held_px = ~split.spatial_mask
    inside = held_px & hull_mask(split.spatial_mask)
    tf, hf = split.train_frequencies, split.heldout_frequencies
    return {
        "heldout_pixels": error_metrics(t[tf][:, held_px], p[tf][:, held_px]),
        "heldout_frequencies": error_metrics(t[hf], p[hf]),
        "all": error_metrics(t, p),
        "heldout_pixels_inside": error_metrics(t[tf][:, inside], p[tf][:, inside]),
    }


def _field_values(field: object, option: str) -> np.ndarray:
    """The complex values of a PhasorField or of a numeric array; a ConfigError naming
    ``option`` for anything else."""
    if isinstance(field, PhasorField):
        return field.values
    try:
        values = np.asarray(field) if isinstance(field, (np.ndarray, list, tuple)) else None
    except (TypeError, ValueError):          # a ragged list
        values = None
    if values is None or values.dtype.kind not in "biufc" or values.ndim != 3:
        got = (type(field).__name__ if values is None
               else f"an array of shape {values.shape} of {values.dtype}")
        raise ConfigError(option, f"expected a PhasorField or its values (F, Y, X), got {got}")
    return values


def hull_mask(spatial_mask: np.ndarray) -> np.ndarray:
    """Pixels inside the bounding box of the training pixels (rows and columns between the
    first and last ones holding a training pixel)."""
    rows = np.flatnonzero(spatial_mask.any(axis=1))
    cols = np.flatnonzero(spatial_mask.any(axis=0))
    out = np.zeros_like(spatial_mask, dtype=bool)
    if rows.size and cols.size:
        out[rows[0]:rows[-1] + 1, cols[0]:cols[-1] + 1] = True
    return out


def parameter_data_ratio(n_parameters: int, n_values: int | FieldSplit) -> float:
    """Parameters per training value in percent (thesis Table 4.1's "Parameters/Data (%)").

    ``n_values`` counts real values (2 per complex sample) or is a :class:`FieldSplit`.
    E.g. SIREN, 3362 parameters, 32 x 32 x 135 x 2 = 276,480 values: 1.22%.
    """
    n = n_values.n_train_values if isinstance(n_values, FieldSplit) else int(n_values)
    if n <= 0:
        raise DataError(f"parameter_data_ratio: need a positive number of values, got {n}")
    return 100.0 * int(n_parameters) / n
