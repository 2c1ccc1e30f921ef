"""The training samples of the physics-constrained fit (and of the neural volume) on their
wall grid: a regular grid, or the scattered samples of a random scan placed on the grid they
were drawn from; the field on that grid, normalised; and the split of the sampled wall
points into training and validation points (``fit_lobe``'s held-out search, the neural
volume's early stopping)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosfw.common.errors import DataError
from nlosfw.image.plane_convolution import GridLayout, GridOrder, grid_layout, to_canonical
from nlosfw.image.rsd_kernel import wall_field
from nlosfw.transform.field import PhasorField


def training_grid(field: PhasorField, who: str = "rsd_prior") -> GridLayout:
    """The training samples' regular grid in the wall plane (a DataError naming model
    ``who`` if they are not)."""
    layout = grid_layout(field.wall_xyz)
    if layout is None or min(layout.shape) < 2:
        raise _not_a_grid(field, who)
    return layout


def _not_a_grid(field: PhasorField, who: str) -> DataError:
    return DataError(f"{who}: the training samples must form a regular axis-aligned grid of "
                     f"at least 2 x 2 points in the wall plane z = 0, or be scattered points "
                     f"of such a grid (one row, (1, N)), got wall_xyz of shape "
                     f"{field.wall_xyz.shape}")


#: Relative tolerance (of the grid spacing) on scattered samples lying on a grid.
LATTICE_RTOL = 1e-3
#: Most grid points per scattered sample (a random scan keeping 1/64 of its grid has 64).
MAX_GRID_PER_SAMPLE = 1024


@dataclass(frozen=True, eq=False)
class WallSamples:
    """The training samples on a regular wall grid in canonical order: every grid point
    (``mask`` None) or the kept points of a random scan (``mask`` True there, (ny, nx))."""

    layout: GridLayout
    mask: np.ndarray | None = None
    cells: tuple[np.ndarray, np.ndarray] | None = None
    """(row, column) of each scattered sample on the canonical grid (None: a grid field)."""

    @property
    def count(self) -> int:
        """The number of samples."""
        return int(np.prod(self.layout.shape)) if self.mask is None else int(self.mask.sum())

    def on_grid(self, a: np.ndarray) -> np.ndarray:
        """An array over the field's wall (its last two axes) on the canonical grid, zero at
        the points not sampled (a new array for scattered samples, else a view)."""
        if self.cells is None:
            return to_canonical(a, self.layout.order, axes=(a.ndim - 2, a.ndim - 1))
        out = np.zeros(a.shape[:-2] + self.layout.shape, dtype=a.dtype)
        out[..., self.cells[0], self.cells[1]] = a[..., 0, :]
        return out


def wall_samples(field: PhasorField, who: str = "rsd_prior") -> WallSamples:
    """The training samples of ``field`` on their wall grid: a regular grid field as it is,
    or scattered samples (one row, (1, N); :func:`nlosfw.evaluation.scattered_field`)
    on the smallest regular grid that holds them all, its spacing the closest distinct
    coordinates per axis. A DataError naming model ``who`` if they lie on no such grid."""
    layout = grid_layout(field.wall_xyz)
    if layout is not None and min(layout.shape) >= 2:
        return WallSamples(layout)
    ny, nx = field.grid_shape
    if ny != 1 or nx < 4:
        raise _not_a_grid(field, who)
    points = np.asarray(field.wall_xyz, dtype=float)[0]
    extent = max(float(np.ptp(points[:, :2])), 1e-12)
    if np.max(np.abs(points[:, 2])) > LATTICE_RTOL * extent:
        raise DataError(f"{who}: the training samples must lie in the wall plane z = 0, got "
                        f"z up to {np.max(np.abs(points[:, 2])):.4g} m")
    axes = [_lattice_axis(points[:, k], who, "yx"[k]) for k in (1, 0)]
    shape = (axes[0][2], axes[1][2])
    if shape[0] < 2 or shape[1] < 2 or shape[0] * shape[1] > MAX_GRID_PER_SAMPLE * nx:
        raise DataError(f"{who}: the {nx} scattered training samples span a {shape[0]} x "
                        f"{shape[1]} grid; they must span at least 2 x 2 points and at most "
                        f"{MAX_GRID_PER_SAMPLE} per sample")
    rows = np.round((points[:, 1] - axes[0][0]) / axes[0][1]).astype(np.int64)
    cols = np.round((points[:, 0] - axes[1][0]) / axes[1][1]).astype(np.int64)
    mask = np.zeros(shape, dtype=bool)
    mask[rows, cols] = True
    if int(mask.sum()) != nx:
        raise DataError(f"{who}: {nx - int(mask.sum())} of the {nx} scattered training "
                        "samples share a wall point with another; give each point once")
    layout = GridLayout(GridOrder(False, False, False), (axes[0][0], axes[1][0]),
                        (axes[0][1], axes[1][1]), shape)
    return WallSamples(layout, mask, (rows, cols))


def training_values(field: PhasorField, who: str = "rsd_prior"
                    ) -> tuple[WallSamples, np.ndarray, float]:
    """(the samples' wall grid, the field without device legs on it divided by its RMS over
    the samples (F, ny, nx), zero where not sampled, that RMS): what ``rsd_prior`` and the
    neural volume fit."""
    samples, raw = wall_samples(field, who), wall_field(field)
    scale = float(np.sqrt(np.mean(np.abs(raw) ** 2)))
    return samples, samples.on_grid(raw) / scale, scale


def _lattice_axis(values: np.ndarray, who: str, name: str) -> tuple[float, float, int]:
    """(first, spacing, points) of the regular axis holding every coordinate of ``values``."""
    distinct = np.unique(values)
    # coordinates closer than a millionth of the extent are one grid line (rounding)
    tolerance = 1e-6 * max(float(np.ptp(distinct)), 1e-12)
    lines = distinct[np.concatenate([[True], np.diff(distinct) > tolerance])]
    if lines.size < 2:
        return float(lines[0]), 0.0, 1
    spacing = float(np.diff(lines).min())
    steps = (lines - lines[0]) / spacing
    if np.max(np.abs(steps - np.round(steps))) > LATTICE_RTOL:
        raise DataError(f"{who}: the scattered training samples' {name} coordinates are not "
                        f"on a regular grid (spacing {spacing:.4g} m does not divide their "
                        "offsets); the model needs points drawn from a regular wall grid")
    return float(lines[0]), spacing, int(round(steps[-1])) + 1


def validation_split(shape: tuple[int, int], fraction: float, seed: int,
                     sampled: np.ndarray | None = None
                     ) -> tuple[np.ndarray, np.ndarray | None]:
    """(train, validation) weights (ny, nx), float32 0/1: ``fraction`` of the sampled wall
    points (``sampled`` True, (ny, nx); None: every point), chosen at random with ``seed``,
    are validation points (none below 10 points or at 0); both are 0 where not sampled."""
    points = (np.arange(shape[0] * shape[1]) if sampled is None
              else np.flatnonzero(np.asarray(sampled, dtype=bool)))
    train = np.zeros(shape[0] * shape[1], np.float32)
    train[points] = 1
    n_val = int(round(fraction * points.size))
    if fraction <= 0 or points.size < 10 or n_val < 1:
        return train.reshape(shape), None
    chosen = points[np.random.default_rng(seed).permutation(points.size)[:n_val]]
    validation = np.zeros_like(train)
    validation[chosen] = 1
    train[chosen] = 0
    return train.reshape(shape), validation.reshape(shape)

