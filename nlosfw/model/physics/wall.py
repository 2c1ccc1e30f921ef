"""What ``rsd_prior`` (and ``neural_volume``, on its lattice) fits on: the training grid
(a regular grid, or the scattered samples of a random scan placed on the grid they were
drawn from), the voxel lattice, and which frequencies (evenly spread, and enough that the
depth span does not alias in time)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosfw.common.config import number
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.image.plane_convolution import GridLayout, GridOrder, grid_layout, to_canonical
from nlosfw.image.rsd_kernel import wall_field
from nlosfw.model.scene_operator import VoxelLattice
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


def deepest_path(field: PhasorField) -> float:
    """Half the longest path the field can hold: the capture's time span (from the
    transform's metadata) or the unambiguous range 1/df of the frequency spacing."""
    meta = field.metadata
    try:
        t_start, n_bins, delta_t = (number(meta[k]) for k in ("t_start", "n_bins", "delta_t"))
        end = t_start + int(n_bins) * delta_t
        if end > 0:
            return end / 2
    except (KeyError, TypeError, ValueError):
        pass
    f = np.sort(np.unique(field.frequencies))
    if f.size < 2:
        raise ConfigError("model.depth_range", "give [near, far] (m): one frequency and no "
                          "capture time span in the field's metadata cannot place the scene")
    return 1.0 / (2.0 * float(np.min(np.diff(f))))


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
    or scattered samples (one row, (1, N); :func:`nlosfw.model.protocol.scattered_field`)
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


def voxel_lattice(wall: GridLayout, lateral_step: float, depths: np.ndarray) -> VoxelLattice:
    """Voxel planes at ``depths`` whose spacing divides the training spacing (at most
    ``lateral_step``) and covering the training grid plus half a training spacing."""
    origin, step, shape = [], [], []
    for axis in (0, 1):
        spacing, n = wall.spacing[axis], wall.shape[axis]
        k = max(1, math.ceil(spacing / lateral_step - 1e-6))
        pad = k // 2
        step.append(spacing / k)
        origin.append(wall.origin[axis] - pad * spacing / k)
        shape.append(k * (n - 1) + 1 + 2 * pad)
    return VoxelLattice(np.asarray(depths, dtype=float), (origin[0], origin[1]),
                        (step[0], step[1]), (shape[0], shape[1]))
