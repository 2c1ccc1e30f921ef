"""The splits of the protocol: a phasor field's training and held-out samples, spatial
and spectral.

Thesis ch. 4-5: train on every other wall sample in x and y (32 x 32 of
64 x 64) and on 90% of 151 frequencies, then predict the full field. Sparser
scans keep every 4th or 8th sample (16 x 16, 8 x 8), or a random subset of the
wall samples (:class:`SpatialSampling`). :func:`split_field` makes the split;
:mod:`nlosfw.evaluation.field_scores` scores a prediction on its sets, and count
splitting (:mod:`nlosfw.evaluation.count_splitting`) splits the photons themselves.

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


def heldout_frequency_count(n_frequencies: int, spectral: str, fraction: float) -> int:
    """How many frequencies :func:`heldout_frequency_indices` holds out, without making
    them (a plan sizes fields of any requested count before anything is allocated).

    The interleaved indices are ``(i + 1/2) * F / n`` rounded, n <= F - 2, so consecutive
    ones differ by more than one; only the last can meet its neighbour, where the clip to
    F - 2 lowers it."""
    if spectral == "none" or n_frequencies < 3:
        return 0
    n_hold = min(max(int(math.ceil(fraction * n_frequencies - 1e-9)), 1), n_frequencies - 2)
    if spectral == "tail" or n_hold < 2:
        return n_hold
    step = n_frequencies / n_hold
    last, before = (int(np.clip(np.round((i + 0.5) * step), 1, n_frequencies - 2))
                    for i in (n_hold - 1, n_hold - 2))
    return n_hold - int(last == before)


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
