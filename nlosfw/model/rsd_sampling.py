"""What ``rsd_prior`` (and ``neural_volume``, on its lattice) fits on: the training grid,
the voxel lattice, and which frequencies (evenly spread, and enough that the depth span
does not alias in time)."""

from __future__ import annotations

import math

import numpy as np

from nlosfw.common.config import number
from nlosfw.common.errors import ConfigError, DataError
from nlosfw.image.plane_convolution import GridLayout, grid_layout
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
        raise DataError(f"{who}: the training samples must form a regular axis-aligned "
                        f"grid of at least 2 x 2 points in the wall plane z = 0, got wall_xyz "
                        f"of shape {field.wall_xyz.shape}")
    return layout


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
